//! `photomat train-estimator --gan RUN --brdf SPEC --out RUN_E [--steps N] [--finetune-steps M]
//! [--batch 4] [--lr 1e-4] [--finetune-lr 5e-5] [--vgg19 FILE] [--width 1.0] [--seed S]
//! [--panel-every K] [--checkpoint-every K] [--resume]`: trains the map estimator E for the
//! BRDF model SPEC against the frozen G_ema + M of a GAN model folder (PhotoMat §3 "Material
//! map estimator", issue 7; the step is `photomat_estimator::train::EstimatorTrainer`).
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
//! steps, at the end and on Ctrl-C after the current step), `log.csv` (one row per step) and
//! `panels/step-NNNNNN.png` (per material: M's relighting | the analytic render | the maps).
//! `--resume` continues from the last checkpoint bit-identically; flags that contradict
//! `train.json` are errors naming the field.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::Device;
use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::image_io::{CONTACT_SHEET_GAP, PlanarImage, PngBits, write_png};
use photomat_core::{Highlight, lookup};
use photomat_estimator::train::{
    EstimatorTrainer, StepReport, TRAIN_STATE_FILE, TrainConfig, TrainManifest, copy_gan_model,
};
use photomat_estimator::{EstimatorConfig, EstimatorModel};
use photomat_generator::GanModel;

use super::previews::map_previews;

/// Default stage-1 steps for a new run (the paper trains 60 k; CPU runs set fewer).
const DEFAULT_STEPS: u64 = 60_000;
/// Default fine-tune steps for a new run (the paper trains 60 k).
const DEFAULT_FINETUNE_STEPS: u64 = 60_000;
/// Materials shown in each training panel.
const PANEL_MATERIALS: u64 = 2;
/// Key mixed into the run seed for the panels' fixed materials (distinct from every step's).
const PANEL_SEED_KEY: u64 = 0x7061_6E65_6C73; // "panels"
/// Light of the panels: off-centre, so that both the highlight and the falloff show.
const PANEL_LIGHT: Highlight = Highlight { x: 0.2, y: 0.2 };

#[derive(Debug, clap::Args)]
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

    /// Steps between training panels in RUN_E/panels/.
    #[arg(long, value_name = "K", default_value_t = 500,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub panel_every: u64,

    /// Steps between checkpoints.
    #[arg(long, value_name = "K", default_value_t = 500,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: u64,

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

/// `config` with every training flag that was given applied.
fn apply_flags(mut config: TrainConfig, args: &Args) -> TrainConfig {
    if let Some(v) = args.steps {
        config.steps = v;
    }
    if let Some(v) = args.finetune_steps {
        config.finetune_steps = v;
    }
    if let Some(v) = args.batch {
        config.batch = v;
    }
    if let Some(v) = args.lr {
        config.lr = v;
    }
    if let Some(v) = args.finetune_lr {
        config.finetune_lr = v;
    }
    if let Some(v) = args.seed {
        config.seed = v;
    }
    if let Some(path) = &args.vgg19 {
        config.vgg19 = Some(absolute(path));
    }
    config
}

/// E's architecture for `gan` and a model of `channels` parameters at width `width`.
fn architecture(gan: &GanModel, channels: usize, width: f64) -> anyhow::Result<EstimatorConfig> {
    EstimatorConfig {
        in_channels: gan.config().feature_channels,
        out_channels: channels,
        ..EstimatorConfig::default()
    }
    .with_width(width)
    .context("invalid --width")
}

/// `path` made absolute (links resolved) when it exists, so that `train.json` names the GAN
/// folder whatever the working directory of a later `--resume`; unchanged otherwise (loading
/// it then reports the missing folder).
fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// A new run from the flags.
fn fresh(args: &Args, device: &Device) -> anyhow::Result<(EstimatorTrainer, PathBuf)> {
    let Some(gan_dir) = args.gan.as_deref().map(absolute) else {
        bail!("--gan RUN is required for a new run (a `photomat train-gan` output folder)");
    };
    let Some(spec) = &args.brdf else {
        bail!("--brdf SPEC is required for a new run (`photomat brdfs` lists the models)");
    };
    let brdf = lookup(spec).context("invalid --brdf")?;
    let gan = GanModel::load(&gan_dir, device)
        .with_context(|| format!("cannot load the GAN model {}", gan_dir.display()))?;
    let config = apply_flags(
        TrainConfig {
            steps: DEFAULT_STEPS,
            finetune_steps: DEFAULT_FINETUNE_STEPS,
            ..TrainConfig::default()
        },
        args,
    );
    config
        .validate(gan.config().resolution)
        .context("invalid training settings")?;
    let arch = architecture(&gan, brdf.channels(), args.width.unwrap_or(1.0))?;
    let model = EstimatorModel::new_seeded(brdf, arch, config.seed, device)?;
    let trainer = EstimatorTrainer::new(gan, model, config)?;
    Ok((trainer, gan_dir))
}

