//! The GAN training driver: a run folder opened fresh or resumed, the [`Trainer`] stepped to a
//! total, and the run's cadence of checkpoints, `log.csv` rows, sample grids and SWD
//! measurements (PhotoMat, Zhou et al. 2023, §3–4; StyleGAN2-ADA's training loop).
//!
//! [`GanTraining::plan`] turns [`GanSettings`] into the run's [`TrainConfig`]: a fresh run
//! takes every setting (with the CPU-sized defaults), a resumed one keeps `train.json` and
//! refuses a setting that contradicts it ([`RESUME_FIXED`] lists the fields that may not
//! change; the data folder may move, the learning rate and the cadence of outputs may change).
//! The caller opens the training data the plan names (any [`TrainingData`]), then
//! [`GanTraining::open`], which locks the folder, and [`GanTraining::run`], which stops after
//! the current step when the stop flag is set (e.g. by a Ctrl-C handler) and reports to a
//! progress callback. A resumed run continues with the same optimiser state and draws: with
//! the same learning rate the result is identical to an uninterrupted run.
//!
//! A checkpoint is written only from a sound state ([`Trainer::unsound_state`]): after a step
//! that skipped an update, or with non-finite weights, the previous checkpoint stays, so a
//! diverging run can be resumed from its last good state with a lower `--lr`
//! (docs/robustness.md).
//!
//! The run folder holds `train.json` + `train_state.safetensors` (every checkpoint), the GAN
//! model folder `gan.json` + `gan.safetensors`, `log.csv`, `samples/step-NNNNNN.png` and, with a
//! snapshot cadence, `snapshots/step-NNNNNN/` (G_ema + M of that step, a model folder).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::Device;
use photomat_core::FolderLock;
use photomat_core::image_io::{PngBits, write_png};
use photomat_core::paths::absolute;

use super::config::{Cadence, TrainConfig};
use super::data::TrainingData;
use super::log::{LogRow, TrainLog};
use super::samples::sample_grid;
use super::state::{CONFIG_FILE, LOG_FILE, Restored, STATE_FILE, read_config};
use super::trainer::{PhaseSeconds, StepStats, Trainer};
use crate::relight::DEFAULT_RELIGHT_LOBES;
use crate::swd::{FakeWindows, SwdConfig, SwdReport, model_swd};
use crate::{GeneratorConfig, MAX_RESOLUTION, MIN_RESOLUTION, SpatialConfig};

/// Default model side for a fresh run (CPU-sized).
pub const DEFAULT_SIZE: usize = 64;
/// Default channel multiplier for a fresh run (CPU-sized; the reference is 1).
pub const DEFAULT_MULTIPLIER: f64 = 0.25;
/// Default batch (the reference trains 32 on 8 GPUs; 4 keeps a CPU step in seconds).
pub const DEFAULT_BATCH: usize = 4;
/// Key mixed into the run seed for the SWD's fixed draws (one fixed set of fakes and reals
/// per run, so successive measurements compare).
const SWD_SEED_KEY: u64 = 0x7472_6169_6E5F_7377; // "train_sw"

