//! `photomat train-gan --data DATASET --out RUN (--steps N | --kimg K) [--size 64]
//! [--multiplier 0.25] [--batch 4] [--seed S] [--tileable] [--lr 0.0025] [--pl-weight W]
//! [--checkpoint-every N] [--sample-every N] [--swd-every N] [--swd-count N] [--resume]`: trains the
//! relightable generator G, the relighting MLP M and the light-conditioned discriminator D on
//! a prepared flash-photo data set (PhotoMat §3–4, issue 6; the step is
//! `photomat_generator::train::Trainer`).
//!
//! The run folder RUN holds:
//! - `train.json` (the full configuration) and `train_state.safetensors` (G, G_ema, M, D,
//!   Adam moments, counters): written atomically every `--checkpoint-every` steps, at the
//!   end, and when Ctrl-C is pressed (the current step finishes first);
//! - `gan.json` + `gan.safetensors`: the inference model (G_ema + M) with its provenance,
//!   written with every checkpoint, so RUN is a GAN model folder for `photomat relight --gan
//!   RUN` and `photomat train-estimator --gan RUN`;
//! - `log.csv`: one row per step (losses, logits, R1, seconds, and every `--swd-every` steps
//!   the sliced Wasserstein distance ×10³ of `--swd-count` relit G_ema samples against as
//!   many real crops, a fixed seeded set: `photomat_generator::swd::model_swd`, the value
//!   `photomat eval-gan` prints);
//! - `samples/step-NNNNNN.png`: five fixed materials of G_ema under four lights each, a real
//!   crop at the end of each row.
//!
//! `--resume` continues RUN from its last checkpoint with the same optimiser state and
//! draws, until `--steps`/`--kimg` in total: the result is identical to an uninterrupted
//! run. Architecture and training flags given with `--resume` must agree with `train.json`;
//! a contradiction is an error naming the field.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::Device;
use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::image_io::{PngBits, write_png};
use photomat_data::source::DatasetSource;
use photomat_generator::swd::{SwdConfig, model_swd};
use photomat_generator::train::config::TrainConfig;
use photomat_generator::train::log::{LogRow, TrainLog};
use photomat_generator::train::samples::sample_grid;
use photomat_generator::train::state::{CONFIG_FILE, STATE_FILE, read_config};
use photomat_generator::train::{Trainer, enable_second_order_gradients};
use photomat_generator::{GeneratorConfig, MAX_RESOLUTION, MIN_RESOLUTION};

/// Default model side for a fresh run (CPU-sized).
const DEFAULT_SIZE: usize = 64;
/// Default channel multiplier for a fresh run (CPU-sized; the reference is 1).
const DEFAULT_MULTIPLIER: f64 = 0.25;
/// Key mixed into the run seed for the SWD's fixed draws (one fixed set of fakes and reals
/// per run, so successive measurements compare).
const SWD_SEED_KEY: u64 = 0x7472_6169_6E5F_7377; // "train_sw"
/// Default batch (the reference trains 32 on 8 GPUs; 4 keeps a CPU step in seconds).
const DEFAULT_BATCH: usize = 4;

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("length").args(["steps", "kimg"]).required(true)))]
pub struct Args {
    /// Prepared data set folder (`photomat prepare` output); its photos must be at least
    /// twice the model size. Taken from RUN/train.json with --resume.
    #[arg(long, value_name = "DATASET")]
    pub data: Option<PathBuf>,

    /// Run folder: checkpoints, samples, log and the trained GAN model.
    #[arg(long, value_name = "RUN")]
    pub out: PathBuf,

    /// Total training steps (a resumed run continues up to this count).
    #[arg(long, value_name = "N")]
    pub steps: Option<u64>,

    /// Total training length in thousands of real images (steps = ⌈1000·K / batch⌉).
    #[arg(long, value_name = "K")]
    pub kimg: Option<f64>,

    /// Model side: a power of two in 32 … 1024 [default: 64].
    #[arg(long, value_name = "PIXELS")]
    pub size: Option<usize>,

    /// Channel multiplier of G and D (1 = the reference's widths) [default: 0.25].
    #[arg(long, value_name = "M")]
    pub multiplier: Option<f64>,

    /// Dimension of z and w [default: 512].
    #[arg(long, value_name = "D")]
    pub latent_dim: Option<usize>,

    /// Images per step [default: 4].
    #[arg(long, value_name = "B")]
    pub batch: Option<usize>,

    /// Seed of the run: initial weights and every random draw [default: 0].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,

    /// Tileable generator: circular padding, F rolled per sample before M.
    #[arg(long)]
    pub tileable: bool,

    /// Base learning rate of G, M and D before the lazy-regularisation correction
    /// [default: 0.0025].
    #[arg(long, value_name = "LR")]
    pub lr: Option<f64>,

