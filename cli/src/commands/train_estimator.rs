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
    /// Run folder: the trained model (E + a copy of the GAN), checkpoints, panels, log.
    #[arg(long, value_name = "RUN_E")]
    pub out: PathBuf,

    /// Continue the run in RUN_E from its last checkpoint.
    #[arg(long)]
    pub resume: bool,

    #[command(flatten)]
    pub settings: EstimatorSettings,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let run = &args.out;
    let mut training = EstimatorTraining::open(run, &args.settings, args.resume, &Device::Cpu)?;
    for note in training.notes() {
        eprintln!("{note}");
    }
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