/// The settings of a run; `None` keeps the default (fresh run) or the saved value (resume).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GanSettings {
    /// Prepared data set folder (required for a fresh run; relocates it on resume).
    pub data: Option<PathBuf>,
    /// Model side, a power of two in 32 … 1024.
    pub size: Option<usize>,
    /// Channel multiplier of G and D.
    pub multiplier: Option<f64>,
    /// Dimension of z and w.
    pub latent_dim: Option<usize>,
    /// Images per step.
    pub batch: Option<usize>,
    /// Seed of the run.
    pub seed: Option<u64>,
    /// Tileable generator (`false`: not asked for).
    pub tileable: bool,
    /// Base learning rate.
    pub lr: Option<f64>,
    /// Path-length regularisation weight.
    pub pl_weight: Option<f64>,
    /// Learning-rate multiplier of M.
    pub relight_lr_multiplier: Option<f64>,
    /// R1 weight γ.
    pub r1_gamma: Option<f64>,
    /// Spatial (any-size) generator trained on native-scale patches (`false`: not asked for).
    /// Implies a tileable generator (docs/conventions.md, "Spatial generator").
    pub spatial: bool,
    /// Channels of a spatial generator's local latents.
    pub local_dim: Option<usize>,
    /// Periodic waves of a spatial generator ([`SpatialConfig::waves`]).
    pub waves: Option<usize>,
    /// Probability that a training patch holds the photo's highlight.
    pub highlight_prob: Option<f64>,
    /// Weight of D's light-mismatch term ([`TrainConfig::light_mismatch`]).
    pub light_mismatch: Option<f64>,
    /// Exponents of M's Phong-lobe light input ([`GeneratorConfig::relight_lobes`]; empty:
    /// the paper's M on F ‖ ω). Default for new runs [`DEFAULT_RELIGHT_LOBES`].
    pub relight_lobes: Option<Vec<f64>>,
    /// Leave out the per-pixel noise inputs ([`GeneratorConfig::noise_inputs`]; `false`: not
    /// asked for).
    pub no_noise: bool,
    /// Gain of D's input sharpening ([`GeneratorConfig::d_input_sharpen`]).
    pub d_sharpen: Option<f64>,
    /// M shades in the frame of a learned relief ([`GeneratorConfig::relief`]; `false`: not
    /// asked for). A resume may switch it on for a run without it.
    pub relief: bool,
    /// Steps between checkpoints ([`Cadence::checkpoint_every`]).
    pub checkpoint_every: Option<u64>,
    /// Steps between sample grids ([`Cadence::sample_every`]).
    pub sample_every: Option<u64>,
    /// Steps between SWD measurements ([`Cadence::swd_every`]).
    pub swd_every: Option<u64>,
    /// Images per SWD measurement ([`Cadence::swd_count`]).
    pub swd_count: Option<u64>,
    /// Steps between snapshots of G_ema + M ([`Cadence::snapshot_every`]).
    pub snapshot_every: Option<u64>,
}

impl GanSettings {
    /// `cadence` with every cadence setting that was given applied.
    fn cadence_over(&self, cadence: Cadence) -> Cadence {
        Cadence {
            checkpoint_every: self.checkpoint_every.unwrap_or(cadence.checkpoint_every),
            sample_every: self.sample_every.unwrap_or(cadence.sample_every),
            swd_every: self.swd_every.unwrap_or(cadence.swd_every),
            swd_count: self.swd_count.unwrap_or(cadence.swd_count),
            snapshot_every: self.snapshot_every.unwrap_or(cadence.snapshot_every),
        }
    }
}

/// The settings that a resume may not change: (flag, field of `train.json`, the given value,
/// the saved value), both as text. The exceptions ([`TrainConfig::with_resume_changes`]): the
/// data folder may move, `--lr` may change (as a diverged run's message recommends) and so may
/// the cadence of outputs.
type FixedField = (
    &'static str,
    &'static str,
    fn(&GanSettings) -> Option<String>,
    fn(&TrainConfig) -> String,
);