/// The run in `args.out`, after checking that no given flag contradicts its `train.json`.
fn resumed(args: &Args, device: &Device) -> anyhow::Result<(EstimatorTrainer, PathBuf)> {
    let saved = TrainManifest::load(&args.out)?;
    let file = args
        .out
        .join(photomat_estimator::train::TRAIN_MANIFEST_FILE);
    let mut conflicts = Vec::new();
    if let Some(gan) = args.gan.as_deref().map(absolute)
        && gan != saved.gan
    {
        conflicts.push(format!(
            "--gan {} contradicts gan = {}",
            gan.display(),
            saved.gan.display()
        ));
    }
    let brdf = lookup(&saved.brdf)
        .with_context(|| format!("{}: the run's BRDF model cannot be built", file.display()))?;
    if let Some(spec) = &args.brdf {
        let given = lookup(spec).context("invalid --brdf")?.name();
        if given != saved.brdf {
            conflicts.push(format!("--brdf {given} contradicts brdf = {}", saved.brdf));
        }
    }
    let gan = GanModel::load(&saved.gan, device)
        .with_context(|| format!("cannot load the run's GAN model {}", saved.gan.display()))?;
    if let Some(width) = args.width {
        let given = architecture(&gan, brdf.channels(), width)?;
        if given != saved.architecture {
            conflicts.push(format!(
                "--width {width} gives encoder widths {:?}, which contradicts the run's {:?}",
                given.encoder_channels, saved.architecture.encoder_channels
            ));
        }
    }
    let config = apply_flags(saved.config.clone(), args);
    if let Err(e) = config.check_resume(&saved.config) {
        conflicts.push(e.to_string());
    }
    if !conflicts.is_empty() {
        bail!(
            "cannot resume {}: {} (leave the flag out to keep the run's value)",
            file.display(),
            conflicts.join("; ")
        );
    }
    config
        .validate(gan.config().resolution)
        .context("invalid training settings")?;
    let model = EstimatorModel::new(
        brdf,
        saved.architecture.clone(),
        candle_nn::VarMap::new(),
        device,
    )?;
    let mut trainer = EstimatorTrainer::new(gan, model, config)?;
    trainer.load_checkpoint(&args.out)?;
    Ok((trainer, saved.gan))
}

/// Writes the training state, E's model files and `train.json` into `run`.
fn checkpoint(trainer: &EstimatorTrainer, run: &Path, gan_dir: &Path) -> anyhow::Result<()> {
    trainer
        .save_checkpoint(run, gan_dir)
        .with_context(|| format!("cannot save the checkpoint in {}", run.display()))
}

/// Tiles laid out one row per inner vector, [`CONTACT_SHEET_GAP`] pixels of `background`
/// between them; rows may differ in length (the sheet is as wide as the longest).
fn rows_sheet(rows: &[Vec<PlanarImage>], background: f32) -> anyhow::Result<PlanarImage> {
    let first = rows
        .iter()
        .flatten()
        .next()
        .context("a panel needs at least one image")?;
    let (c, h, w) = (first.channels, first.height, first.width);
    let gap = CONTACT_SHEET_GAP;
    let columns = rows.iter().map(Vec::len).max().unwrap_or(1);
    let (sheet_h, sheet_w) = (rows.len() * (h + gap) - gap, columns * (w + gap) - gap);
    let mut sheet = PlanarImage::filled(c, sheet_h, sheet_w, background);
    for (r, row) in rows.iter().enumerate() {
        for (k, tile) in row.iter().enumerate() {
            if (tile.channels, tile.height, tile.width) != (c, h, w) {
                bail!("panel tiles differ in shape");
            }
            for ch in 0..c {
                for y in 0..h {
                    let dst = (ch * sheet_h + r * (h + gap) + y) * sheet_w + k * (w + gap);
                    let src = (ch * h + y) * w;
                    sheet.data[dst..dst + w].copy_from_slice(&tile.data[src..src + w]);
                }
            }
        }
    }
    Ok(sheet)
}

/// Writes `run/panels/step-NNNNNN.png`: per material, M's relighting | the analytic render
/// of E's maps (both under [`PANEL_LIGHT`]) | previews of the maps.
fn write_panel(trainer: &EstimatorTrainer, run: &Path) -> anyhow::Result<PathBuf> {
    let dir = run.join("panels");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let path = dir.join(format!("step-{:06}.png", trainer.steps_done()));
    let brdf = trainer.model().brdf();
    let mut rows = Vec::new();
    for k in 0..PANEL_MATERIALS {
        let seed = trainer.config().seed ^ PANEL_SEED_KEY ^ k;
        let p = trainer.preview(seed, PANEL_LIGHT)?;
        let mut row = vec![
            PlanarImage::from_tensor(&p.neural)?,
            PlanarImage::from_tensor(&p.analytic)?,
        ];
        row.extend(
            map_previews(brdf.as_ref(), &p.maps)?
                .into_iter()
                .map(|(_, image)| image),
        );
        rows.push(row);
    }
    write_png(&path, &rows_sheet(&rows, 0.0)?, PngBits::Eight)?;
    Ok(path)
}

