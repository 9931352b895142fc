//! The GAN training driver: a run folder opened fresh or resumed, the [`Trainer`] stepped to a
//! total, and the run's cadence of checkpoints, `log.csv` rows, sample grids and SWD
//! measurements (PhotoMat, Zhou et al. 2023, §3–4; StyleGAN2-ADA's training loop).
//!
//! [`GanTraining::plan`] turns [`GanSettings`] into the run's [`TrainConfig`] ([`super::settings`]):
//! a fresh run takes every setting (with the CPU-sized defaults), a resumed one keeps
//! `train.json` and refuses a setting that contradicts it (the data folder may move, the
//! learning rate and the cadence of outputs may change).
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
use photomat_train::RunLog;

use super::config::TrainConfig;
use super::data::TrainingData;
use super::log::{LOG_HEADER, LogRow};
use super::samples::sample_grid;
use super::settings::GanSettings;
use super::state::{CONFIG_FILE, LOG_FILE, Restored, STATE_FILE, read_config};
use super::trainer::{PhaseSeconds, StepStats, Trainer};
use crate::swd::{FakeWindows, SwdConfig, SwdReport, model_swd};

/// Key mixed into the run seed for the SWD's fixed draws (one fixed set of fakes and reals
/// per run, so successive measurements compare).
const SWD_SEED_KEY: u64 = 0x7472_6169_6E5F_7377; // "train_sw"

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
    log: RunLog,
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
        photomat_train::check_run_folder(run, STATE_FILE, resume, "a training run")?;
        let saved = if resume {
            Some((read_config(run)?, run.join(CONFIG_FILE)))
        } else {
            None
        };
        let merged = settings.merge(saved.as_ref().map(|(c, f)| (c.clone(), f.as_path())))?;
        Ok(RunPlan {
            config: merged.config,
            resume,
            notes: merged.notes,
        })
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
                RunLog::resume(&log_path, LOG_HEADER, trainer.steps_done())?,
                Some(restored),
            )
        } else {
            // The configuration is on disk from the start, so a crash before the first
            // checkpoint still leaves a folder that says what it was.
            checkpoint(&trainer, run)?;
            (RunLog::create(&log_path, LOG_HEADER)?, None)
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
            let row = LogRow {
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
            };
            self.log.append(&row.line())?;
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
    use crate::{GeneratorConfig, SpatialConfig};

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
}