    /// Weight of StyleGAN2's path-length regularisation of G, every 4 steps on half a batch
    /// (the reference uses 2; a step then takes about 1.25× as long) [default: 0, off].
    #[arg(long, value_name = "W")]
    pub pl_weight: Option<f64>,

    /// Learning-rate multiplier of every layer of M [default: the reference's 0.01]. M's
    /// weights move by about lr·multiplier/√64 per step, so short CPU runs (a few thousand
    /// steps) need a larger one (e.g. 0.1) for M to learn to move the highlight.
    #[arg(long, value_name = "M")]
    pub relight_lr_multiplier: Option<f64>,

    /// R1 weight γ on D's gradient at real images, applied every 16 steps
    /// [default: the reference's 0.0002·size²/batch]. Raise it (e.g. ×10) when D overpowers G
    /// on a small data set (real/fake logit gap growing without bound in log.csv).
    #[arg(long, value_name = "GAMMA")]
    pub r1_gamma: Option<f64>,

    /// Steps between checkpoints (state, GAN model folder).
    #[arg(long, value_name = "N", default_value_t = 500,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: u64,

    /// Steps between sample grids in RUN/samples/.
    #[arg(long, value_name = "N", default_value_t = 500,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub sample_every: u64,

    /// Steps between SWD measurements of G_ema against the data set (logged in log.csv;
    /// 0: never).
    #[arg(long, value_name = "N", default_value_t = 1000)]
    pub swd_every: u64,

    /// Fakes and real crops per SWD measurement (a fixed, seeded set).
    #[arg(long, value_name = "N", default_value_t = 64,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub swd_count: u64,

    /// Continue the run in RUN from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
}

/// Set by the Ctrl-C handler; the training loop stops after the current step.
static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// The stop flag, installing the Ctrl-C handler on first use (once per process).
pub(crate) fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    if let Some(flag) = STOP.get() {
        flag.store(false, Ordering::SeqCst);
        return Ok(flag.clone());
    }
    let flag = Arc::new(AtomicBool::new(false));
    let handler_flag = flag.clone();
    ctrlc::set_handler(move || {
        // A second Ctrl-C while the step finishes exits at once: checkpoints are written
        // atomically, so the last one stays intact (130 = 128 + SIGINT, the shell's code).
        if handler_flag.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted twice: exiting without saving the current step");
            std::process::exit(130);
        }
        eprintln!("\nCtrl-C: finishing the current step, then saving (Ctrl-C again to quit now)");
    })
    .context("cannot install the Ctrl-C handler")?;
    Ok(STOP.get_or_init(|| flag).clone())
}

/// `path` made absolute (symbolic links resolved) when it exists, so that `train.json` names
/// the data set whatever the working directory of a later `--resume`; unchanged otherwise
/// (opening it then reports the missing folder).
fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The configuration of a fresh run from the flags, with the reference hyper-parameters.
fn fresh_config(args: &Args) -> anyhow::Result<TrainConfig> {
    let Some(data) = &args.data else {
        bail!("--data DATASET is required for a new run (a prepared data set folder)");
    };
    let size = args.size.unwrap_or(DEFAULT_SIZE);
    if !size.is_power_of_two() || !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&size) {
        bail!(
            "--size {size} is not supported: use a power of two in {MIN_RESOLUTION} … \
             {MAX_RESOLUTION} (32, 64, 128, 256, 512, 1024)"
        );
    }
    let generator = GeneratorConfig {
        resolution: size,
        channel_multiplier: args.multiplier.unwrap_or(DEFAULT_MULTIPLIER),
        tileable: args.tileable,
        latent_dim: args
            .latent_dim
            .unwrap_or(GeneratorConfig::default().latent_dim),
        relight_lr_multiplier: args
            .relight_lr_multiplier
            .unwrap_or(GeneratorConfig::default().relight_lr_multiplier),
        ..Default::default()
    };
    let mut config = TrainConfig::new(
        generator,
        absolute(data),
        args.batch.unwrap_or(DEFAULT_BATCH),
        args.seed.unwrap_or(0),
    );
    if let Some(lr) = args.lr {
        config.lr = lr;
    }
    if let Some(w) = args.pl_weight {
        config.pl_weight = w;
    }
    if let Some(gamma) = args.r1_gamma {
        config.r1_gamma = gamma;
    }
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid training settings: {e}"))?;
    Ok(config)
}

