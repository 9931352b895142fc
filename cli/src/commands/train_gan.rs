//! `photomat train-gan --data DATASET --out RUN (--steps N | --kimg K) [--size 64]
//! [--multiplier 0.25] [--batch 4] [--seed S] [--tileable | --spatial] [--lr 0.0025] [--pl-weight W]
//! [--checkpoint-every N] [--sample-every N] [--swd-every N] [--swd-count N] [--resume]`: trains the
//! relightable generator G, the relighting MLP M and the light-conditioned discriminator D on
//! a prepared flash-photo data set (PhotoMat §3–4). The run is the library's
//! `photomat_generator::train::GanTraining` driver; this command parses the flags, opens the
//! data set, installs the signal handler and shows progress.
//!
//! The run folder RUN holds:
//! - `train.json` (the full configuration) and `train_state.safetensors` (G, G_ema, M, D,
//!   Adam moments, counters): written atomically every `--checkpoint-every` steps, at the
//!   end, and on SIGINT (Ctrl-C), SIGTERM or SIGHUP (the current step finishes first; the
//!   command then exits with 128 + the signal number: 130, 143, 129);
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
//! `--resume` continues RUN from its last checkpoint with the same optimiser state, draws and
//! cadence of outputs (saved in `train.json`), until `--steps`/`--kimg` in total: the result
//! is identical to an uninterrupted run. Architecture and training flags given with
//! `--resume` must agree with `train.json` (a contradiction is an error naming the field),
//! except `--lr` (lower it to continue a diverged run; log.csv records it) and the cadence
//! flags. RUN is locked while the command runs: a second one on it fails naming this one's
//! process id. A step whose update a non-finite value skipped is reported on stderr and in
//! log.csv, and no checkpoint is written until a step updates again (docs/robustness.md).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use candle_core::Device;
use indicatif::ProgressBar;
use photomat_data::source::DatasetSource;
use photomat_generator::train::state::Restored;
use photomat_generator::train::{GanEvent, GanOutcome, GanSettings, GanTraining, RunLength};

use crate::common::{interruption, steps_bar, stop_flag};

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("length").args(["steps", "kimg"]).required(true)))]
#[command(after_help = crate::common::STOP_HELP)]
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

    /// Exponents s of the Phong lobes ω_z^s that the relighting MLP reads next to the light
    /// direction, comma-separated, or `none` for the paper's MLP on features ‖ ω [default:
    /// 4,16,64,256,1024: highlight peaks from 0.5 to 0.03 rad wide, which an MLP on ω alone
    /// learns slowly].
    #[arg(long, value_name = "S,S,…", value_parser = parse_lobes)]
    pub relight_lobes: Option<Lobes>,

    /// Weight of the discriminator's light-mismatch term: real photos shown under another
    /// sample's flash count as fakes, so that the relighting must follow the light (0: off,
    /// StyleGAN2's loss) [default: 1].
    #[arg(long, value_name = "W")]
    pub light_mismatch: Option<f64>,

    /// Spatial (any-size) generator: a field of local latents replaces the 4×4 constant, and
    /// the run trains on --size × --size patches cut from the photos at their prepared
    /// resolution (no shrinking), each with the photo's own flash geometry. Implies
    /// --tileable. The model then samples materials of any multiple of size/4 texels.
    #[arg(long)]
    pub spatial: bool,

    /// Leave out StyleGAN2's per-pixel noise inputs: all variation then comes from the
    /// latents (the local latents of a spatial generator), as in spatial texture GANs. On a
    /// CPU-sized spatial run the learned noise became a per-texel speckle.
    #[arg(long)]
    pub no_noise: bool,

    /// Gain k of the discriminator's input sharpening: D reads x + k·(x − 3×3 mean of x), the
    /// images' detail amplified k + 1 times, so that it sees texture that is faint next to
    /// the colour and the highlight [default: 0, StyleGAN2's D; 9 is what was measured].
    #[arg(long, value_name = "K")]
    pub d_sharpen: Option<f64>,

    /// Relief in the neural material: M shades each texel in the frame of a normal from a
    /// learned height channel of F, so that the light dependence M learns can be relief that
    /// the estimator's normals then show. May be switched on when resuming a run without it
    /// (its projection starts at zero: outputs unchanged until it trains).
    #[arg(long)]
    pub relief: bool,

    /// Channels of the spatial generator's local latents (one vector per size/4 cell)
    /// [default: 32].
    #[arg(long, value_name = "N", requires = "spatial",
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub local_dim: Option<u32>,

    /// Periodic channels of the spatial generator: N plane waves whose wave vectors follow
    /// the material's style, added at every block, for lattices that repeat across many
    /// cells (tiles, weave; PSGAN's periodic latents) [default: 0].
    #[arg(long, value_name = "N", requires = "spatial",
          value_parser = clap::value_parser!(u32).range(0..=256))]
    pub waves: Option<u32>,

    /// Probability that a training patch holds the photo's highlight [default: 0.5]; under
    /// uniform positions a 64² patch of a 512² photo holds it in about 2 % of draws.
    #[arg(long, value_name = "P", requires = "spatial")]
    pub highlight_prob: Option<f64>,

    /// Steps between checkpoints (state, GAN model folder) [default: 500; on --resume the
    /// run's, from train.json].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,

    /// Steps between sample grids in RUN/samples/ [default: 500; on --resume the run's].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub sample_every: Option<u64>,

    /// Steps between SWD measurements of G_ema against the data set (logged in log.csv;
    /// 0: never) [default: 1000; on --resume the run's].
    #[arg(long, value_name = "N")]
    pub swd_every: Option<u64>,

    /// Fakes and real crops per SWD measurement (a fixed, seeded set) [default: 64; on
    /// --resume the run's].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub swd_count: Option<u64>,

    /// Steps between snapshots of G_ema + M, each a model folder RUN/snapshots/step-NNNNNN/
    /// (0: none; about 2 MB each for the bundled recipe). The model's quality swings between
    /// checkpoints, so keep snapshots and pick one with `photomat rank-snapshots` [default:
    /// 0; on --resume the run's].
    #[arg(long, value_name = "N")]
    pub snapshot_every: Option<u64>,

    /// Continue the run in RUN from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
}