/// Every setting fixed at the start of a run, with its command-line flag.
pub const RESUME_FIXED: [FixedField; 17] = [
    (
        "--d-sharpen",
        "generator.d_input_sharpen",
        |s| s.d_sharpen.map(|v| v.to_string()),
        |c| c.generator.d_input_sharpen.to_string(),
    ),
    (
        "--no-noise",
        "generator.noise_inputs",
        |s| s.no_noise.then(|| "false".to_string()),
        |c| c.generator.noise_inputs.to_string(),
    ),
    (
        "--size",
        "generator.resolution",
        |s| s.size.map(|v| v.to_string()),
        |c| c.generator.resolution.to_string(),
    ),
    (
        "--multiplier",
        "generator.channel_multiplier",
        |s| s.multiplier.map(|v| v.to_string()),
        |c| c.generator.channel_multiplier.to_string(),
    ),
    (
        "--latent-dim",
        "generator.latent_dim",
        |s| s.latent_dim.map(|v| v.to_string()),
        |c| c.generator.latent_dim.to_string(),
    ),
    (
        "--relight-lr-multiplier",
        "generator.relight_lr_multiplier",
        |s| s.relight_lr_multiplier.map(|v| v.to_string()),
        |c| c.generator.relight_lr_multiplier.to_string(),
    ),
    (
        "--tileable",
        "generator.tileable",
        |s| s.tileable.then(|| "true".to_string()),
        |c| c.generator.tileable.to_string(),
    ),
    (
        "--spatial",
        "generator.spatial",
        |s| s.spatial.then(|| "true".to_string()),
        |c| c.generator.spatial.is_some().to_string(),
    ),
    (
        "--local-dim",
        "generator.spatial.local_dim",
        |s| s.local_dim.map(|v| v.to_string()),
        |c| {
            c.generator
                .spatial
                .as_ref()
                .map_or("none".into(), |s| s.local_dim.to_string())
        },
    ),
    (
        "--waves",
        "generator.spatial.waves",
        |s| s.waves.map(|v| v.to_string()),
        |c| {
            c.generator
                .spatial
                .as_ref()
                .map_or("none".into(), |s| s.waves.to_string())
        },
    ),
    (
        "--highlight-prob",
        "patches.highlight_prob",
        |s| s.highlight_prob.map(|v| v.to_string()),
        |c| {
            c.patches
                .as_ref()
                .map_or("none".into(), |p| p.highlight_prob.to_string())
        },
    ),
    (
        "--batch",
        "batch",
        |s| s.batch.map(|v| v.to_string()),
        |c| c.batch.to_string(),
    ),
    (
        "--seed",
        "seed",
        |s| s.seed.map(|v| v.to_string()),
        |c| c.seed.to_string(),
    ),
    (
        "--r1-gamma",
        "r1_gamma",
        |s| s.r1_gamma.map(|v| v.to_string()),
        |c| c.r1_gamma.to_string(),
    ),
    (
        "--pl-weight",
        "pl_weight",
        |s| s.pl_weight.map(|v| v.to_string()),
        |c| c.pl_weight.to_string(),
    ),
    (
        "--relight-lobes",
        "generator.relight_lobes",
        |s| s.relight_lobes.as_ref().map(|l| lobes_text(l)),
        |c| lobes_text(&c.generator.relight_lobes),
    ),
    (
        "--light-mismatch",
        "light_mismatch",
        |s| s.light_mismatch.map(|v| v.to_string()),
        |c| c.light_mismatch.to_string(),
    ),
];

/// Lobe exponents as `--relight-lobes` spells them: comma-separated, or `none`.
pub fn lobes_text(lobes: &[f64]) -> String {
    if lobes.is_empty() {
        return "none".into();
    }
    lobes
        .iter()
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// How long a run trains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RunLength {
    /// Total steps (a resumed run continues up to this count).
    Steps(u64),
    /// Total thousands of real images: ⌈1000·K / batch⌉ steps.
    Kimg(f64),
}

impl RunLength {
    /// Total steps at `batch` images per step.
    pub fn steps(self, batch: usize) -> anyhow::Result<u64> {
        match self {
            RunLength::Steps(s) => Ok(s),
            RunLength::Kimg(k) if k.is_finite() && k > 0.0 => {
                Ok((k * 1000.0 / batch as f64).ceil() as u64)
            }
            RunLength::Kimg(k) => bail!("--kimg {k} must be positive"),
        }
    }
}

/// The configuration a run will train with.
#[derive(Debug, Clone, PartialEq)]
pub struct RunPlan {
    /// The full configuration (`train.json`).
    pub config: TrainConfig,
    /// Whether the run continues from its checkpoint.
    pub resume: bool,
    /// Lines for the user (e.g. a relocated data set).
    pub notes: Vec<String>,
}

impl RunPlan {
    /// Records what the training data fixes in the model: a spatial G's texel size in world
    /// units (the data's sample side over R). A run that already has one must get data of the
    /// same texel: photos prepared at another size would change what the model's texels mean.
    pub fn bind_data(&mut self, data: &dyn TrainingData) -> anyhow::Result<()> {
        let resolution = self.config.generator.resolution as f64;
        let Some(spatial) = self.config.generator.spatial.as_mut() else {
            return Ok(());
        };
        let texel = data.sample_side() / resolution;
        match spatial.texel_size {
            None => spatial.texel_size = Some(texel),
            // Equal up to f64 rounding of the same ratio computed twice.
            Some(saved) if (saved - texel).abs() <= 1e-12 * saved => {}
            Some(saved) => bail!(
                "the run's texels are {saved} world units but this data set's are {texel}: \
                 prepare the photos at the size the run started with"
            ),
        }
        Ok(())
    }
}