/// The saved configuration of RUN, after checking that no given flag contradicts it.
/// `--data` is the exception: it relocates a data set that was moved since the run started
/// (the photos are the user's to keep the same), and the new path is saved at the next
/// checkpoint.
fn resumed_config(args: &Args) -> anyhow::Result<TrainConfig> {
    let mut saved = read_config(&args.out)?;
    if let Some(data) = &args.data {
        let moved = absolute(data);
        if moved != saved.data {
            eprintln!(
                "note: data set relocated from {} to {}",
                saved.data.display(),
                moved.display()
            );
            saved.data = moved;
        }
    }
    let file = args.out.join(CONFIG_FILE);
    let g = &saved.generator;
    let mut conflicts = Vec::new();
    let mut check = |flag: &str, field: &str, given: Option<String>, saved: String| {
        if let Some(v) = given
            && v != saved
        {
            conflicts.push(format!(
                "{flag} {v} contradicts {field} = {saved} of the run"
            ));
        }
    };
    check(
        "--size",
        "generator.resolution",
        args.size.map(|v| v.to_string()),
        g.resolution.to_string(),
    );
    check(
        "--multiplier",
        "generator.channel_multiplier",
        args.multiplier.map(|v| v.to_string()),
        g.channel_multiplier.to_string(),
    );
    check(
        "--latent-dim",
        "generator.latent_dim",
        args.latent_dim.map(|v| v.to_string()),
        g.latent_dim.to_string(),
    );
    check(
        "--relight-lr-multiplier",
        "generator.relight_lr_multiplier",
        args.relight_lr_multiplier.map(|v| v.to_string()),
        g.relight_lr_multiplier.to_string(),
    );
    check(
        "--tileable",
        "generator.tileable",
        args.tileable.then(|| "true".to_string()),
        g.tileable.to_string(),
    );
    check(
        "--batch",
        "batch",
        args.batch.map(|v| v.to_string()),
        saved.batch.to_string(),
    );
    check(
        "--seed",
        "seed",
        args.seed.map(|v| v.to_string()),
        saved.seed.to_string(),
    );
    check(
        "--lr",
        "lr",
        args.lr.map(|v| v.to_string()),
        saved.lr.to_string(),
    );
    check(
        "--r1-gamma",
        "r1_gamma",
        args.r1_gamma.map(|v| v.to_string()),
        saved.r1_gamma.to_string(),
    );
    check(
        "--pl-weight",
        "pl_weight",
        args.pl_weight.map(|v| v.to_string()),
        saved.pl_weight.to_string(),
    );
    if !conflicts.is_empty() {
        bail!(
            "cannot resume {}: {} (leave the flag out to keep the run's value)",
            file.display(),
            conflicts.join("; ")
        );
    }
    Ok(saved)
}

/// Total steps from `--steps` or `--kimg`.
fn total_steps(args: &Args, batch: usize) -> anyhow::Result<u64> {
    match (args.steps, args.kimg) {
        (Some(s), _) => Ok(s),
        (None, Some(k)) if k.is_finite() && k > 0.0 => {
            Ok((k * 1000.0 / batch as f64).ceil() as u64)
        }
        (None, Some(k)) => bail!("--kimg {k} must be positive"),
        (None, None) => bail!("give the run's length with --steps N or --kimg K"),
    }
}

/// The provenance recorded in the GAN model folder.
fn provenance(trainer: &Trainer) -> serde_json::Value {
    let c = trainer.config();
    serde_json::json!({
        "trained_by": "photomat train-gan",
        "step": trainer.steps_done(),
        "kimg": trainer.images_seen() as f64 / 1000.0,
        "data": c.data,
        "seed": c.seed,
        "batch": c.batch,
    })
}

/// Writes the training state and the GAN model folder into `run`.
fn checkpoint(trainer: &Trainer, run: &Path) -> anyhow::Result<()> {
    trainer
        .save_state(run)
        .with_context(|| format!("cannot save the training state in {}", run.display()))?;
    trainer
        .save_model(run, provenance(trainer))
        .with_context(|| format!("cannot save the GAN model in {}", run.display()))
}