/// `log.csv` header.
const LOG_HEADER: &str = "step,stage,l1,gram,total,skipped,seconds";

/// Opens `run/log.csv` for appending: a new file with the header, or on resume the existing
/// rows up to step `keep` (rows of steps after the checkpoint are dropped: they are redone).
fn open_log(run: &Path, keep: Option<u64>) -> anyhow::Result<std::fs::File> {
    let path = run.join("log.csv");
    let mut text = format!("{LOG_HEADER}\n");
    if let Some(keep) = keep
        && let Ok(old) = std::fs::read_to_string(&path)
    {
        for line in old.lines().skip(1) {
            let step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
            if step.is_some_and(|s| s <= keep) {
                text.push_str(line);
                text.push('\n');
            }
        }
    }
    photomat_core::image_io::write_atomic(&path, text.as_bytes())?;
    std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))
}

fn log_row(log: &mut std::fs::File, r: &StepReport, seconds: f64) -> anyhow::Result<()> {
    writeln!(
        log,
        "{},{},{},{},{},{},{seconds:.4}",
        r.step,
        r.stage.name(),
        r.l1,
        r.gram,
        r.total,
        r.skipped
    )
    .context("cannot append to log.csv")
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let device = Device::Cpu;
    let run = &args.out;
    let state_exists = run.join(TRAIN_STATE_FILE).exists();
    let (mut trainer, gan_dir) = if args.resume {
        if !state_exists {
            bail!(
                "cannot resume: {} does not exist (start the run without --resume)",
                run.join(TRAIN_STATE_FILE).display()
            );
        }
        resumed(args, &device)?
    } else {
        if state_exists {
            bail!(
                "{} already holds an estimator run; continue it with --resume or choose another --out",
                run.display()
            );
        }
        fresh(args, &device)?
    };
    let mut log = if args.resume {
        open_log(run, Some(trainer.steps_done()))?
    } else {
        // The model folder is complete from the start: the GAN copy, E and the settings.
        copy_gan_model(&gan_dir, run)
            .with_context(|| format!("cannot copy the GAN model into {}", run.display()))?;
        checkpoint(&trainer, run, &gan_dir)?;
        open_log(run, None)?
    };
    let stop = super::train_gan::stop_flag()?;
    let config = trainer.config().clone();
    let total = config.total_steps();
    let start_step = trainer.steps_done();
    writeln!(
        out,
        "training E for {} ({} parameters) against {} ({}², batch {}, seed {}, Gram features: {}): steps {start_step} → {total} ({} aligned + {} fine-tune)",
        trainer.model().brdf().name(),
        trainer.model().estimator().config().num_parameters(),
        gan_dir.display(),
        trainer.gan().config().resolution,
        config.batch,
        config.seed,
        trainer.extractor().describe(),
        config.steps,
        config.finetune_steps,
    )?;

    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} steps ({eta} left) {msg}",
        )
        .expect("the template is valid")
        .progress_chars("=> "),
    );
    bar.set_position(start_step);
    let mut interrupted = false;
    let mut seconds_total = 0.0;
    let mut last = None;
    while !trainer.is_done() {
        let t0 = Instant::now();
        let report = trainer
            .step()
            .with_context(|| format!("training step {} failed", trainer.steps_done() + 1))?;
        let seconds = t0.elapsed().as_secs_f64();
        seconds_total += seconds;
        if report.skipped {
            bar.println(format!(
                "step {}: loss not finite (L1 {}, Gram {}), update skipped",
                report.step, report.l1, report.gram
            ));
        }
        log_row(&mut log, &report, seconds)?;
        bar.set_position(report.step);
        bar.set_message(format!(
            "{} | L1 {:.4} Gram {:.4} total {:.4} | {seconds:.2} s/step",
            report.stage.name(),
            report.l1,
            report.gram,
            report.total
        ));
        let done = report.step;
        last = Some(report);
        if done % args.panel_every == 0 {
            write_panel(&trainer, run)?;
        }
        if done % args.checkpoint_every == 0 {
            checkpoint(&trainer, run, &gan_dir)?;
        }
        if stop.load(Ordering::SeqCst) {
            interrupted = true;
            break;
        }
    }
    bar.finish_and_clear();
    checkpoint(&trainer, run, &gan_dir)?;
    let panel = write_panel(&trainer, run)?;
    let steps_run = trainer.steps_done() - start_step;
    if interrupted {
        writeln!(
            out,
            "interrupted at step {} of {total}: state saved in {}; continue with\n  photomat train-estimator --out {} --resume",
            trainer.steps_done(),
            run.display(),
            run.display()
        )?;
    } else {
        writeln!(
            out,
            "trained {steps_run} steps ({} in total){}{}",
            trainer.steps_done(),
            if steps_run > 0 {
                format!(", {:.2} s/step", seconds_total / steps_run as f64)
            } else {
                String::new()
            },
            last.map(|r| format!(
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
    writeln!(out, "  {}  latest panel", panel.display())?;
    Ok(())
}