/// What [`GanTraining::run`] reports while it works.
#[derive(Debug)]
pub enum GanEvent<'a> {
    /// A step finished: its statistics, wall seconds, steps done and kimg seen.
    Step {
        stats: &'a StepStats,
        seconds: f64,
        done: u64,
        kimg: f64,
    },
    /// A step skipped an update (a non-finite loss or gradient).
    Skipped { step: u64, reason: &'a str },
    /// The checkpoint after step `step` was not written: the state is not sound (a skipped
    /// update or non-finite weights), so the previous checkpoint stays the last good one.
    CheckpointHeld { step: u64, reason: &'a str },
    /// The snapshot after step `step` was not written, for the same reason.
    SnapshotHeld { step: u64, reason: &'a str },
    /// An SWD measurement of `count` images starts.
    SwdStarted { count: u64 },
    /// The SWD measurement progressed.
    SwdProgress,
    /// An SWD measurement finished after step `step`.
    Swd { step: u64, report: &'a SwdReport },
}

/// How a [`GanTraining::run`] ended.
#[derive(Debug, Clone, PartialEq)]
pub struct GanOutcome {
    /// Whether the stop flag ended it before the total.
    pub interrupted: bool,
    /// Steps run by this call.
    pub steps_run: u64,
    /// Steps done in total.
    pub steps_done: u64,
    /// Thousands of real images seen in total.
    pub kimg: f64,
    /// Wall seconds of this call's steps.
    pub seconds: f64,
    /// Their phases, summed.
    pub phases: PhaseSeconds,
    /// The last sample grid.
    pub samples: PathBuf,
}

/// A GAN training run in its folder.
pub struct GanTraining {
    trainer: Trainer,
    /// How a resumed run's state was restored (`None` for a fresh run).
    restored: Option<Restored>,
    run: PathBuf,
    log: TrainLog,
    total: u64,
    device: Device,
    // Held while the run is open: one writer per run folder.
    _lock: FolderLock,
}

impl GanTraining {
    /// The configuration of the run in `run`: from `settings` for a fresh run (an error if
    /// `run` already holds one), from `run/train.json` on `resume` after checking that no
    /// setting contradicts it.
    pub fn plan(run: &Path, settings: &GanSettings, resume: bool) -> anyhow::Result<RunPlan> {
        let state = run.join(STATE_FILE);
        if resume && !state.exists() {
            bail!(
                "cannot resume: {} does not exist (start the run without --resume)",
                state.display()
            );
        }
        if !resume && state.exists() {
            bail!(
                "{} already holds a training run; continue it with --resume or choose another --out",
                run.display()
            );
        }
        if resume {
            resumed_config(run, settings)
        } else {
            Ok(RunPlan {
                config: fresh_config(settings)?,
                resume,
                notes: Vec::new(),
            })
        }
    }

    /// Opens the run of `plan` in `run` (created and locked until the training is dropped: a
    /// second process on the folder fails naming this one) to train up to `total` steps: a
    /// fresh run writes its first checkpoint at once, a resumed one loads its state and keeps
    /// the log rows up to it and removes the snapshots after it (left by a run that went on
    /// past its last checkpoint; the resumed run makes them again). Temporary files of a
    /// killed checkpoint are removed.
    pub fn open(run: &Path, plan: RunPlan, total: u64, device: &Device) -> anyhow::Result<Self> {
        let lock = FolderLock::acquire(run, "photomat train-gan")?;
        let mut trainer = Trainer::new(plan.config, device)?;
        let log_path = run.join(LOG_FILE);
        let (log, restored) = if plan.resume {
            let restored = trainer.load_state(run)?;
            remove_snapshots_after(run, trainer.steps_done())?;
            (
                TrainLog::resume(&log_path, trainer.steps_done())?,
                Some(restored),
            )
        } else {
            // The configuration is on disk from the start, so a crash before the first
            // checkpoint still leaves a folder that says what it was.
            checkpoint(&trainer, run)?;
            (TrainLog::create(&log_path)?, None)
        };
        Ok(Self {
            trainer,
            restored,
            run: run.to_path_buf(),
            log,
            total,
            device: device.clone(),
            _lock: lock,
        })
    }

    /// The trainer (configuration, counters, models).
    pub fn trainer(&self) -> &Trainer {
        &self.trainer
    }

    /// How a resumed run's state was restored; `None` for a fresh run.
    pub fn restored(&self) -> Option<Restored> {
        self.restored
    }

    /// The total steps the run trains to.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Trains on `data` until the total or until `stop` is set (checked after each step),
    /// then checkpoints and writes a sample grid.
    pub fn run(
        &mut self,
        data: &dyn TrainingData,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(GanEvent<'_>),
    ) -> anyhow::Result<GanOutcome> {
        let start_step = self.trainer.steps_done();
        let mut interrupted = false;
        let mut seconds_total = 0.0;
        let mut phases = PhaseSeconds::default();
        while self.trainer.steps_done() < self.total {
            let t0 = Instant::now();
            let stats = self.trainer.step(data).with_context(|| {
                format!("training step {} failed", self.trainer.steps_done() + 1)
            })?;
            let seconds = t0.elapsed().as_secs_f64();
            seconds_total += seconds;
            let p = stats.seconds;
            phases.g += p.g;
            phases.d += p.d;
            phases.data += p.data;
            phases.r1 += p.r1;
            phases.ema += p.ema;
            for reason in &stats.skipped {
                progress(GanEvent::Skipped {
                    step: stats.step + 1,
                    reason: reason.as_str(),
                });
            }
            let done = self.trainer.steps_done();
            let kimg = self.trainer.images_seen() as f64 / 1000.0;
            let swd = self.swd_at(done, data, progress)?;
            self.log.append(&LogRow {
                step: done,
                kimg,
                loss_g: stats.loss_g,
                loss_d: stats.loss_d,
                real_logit: stats.real_logit,
                fake_logit: stats.fake_logit,
                mismatch_logit: stats.mismatch_logit,
                r1: stats.r1,
                seconds,
                swd,
                path_length: stats.path_length,
                lr: self.trainer.config().lr,
                skipped: stats.skipped.clone(),
            })?;
            progress(GanEvent::Step {
                stats: &stats,
                seconds,
                done,
                kimg,
            });
            if done.is_multiple_of(self.trainer.config().cadence.sample_every) {
                self.write_samples(data)?;
            }
            if done.is_multiple_of(self.trainer.config().cadence.checkpoint_every) {
                self.checkpoint_if_sound(progress)?;
            }
            let snapshot_every = self.trainer.config().cadence.snapshot_every;
            if snapshot_every > 0 && done.is_multiple_of(snapshot_every) {
                self.snapshot_if_sound(progress)?;
            }
            if stop.load(Ordering::SeqCst) {
                interrupted = true;
                break;
            }
        }
        self.checkpoint_if_sound(progress)?;
        let samples = self.write_samples(data)?;
        Ok(GanOutcome {
            interrupted,
            steps_run: self.trainer.steps_done() - start_step,
            steps_done: self.trainer.steps_done(),
            kimg: self.trainer.images_seen() as f64 / 1000.0,
            seconds: seconds_total,
            phases,
            samples,
        })
    }

    /// Checkpoints unless the state is unsound ([`Trainer::unsound_state`]): then the last
    /// checkpoint, the last good state, stays and `progress` hears why.
    fn checkpoint_if_sound(&self, progress: &mut dyn FnMut(GanEvent<'_>)) -> anyhow::Result<()> {
        match self.trainer.unsound_state()? {
            None => checkpoint(&self.trainer, &self.run),
            Some(reason) => {
                progress(GanEvent::CheckpointHeld {
                    step: self.trainer.steps_done(),
                    reason: &reason,
                });
                Ok(())
            }
        }
    }

    /// Writes G_ema + M as the model folder [`snapshot_folder`] of this step unless the state
    /// is unsound (then `progress` hears why and no snapshot is written for this step).
    fn snapshot_if_sound(&self, progress: &mut dyn FnMut(GanEvent<'_>)) -> anyhow::Result<()> {
        let step = self.trainer.steps_done();
        if let Some(reason) = self.trainer.unsound_state()? {
            progress(GanEvent::SnapshotHeld {
                step,
                reason: &reason,
            });
            return Ok(());
        }
        let dir = snapshot_folder(&self.run, step);
        self.trainer
            .save_model(&dir, provenance(&self.trainer))
            .with_context(|| format!("cannot save the snapshot {}", dir.display()))
    }

    /// The SWD×10³ of G_ema when step `done` is on the SWD cadence.
    fn swd_at(
        &self,
        done: u64,
        data: &dyn TrainingData,
        progress: &mut dyn FnMut(GanEvent<'_>),
    ) -> anyhow::Result<Option<f64>> {
        let every = self.trainer.config().cadence.swd_every;
        if every == 0 || !done.is_multiple_of(every) {
            return Ok(None);
        }
        let count = self.trainer.config().cadence.swd_count;
        progress(GanEvent::SwdStarted { count });
        let report = model_swd(
            self.trainer.ema_model(),
            data,
            count as usize,
            self.trainer.config().seed ^ SWD_SEED_KEY,
            FakeWindows::Native,
            &SwdConfig::default(),
            &mut |_, _| progress(GanEvent::SwdProgress),
        )
        .context("cannot measure the SWD")?;
        progress(GanEvent::Swd {
            step: done,
            report: &report,
        });
        Ok(Some(report.mean))
    }

    /// Writes `run/samples/step-NNNNNN.png`.
    fn write_samples(&self, data: &dyn TrainingData) -> anyhow::Result<PathBuf> {
        let dir = self.run.join("samples");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        let path = dir.join(format!("step-{:06}.png", self.trainer.steps_done()));
        let trainer = &self.trainer;
        let grid = sample_grid(
            trainer.ema_model(),
            data,
            trainer.config().seed,
            &self.device,
        )?;
        write_png(&path, &grid, PngBits::Eight)?;
        Ok(path)
    }
}

/// The configuration of a fresh run from `settings`, with the reference hyper-parameters.
fn fresh_config(settings: &GanSettings) -> anyhow::Result<TrainConfig> {
    let Some(data) = &settings.data else {
        bail!("--data DATASET is required for a new run (a prepared data set folder)");
    };
    let size = settings.size.unwrap_or(DEFAULT_SIZE);
    if !size.is_power_of_two() || !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&size) {
        bail!(
            "--size {size} is not supported: use a power of two in {MIN_RESOLUTION} … \
             {MAX_RESOLUTION} (32, 64, 128, 256, 512, 1024)"
        );
    }
    let defaults = GeneratorConfig::default();
    if !settings.spatial
        && (settings.local_dim.is_some()
            || settings.waves.is_some()
            || settings.highlight_prob.is_some())
    {
        bail!(
            "--local-dim, --waves and --highlight-prob configure a spatial generator: add \
             --spatial"
        );
    }
    let spatial = settings.spatial.then(|| SpatialConfig {
        local_dim: settings
            .local_dim
            .unwrap_or(SpatialConfig::default().local_dim),
        waves: settings.waves.unwrap_or(SpatialConfig::default().waves),
        ..SpatialConfig::default()
    });
    let generator = GeneratorConfig {
        resolution: size,
        channel_multiplier: settings.multiplier.unwrap_or(DEFAULT_MULTIPLIER),
        // A spatial G is translation-equivariant only with wrap-around padding.
        tileable: settings.tileable || settings.spatial,
        noise_inputs: !settings.no_noise,
        relief: settings.relief,
        d_input_sharpen: settings.d_sharpen.unwrap_or(defaults.d_input_sharpen),
        spatial,
        latent_dim: settings.latent_dim.unwrap_or(defaults.latent_dim),
        relight_lr_multiplier: settings
            .relight_lr_multiplier
            .unwrap_or(defaults.relight_lr_multiplier),
        relight_lobes: settings
            .relight_lobes
            .clone()
            .unwrap_or_else(|| DEFAULT_RELIGHT_LOBES.to_vec()),
        ..defaults
    };
    let mut config = TrainConfig::new(
        generator,
        absolute(data),
        settings.batch.unwrap_or(DEFAULT_BATCH),
        settings.seed.unwrap_or(0),
    );
    if let Some(lr) = settings.lr {
        config.lr = lr;
    }
    config.cadence = settings.cadence_over(Cadence::default());
    if let Some(w) = settings.pl_weight {
        config.pl_weight = w;
    }
    if let Some(weight) = settings.light_mismatch {
        config.light_mismatch = weight;
    }
    if let Some(gamma) = settings.r1_gamma {
        config.r1_gamma = gamma;
    }
    if let (Some(p), Some(patches)) = (settings.highlight_prob, config.patches.as_mut()) {
        patches.highlight_prob = p;
    }
    config
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid training settings: {e}"))?;
    Ok(config)
}

/// The saved configuration of `run`, after checking [`RESUME_FIXED`]. `data` relocates a data
/// set that was moved since the run started (the photos are the user's to keep the same); the
/// new path is saved at the next checkpoint.
fn resumed_config(run: &Path, settings: &GanSettings) -> anyhow::Result<RunPlan> {
    let mut saved = read_config(run)?;
    let mut notes = Vec::new();
    if let Some(data) = &settings.data {
        let moved = absolute(data);
        if moved != saved.data {
            notes.push(format!(
                "note: data set relocated from {} to {}",
                saved.data.display(),
                moved.display()
            ));
            saved.data = moved;
        }
    }
    let conflicts: Vec<String> = RESUME_FIXED
        .iter()
        .filter_map(|(flag, field, given, fixed)| {
            let (given, fixed) = (given(settings)?, fixed(&saved));
            (given != fixed)
                .then(|| format!("{flag} {given} contradicts {field} = {fixed} of the run"))
        })
        .collect();
    if !conflicts.is_empty() {
        bail!(
            "cannot resume {}: {} (leave the flag out to keep the run's value)",
            run.join(CONFIG_FILE).display(),
            conflicts.join("; ")
        );
    }
    if settings.relief && !saved.generator.relief {
        notes.push(
            "note: relief switched on: M's height projection starts at zero, so the model's \
             outputs are unchanged until it trains"
                .to_string(),
        );
        saved.generator.relief = true;
    }
    if let Some(lr) = settings.lr
        && lr != saved.lr
    {
        notes.push(format!(
            "note: learning rate {lr} from here on (the run had {}; log.csv's `lr` column \
             records it per step)",
            saved.lr
        ));
        saved.lr = lr;
    }
    let cadence = settings.cadence_over(saved.cadence);
    if cadence != saved.cadence {
        let snapshots = match cadence.snapshot_every {
            0 => "no snapshots".to_string(),
            every => format!("a snapshot every {every} steps"),
        };
        notes.push(format!(
            "note: checkpoints every {}, samples every {}, SWD every {} steps on {} images, \
             {snapshots} from here on",
            cadence.checkpoint_every, cadence.sample_every, cadence.swd_every, cadence.swd_count,
        ));
        saved.cadence = cadence;
    }
    saved
        .validate()
        .map_err(|e| anyhow::anyhow!("invalid training settings: {e}"))?;
    Ok(RunPlan {
        config: saved,
        resume: true,
        notes,
    })
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

/// The snapshot folder of step `step` in the run folder `run`: `snapshots/step-NNNNNN`, a GAN
/// model folder (gan.json + gan.safetensors) of G_ema + M after that step.
pub fn snapshot_folder(run: &Path, step: u64) -> PathBuf {
    run.join(SNAPSHOTS_DIR).join(format!("step-{step:06}"))
}

/// The snapshot folders of the run folder `run` ([`snapshot_folder`] names) with their steps,
/// in the order of the steps; none when the run has no snapshot folder.
pub fn snapshot_folders(run: &Path) -> std::io::Result<Vec<(u64, PathBuf)>> {
    let entries = match std::fs::read_dir(run.join(SNAPSHOTS_DIR)) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e),
    };
    let mut found = Vec::new();
    for entry in entries {
        let path = entry?.path();
        let step = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("step-"))
            .and_then(|n| n.parse::<u64>().ok());
        if let Some(step) = step {
            found.push((step, path));
        }
    }
    found.sort();
    Ok(found)
}

/// Removes the snapshot folders of `run` whose step is after `step`.
fn remove_snapshots_after(run: &Path, step: u64) -> anyhow::Result<()> {
    let folders = snapshot_folders(run)
        .with_context(|| format!("cannot list the snapshots of {}", run.display()))?;
    for (_, path) in folders.into_iter().filter(|(s, _)| *s > step) {
        std::fs::remove_dir_all(&path)
            .with_context(|| format!("cannot remove the later snapshot {}", path.display()))?;
    }
    Ok(())
}

/// The folder of a run's snapshots ([`Cadence::snapshot_every`]).
pub const SNAPSHOTS_DIR: &str = "snapshots";

/// Writes the training state and the GAN model folder into `run`.
fn checkpoint(trainer: &Trainer, run: &Path) -> anyhow::Result<()> {
    trainer
        .save_state(run)
        .with_context(|| format!("cannot save the training state in {}", run.display()))?;
    trainer
        .save_model(run, provenance(trainer))
        .with_context(|| format!("cannot save the GAN model in {}", run.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::data::{FlashPlacement, RealBatch};

    /// Training data that only knows its sample side.
    struct Side(f64);

    impl TrainingData for Side {
        fn reals(&self, _: usize, _: u64, _: &Device) -> candle_core::Result<RealBatch> {
            candle_core::bail!("no reals")
        }
        fn fake_lights(&self, _: usize, _: u64) -> candle_core::Result<Vec<FlashPlacement>> {
            candle_core::bail!("no lights")
        }
        fn sample_side(&self) -> f64 {
            self.0
        }
        fn sample_side_texels(&self) -> usize {
            64
        }
    }

    #[test]
    fn bind_data_records_the_spatial_texel_and_refuses_another() {
        let generator = GeneratorConfig {
            resolution: 64,
            tileable: true,
            spatial: Some(SpatialConfig::default()),
            ..GeneratorConfig::default()
        };
        let mut plan = RunPlan {
            config: TrainConfig::new(generator, PathBuf::from("d"), 4, 1),
            resume: false,
            notes: Vec::new(),
        };
        // 64² patches of 512² photos cover 2·64/512 = 0.25 world units: texels of 1/256.
        plan.bind_data(&Side(0.25)).unwrap();
        let texel = plan.config.generator.texel_size();
        assert_eq!(texel, Some(1.0 / 256.0));
        plan.bind_data(&Side(0.25)).unwrap();
        // Photos prepared at 256² instead: texels twice as large.
        let err = plan.bind_data(&Side(0.5)).unwrap_err().to_string();
        assert!(err.contains("prepare the photos at the size"), "{err}");
        // A fixed-size G keeps its unit square whatever the data says: 1/R at R = 256.
        let mut fixed = RunPlan {
            config: TrainConfig::new(GeneratorConfig::default(), PathBuf::from("d"), 4, 1),
            resume: false,
            notes: Vec::new(),
        };
        fixed.bind_data(&Side(0.25)).unwrap();
        assert_eq!(fixed.config.generator.texel_size(), Some(1.0 / 256.0));
    }

    #[test]
    fn kimg_rounds_up_to_whole_steps() {
        assert_eq!(RunLength::Steps(7).steps(4).unwrap(), 7);
        assert_eq!(RunLength::Kimg(0.01).steps(4).unwrap(), 3);
        assert_eq!(RunLength::Kimg(0.008).steps(4).unwrap(), 2);
        assert!(RunLength::Kimg(0.0).steps(4).is_err());
        assert!(RunLength::Kimg(f64::NAN).steps(4).is_err());
    }

    #[test]
    fn resume_table_names_every_contradicted_field() {
        let saved = TrainConfig::new(GeneratorConfig::default(), PathBuf::from("d"), 4, 3);
        let same = GanSettings {
            batch: Some(4),
            seed: Some(3),
            ..GanSettings::default()
        };
        let changed = GanSettings {
            batch: Some(8),
            tileable: true,
            ..same.clone()
        };
        let conflicts = |s: &GanSettings| -> Vec<&str> {
            RESUME_FIXED
                .iter()
                .filter(|(_, _, given, fixed)| given(s).is_some_and(|g| g != fixed(&saved)))
                .map(|(_, field, _, _)| *field)
                .collect()
        };
        assert!(conflicts(&same).is_empty());
        assert_eq!(conflicts(&changed), ["generator.tileable", "batch"]);
    }
}