/// The exponents of `--relight-lobes` (a newtype: clap reads a `Vec` as repeated values).
#[derive(Debug, Clone, PartialEq)]
pub struct Lobes(pub Vec<f64>);

/// `none`, or comma-separated finite exponents ≥ 1.
fn parse_lobes(text: &str) -> Result<Lobes, String> {
    if text.trim() == "none" {
        return Ok(Lobes(Vec::new()));
    }
    text.split(',')
        .map(|part| match part.trim().parse::<f64>() {
            Ok(s) if s.is_finite() && s >= 1.0 => Ok(s),
            _ => Err(format!(
                "'{}' is not a lobe exponent (a number ≥ 1; or give `none`)",
                part.trim()
            )),
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Lobes)
}

impl Args {
    /// The run's settings as the flags give them.
    fn settings(&self) -> GanSettings {
        GanSettings {
            data: self.data.clone(),
            size: self.size,
            multiplier: self.multiplier,
            latent_dim: self.latent_dim,
            batch: self.batch,
            seed: self.seed,
            tileable: self.tileable,
            lr: self.lr,
            pl_weight: self.pl_weight,
            relight_lr_multiplier: self.relight_lr_multiplier,
            r1_gamma: self.r1_gamma,
            spatial: self.spatial,
            local_dim: self.local_dim.map(|v| v as usize),
            waves: self.waves.map(|v| v as usize),
            highlight_prob: self.highlight_prob,
            light_mismatch: self.light_mismatch,
            relight_lobes: self.relight_lobes.clone().map(|l| l.0),
            no_noise: self.no_noise,
            d_sharpen: self.d_sharpen,
            relief: self.relief,
            checkpoint_every: self.checkpoint_every,
            sample_every: self.sample_every,
            swd_every: self.swd_every,
            swd_count: self.swd_count,
            snapshot_every: self.snapshot_every,
        }
    }

    /// `--steps N` or `--kimg K` (clap requires one).
    fn length(&self) -> anyhow::Result<RunLength> {
        match (self.steps, self.kimg) {
            (Some(s), _) => Ok(RunLength::Steps(s)),
            (None, Some(k)) => Ok(RunLength::Kimg(k)),
            (None, None) => anyhow::bail!("give the run's length with --steps N or --kimg K"),
        }
    }
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut plan = GanTraining::plan(&args.out, &args.settings(), args.resume)?;
    for note in &plan.notes {
        eprintln!("{note}");
    }
    let total = args.length()?.steps(plan.config.batch)?;
    let data =
        DatasetSource::for_training(&plan.config).context("cannot open the training data")?;
    plan.bind_data(&data)?;
    let mut training = GanTraining::open(&args.out, plan, total, &Device::Cpu)?;
    if training.restored() == Some(Restored::WithFreshOptimisers) {
        eprintln!(
            "note: {} holds no optimiser state (a portable checkpoint): the networks continue \
             from step {}, Adam restarts from zero moments",
            args.out.display(),
            training.trainer().steps_done()
        );
    }
    let stop = stop_flag()?;
    let start_step = training.trainer().steps_done();
    let c = training.trainer().config();
    writeln!(
        out,
        "training {}² (multiplier {}, batch {}, seed {}{}) on {} ({} photos): steps {} → {total}",
        c.generator.resolution,
        c.generator.channel_multiplier,
        c.batch,
        c.seed,
        match (&c.generator.spatial, c.generator.tileable) {
            (Some(_), _) => ", spatial: any-size, on patches at the photos' resolution",
            (None, true) => ", tileable",
            (None, false) => "",
        },
        c.data.display(),
        data.dataset().len(),
        start_step
    )?;
    let bar = steps_bar(total, start_step);
    let outcome = training.run(&data, &stop, &mut |event| show(&bar, event))?;
    bar.finish_and_clear();
    report(&args.out, total, &outcome, out)?;
    if outcome.interrupted {
        return Err(interruption().into());
    }
    Ok(())
}

/// One event of the run on the progress bar.
fn show(bar: &ProgressBar, event: GanEvent<'_>) {
    match event {
        // On stderr whether or not it is a terminal (the bar's own lines are hidden when it
        // is not), and in log.csv's `skipped` column.
        GanEvent::Skipped { step, reason } => {
            bar.suspend(|| eprintln!("warning: step {step}: skipped the update: {reason}"))
        }
        GanEvent::CheckpointHeld { step, reason } => bar.suspend(|| {
            eprintln!(
                "warning: no checkpoint after step {step}: {reason}; the previous one is kept"
            )
        }),
        GanEvent::SnapshotHeld { step, reason } => {
            bar.suspend(|| eprintln!("warning: no snapshot after step {step}: {reason}"))
        }
        GanEvent::SwdStarted { count } => {
            bar.set_message(format!("measuring SWD on {count} images"))
        }
        GanEvent::SwdProgress => bar.tick(),
        GanEvent::Swd { step, report } => bar.println(format!(
            "step {step}: SWD×10³ {:.2} (per level {:?})",
            report.mean, report.per_level
        )),
        GanEvent::Step {
            stats,
            seconds,
            done,
            kimg,
        } => {
            bar.set_position(done);
            bar.set_message(format!(
                "kimg {kimg:.3} | D {:.3} G {:.3} | gap {:+.3} | {seconds:.2} s/step",
                stats.loss_d,
                stats.loss_g,
                stats.real_logit - stats.fake_logit
            ));
        }
    }
}

/// The lines after a run: how it ended and where its outputs are.
fn report(run: &Path, total: u64, o: &GanOutcome, out: &mut dyn Write) -> anyhow::Result<()> {
    if o.interrupted {
        writeln!(
            out,
            "interrupted at step {} of {total}: state saved in {}; continue with\n  photomat train-gan --out {} --resume --steps {total}",
            o.steps_done,
            run.display(),
            run.display()
        )?;
    } else {
        let timing = if o.steps_run > 0 {
            let (n, p) = (o.steps_run as f64, o.phases);
            format!(
                ", {:.2} s/step (G {:.2}, D {:.2}, crops {:.2}, R1 {:.2}, EMA {:.2})",
                o.seconds / n,
                p.g / n,
                p.d / n,
                p.data / n,
                p.r1 / n,
                p.ema / n
            )
        } else {
            String::new()
        };
        writeln!(
            out,
            "trained {} steps ({} in total, {:.3} kimg){timing}",
            o.steps_run, o.steps_done, o.kimg
        )?;
    }
    writeln!(
        out,
        "  {}/gan.json, gan.safetensors  G_ema + M (photomat relight --gan {})",
        run.display(),
        run.display()
    )?;
    writeln!(out, "  {}/log.csv  losses per step", run.display())?;
    writeln!(out, "  {}  latest samples", o.samples.display())?;
    Ok(())
}
