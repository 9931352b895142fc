//! `photomat train-estimator --gan RUN --brdf SPEC --out RUN_E [--steps N] [--finetune-steps M]
//! [--batch 4] [--lr 1e-4] [--finetune-lr 5e-5] [--vgg19 FILE] [--width 1.0] [--seed S]
//! [--panel-every K] [--checkpoint-every K] [--resume]`: trains the map estimator E for the
//! BRDF model SPEC against the frozen G_ema + M of a GAN model folder (PhotoMat §3 "Material
//! map estimator"). The run is the library's `photomat_estimator::train::EstimatorTraining`
//! driver; this command parses the flags, installs the signal handler and shows progress.
//!
//! SPEC is any registered model, including plugins linked into a custom binary built on
//! `photomat_cli::run()`. Stage 1 (`--steps`) compares the analytic render of E's maps with
//! M's relighting by 0.1·L1 + 1.0·Gram at scales 1, ½, ¼; stage 2 (`--finetune-steps`) rolls
//! maps and F per sample before rendering (L1 on 16×16 downsamples, Gram at full resolution).
//! The Gram features are VGG19 from `--vgg19 FILE.safetensors` (torchvision's
//! `vgg19().features` weights; how to write the file: `photomat_estimator::loss::vgg19`) or,
//! without it, a seeded random conv bank (`photomat_estimator::loss::random_features`).
//!
//! RUN_E is a complete **model folder** from the first checkpoint on: `estimator.json` +
//! `estimator.safetensors` (E, BRDF by name) next to a copy of RUN's `gan.json` +
//! `gan.safetensors`, so `photomat sample --model RUN_E` loads both. It also holds
//! `train.json` + `train_state.safetensors` (written atomically every `--checkpoint-every`
//! steps, at the end and on SIGINT/SIGTERM/SIGHUP after the current step, then exiting with
//! 128 + the signal number), `log.csv` (one row per step) and
//! `panels/step-NNNNNN.png` (per material: M's relighting | the analytic render | the maps).
//! `--resume` continues from the last checkpoint bit-identically; flags that contradict
//! `train.json` are errors naming the field.

use std::io::Write;
use std::path::{Path, PathBuf};

use candle_core::Device;
use photomat_estimator::train::{EstimatorOutcome, EstimatorSettings, EstimatorTraining};

use crate::common::{interruption, steps_bar, stop_flag};

#[derive(Debug, clap::Args)]
#[command(after_help = crate::common::STOP_HELP)]
pub struct Args {
    /// GAN model folder (`photomat train-gan` output: gan.json + gan.safetensors). Taken from
    /// RUN_E/train.json with --resume.
    #[arg(long, value_name = "RUN")]
    pub gan: Option<PathBuf>,

    /// BRDF model E decodes into, e.g. `ggx`, `height(ggx)`, `coated` (`photomat brdfs` lists
    /// them). Taken from RUN_E/train.json with --resume.
    #[arg(long, value_name = "SPEC")]
    pub brdf: Option<String>,

    /// Run folder: the trained model (E + a copy of the GAN), checkpoints, panels, log.
    #[arg(long, value_name = "RUN_E")]
    pub out: PathBuf,

    /// Steps of stage 1 (aligned L1 + Gram) [default: 60000, the paper's].
    #[arg(long, value_name = "N")]
    pub steps: Option<u64>,

    /// Steps of stage 2, the fine-tune with rolled maps [default: 60000, the paper's].
    #[arg(long, value_name = "M")]
    pub finetune_steps: Option<u64>,

    /// Materials per step [default: 4].
    #[arg(long, value_name = "B")]
    pub batch: Option<usize>,

    /// Adam learning rate of stage 1 [default: 1e-4].
    #[arg(long, value_name = "LR")]
    pub lr: Option<f64>,

    /// Adam learning rate of the fine-tune [default: 5e-5].
    #[arg(long, value_name = "LR")]
    pub finetune_lr: Option<f64>,

    /// VGG19 weights (safetensors, torchvision's `vgg19().features` names
    /// `features.{0,2,5,…,34}.{weight,bias}`) for the Gram loss; without it a seeded random
    /// conv bank is used.
    #[arg(long, value_name = "FILE", long_help = VGG19_HELP)]
    pub vgg19: Option<PathBuf>,

    /// Width multiplier of E's channels (1 = the paper's 32…256; 0.25 for CPU training)
    /// [default: 1].
    #[arg(long, value_name = "W")]
    pub width: Option<f64>,

    /// Seed of the run: E's initial weights, every step's materials, lights and rolls
    /// [default: 0].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,

    /// Steps between training panels in RUN_E/panels/ [default: 500; on --resume the run's,
    /// from train.json].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub panel_every: Option<u64>,