/// Writes `run/samples/step-NNNNNN.png`.
fn write_samples(
    trainer: &Trainer,
    data: &DatasetSource,
    run: &Path,
    device: &Device,
) -> anyhow::Result<PathBuf> {
    let dir = run.join("samples");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let path = dir.join(format!("step-{:06}.png", trainer.steps_done()));
    let grid = sample_grid(trainer.ema_model(), data, trainer.config().seed, device)?;
    write_png(&path, &grid, PngBits::Eight)?;
    Ok(path)
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    // Before any backward pass of this thread (the R1 penalty is a double backward).
    enable_second_order_gradients();
    let device = Device::Cpu;
    let run = &args.out;
    let state_exists = run.join(STATE_FILE).exists();
    let config = if args.resume {
        if !state_exists {
            bail!(
                "cannot resume: {} does not exist (start the run without --resume)",
                run.join(STATE_FILE).display()
            );
        }
        resumed_config(args)?
    } else {
        if state_exists {
            bail!(
                "{} already holds a training run; continue it with --resume or choose another --out",
                run.display()
            );
        }
        fresh_config(args)?
    };
    let total = total_steps(args, config.batch)?;
    let data = DatasetSource::for_training(&config).context("cannot open the training data")?;
    std::fs::create_dir_all(run).with_context(|| format!("cannot create {}", run.display()))?;

    let mut trainer = Trainer::new(config.clone(), &device)?;
    let log_path = run.join("log.csv");
    let mut log = if args.resume {
        trainer.load_state(run)?;
        TrainLog::resume(&log_path, trainer.steps_done())?
    } else {
        // The configuration is on disk from the start, so a crash before the first
        // checkpoint still leaves a folder that says what it was.
        checkpoint(&trainer, run)?;
        TrainLog::create(&log_path)?
    };
    let stop = stop_flag()?;
    let start_step = trainer.steps_done();
    writeln!(
        out,
        "training {}² (multiplier {}, batch {}, seed {}{}) on {} ({} photos): steps {} → {total}",
        config.generator.resolution,
        config.generator.channel_multiplier,
        config.batch,
        config.seed,
        if config.generator.tileable {
            ", tileable"
        } else {
            ""
        },
        config.data.display(),
        data.dataset().len(),
        start_step
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
    let mut phases = [0.0f64; 5];
    while trainer.steps_done() < total {
        let t0 = Instant::now();
        let stats = trainer
            .step(&data)
            .with_context(|| format!("training step {} failed", trainer.steps_done() + 1))?;
        let seconds = t0.elapsed().as_secs_f64();
        seconds_total += seconds;
        let p = stats.seconds;
        for (acc, v) in phases.iter_mut().zip([p.g, p.d, p.data, p.r1, p.ema]) {
            *acc += v;
        }
        for s in &stats.skipped {
            bar.println(format!("step {}: skipped the update: {s}", stats.step + 1));
        }
        let done = trainer.steps_done();
        let kimg = trainer.images_seen() as f64 / 1000.0;
        let swd = if args.swd_every > 0 && done % args.swd_every == 0 {
            bar.set_message(format!("measuring SWD on {} images", args.swd_count));
            let report = model_swd(
                trainer.ema_model(),
                &data,
                args.swd_count as usize,
                trainer.config().seed ^ SWD_SEED_KEY,
                &SwdConfig::default(),
                &mut |_, _| bar.tick(),
            )
            .context("cannot measure the SWD")?;
            bar.println(format!(
                "step {done}: SWD×10³ {:.2} (per level {:?})",
                report.mean, report.per_level
            ));
            Some(report.mean)
        } else {
            None
        };
        log.append(&LogRow {
            step: done,
            kimg,
            loss_g: stats.loss_g,
            loss_d: stats.loss_d,
            real_logit: stats.real_logit,
            fake_logit: stats.fake_logit,
            r1: stats.r1,
            seconds,
            swd,
            path_length: stats.path_length,
        })?;
        bar.set_position(done);
        bar.set_message(format!(
            "kimg {kimg:.3} | D {:.3} G {:.3} | gap {:+.3} | {seconds:.2} s/step",
            stats.loss_d,
            stats.loss_g,
            stats.real_logit - stats.fake_logit
        ));
        if done % args.sample_every == 0 {
            write_samples(&trainer, &data, run, &device)?;
        }
        if done % args.checkpoint_every == 0 {
            checkpoint(&trainer, run)?;
        }
        if stop.load(Ordering::SeqCst) {
            interrupted = true;
            break;
        }
    }
    bar.finish_and_clear();
    checkpoint(&trainer, run)?;
    let samples = write_samples(&trainer, &data, run, &device)?;
    let steps_run = trainer.steps_done() - start_step;
    if interrupted {
        writeln!(
            out,
            "interrupted at step {} of {total}: state saved in {}; continue with\n  photomat train-gan --out {} --resume --steps {total}",
            trainer.steps_done(),
            run.display(),
            run.display()
        )?;
    } else {
        writeln!(
            out,
            "trained {steps_run} steps ({} in total, {:.3} kimg){}",
            trainer.steps_done(),
            trainer.images_seen() as f64 / 1000.0,
            if steps_run > 0 {
                let n = steps_run as f64;
                format!(
                    ", {:.2} s/step (G {:.2}, D {:.2}, crops {:.2}, R1 {:.2}, EMA {:.2})",
                    seconds_total / n,
                    phases[0] / n,
                    phases[1] / n,
                    phases[2] / n,
                    phases[3] / n,
                    phases[4] / n
                )
            } else {
                String::new()
            }
        )?;
    }
    writeln!(
        out,
        "  {}/gan.json, gan.safetensors  G_ema + M (photomat relight --gan {})",
        run.display(),
        run.display()
    )?;
    writeln!(out, "  {}/log.csv  losses per step", run.display())?;
    writeln!(out, "  {}  latest samples", samples.display())?;
    Ok(())
}