    /// Steps between checkpoints [default: 500; on --resume the run's].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,

    /// Continue the run in RUN_E from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
}

/// `--help` text of `--vgg19`: what the file holds and how to write it.
const VGG19_HELP: &str = "VGG19 weights for the Gram loss, as a safetensors file with \
torchvision's `vgg19().features` tensors `features.{0,2,5,7,10,12,14,16,19,21,23,25,28,30,32,34}.{weight,bias}` \
(max-pools are replaced by average pools; features after pool1–pool5, ImageNet-normalised input). \
Write it once with PyTorch, torchvision and safetensors:

  import torchvision
  from safetensors.torch import save_file
  vgg = torchvision.models.vgg19(weights=torchvision.models.VGG19_Weights.IMAGENET1K_V1)
  save_file({f\"features.{k}\": v.contiguous() for k, v in vgg.features.state_dict().items()}, \"vgg19.safetensors\")

Without --vgg19, a seeded random conv bank with the same five pooled stages (3→16→32→64→64→64) \
gives the Gram statistics (Ustyuzhaninov et al. 2017).";

impl Args {
    /// The run's settings as the flags give them.
    fn settings(&self) -> EstimatorSettings {
        EstimatorSettings {
            gan: self.gan.clone(),
            brdf: self.brdf.clone(),
            steps: self.steps,
            finetune_steps: self.finetune_steps,
            batch: self.batch,
            lr: self.lr,
            finetune_lr: self.finetune_lr,
            vgg19: self.vgg19.clone(),
            width: self.width,
            seed: self.seed,
            panel_every: self.panel_every,
            checkpoint_every: self.checkpoint_every,
        }
    }
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let run = &args.out;
    let mut training = EstimatorTraining::open(run, &args.settings(), args.resume, &Device::Cpu)?;
    let stop = stop_flag()?;
    let trainer = training.trainer();
    let config = trainer.config().clone();
    let total = config.total_steps();
    let start_step = trainer.steps_done();
    writeln!(
        out,
        "training E for {} ({} parameters) against {} ({}², batch {}, seed {}, Gram features: {}): steps {start_step} → {total} ({} aligned + {} fine-tune)",
        trainer.model().brdf().name(),
        trainer.model().estimator().config().num_parameters(),
        training.gan_dir().display(),
        trainer.gan().config().resolution,
        config.batch,
        config.seed,
        trainer.extractor().describe(),
        config.steps,
        config.finetune_steps,
    )?;
    let bar = steps_bar(total, start_step);
    let outcome = training.run(&stop, &mut |report, seconds| {
        // On stderr whether or not it is a terminal, and in log.csv's `skipped` column.
        if report.skipped {
            bar.suspend(|| {
                eprintln!(
                    "warning: step {}: loss not finite (L1 {}, Gram {}), update skipped",
                    report.step, report.l1, report.gram
                )
            });
        }
        bar.set_position(report.step);
        bar.set_message(format!(
            "{} | L1 {:.4} Gram {:.4} total {:.4} | {seconds:.2} s/step",
            report.stage.name(),
            report.l1,
            report.gram,
            report.total
        ));
    })?;
    bar.finish_and_clear();
    report(run, total, &outcome, out)?;
    if outcome.interrupted {
        return Err(interruption().into());
    }
    Ok(())
}

/// The lines after a run: how it ended and where its outputs are.
fn report(run: &Path, total: u64, o: &EstimatorOutcome, out: &mut dyn Write) -> anyhow::Result<()> {
    if o.interrupted {
        writeln!(
            out,
            "interrupted at step {} of {total}: state saved in {}; continue with\n  photomat train-estimator --out {} --resume",
            o.steps_done,
            run.display(),
            run.display()
        )?;
    } else {
        writeln!(
            out,
            "trained {} steps ({} in total){}{}",
            o.steps_run,
            o.steps_done,
            if o.steps_run > 0 {
                format!(", {:.2} s/step", o.seconds / o.steps_run as f64)
            } else {
                String::new()
            },
            o.last
                .as_ref()
                .map(|r| format!(
                    "; last loss: L1 {:.4}, Gram {:.4}, total {:.4}",
                    r.l1, r.gram, r.total
                ))
                .unwrap_or_default()
        )?;
    }
    writeln!(
        out,
        "  {}/estimator.json, estimator.safetensors, gan.json, gan.safetensors  the model (photomat sample --model {})",
        run.display(),
        run.display()
    )?;
    writeln!(out, "  {}/log.csv  losses per step", run.display())?;
    writeln!(out, "  {}  latest panel", o.panel.display())?;
    Ok(())
}
