//! The relief-prior training driver (`photomat train-prior`): a run folder opened fresh or
//! resumed (locked while open, one writer per folder), the [`PriorTrainer`] stepped to a total,
//! and the run's cadence of checkpoints, `log.csv` rows and scored snapshots.
//!
//! The run folder holds `train.json` + `train_state.safetensors` (every checkpoint, written
//! atomically; a resumed run continues bit-identically), the prior itself (`prior.json` +
//! `prior.safetensors`, the latest weights: the folder is a prior folder for `photomat
//! capture --prior-model`), `log.csv` (one row per step) and, every `snapshot_every` steps,
//! `snapshots/step-NNNNNN/` (a prior folder whose manifest records its validation score) with
//! a row of `validation.csv`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Context;
use candle_core::Device;
use photomat_core::FolderLock;
use photomat_core::image_io::write_atomic;
use photomat_train::{RunLog, check_run_folder};

use super::settings::{PriorSettings, PriorTrainConfig};
use super::trainer::{PriorTrainer, STATE_FILE, StepReport, ValidationScore};

/// The configuration file of a run folder.
pub const CONFIG_FILE: &str = "train.json";
/// The per-step log.
pub const LOG_FILE: &str = "log.csv";
/// The snapshots' scores.
pub const VALIDATION_FILE: &str = "validation.csv";
/// The folder of the snapshots.
pub const SNAPSHOTS_DIR: &str = "snapshots";
const LOG_HEADER: &str = "step,loss,maps,normal,render,skipped,seconds";
const VALIDATION_HEADER: &str =
    "step,normal_degrees,flat_normal_degrees,diffuse_rmse,roughness_rmse,loss";

/// What [`PriorTraining::run`] reports while it works.
#[derive(Debug)]
pub enum PriorEvent<'a> {
    Step {
        report: &'a StepReport,
        seconds: f64,
    },
    /// A snapshot was scored.
    Validated {
        step: u64,
        score: &'a ValidationScore,
    },
}

/// How a run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorOutcome {
    pub interrupted: bool,
    pub steps_run: u64,
    pub steps_done: u64,
    pub seconds: f64,
    pub last: Option<StepReport>,
}

/// A relief-prior run in its folder.
pub struct PriorTraining {
    trainer: PriorTrainer,
    run: PathBuf,
    log: RunLog,
    validation: RunLog,
    notes: Vec<String>,
    _lock: FolderLock,
}

/// Reads `run/train.json`; errors name the file.
fn read_config(run: &Path) -> anyhow::Result<PriorTrainConfig> {
    let path = run.join(CONFIG_FILE);
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{}: cannot read the run's settings", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: not a prior run's settings", path.display()))
}

impl PriorTraining {
    /// Opens the run in `run` (module docs): fresh from `settings` (an error if the folder
    /// holds a run) or, on `resume`, the saved one after checking that no setting contradicts
    /// it.
    pub fn open(
        run: &Path,
        settings: &PriorSettings,
        resume: bool,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let lock = FolderLock::acquire(run, "photomat train-prior")?;
        check_run_folder(run, STATE_FILE, resume, "a prior training run")?;
        let saved = if resume {
            Some((read_config(run)?, run.join(CONFIG_FILE)))
        } else {
            None
        };
        let merged = settings.merge(saved.as_ref().map(|(c, f)| (c.clone(), f.as_path())))?;
        let mut trainer = PriorTrainer::new(merged.config, device)?;
        let (log, validation) = if resume {
            trainer.load_state(run)?;
            (
                RunLog::resume(&run.join(LOG_FILE), LOG_HEADER, trainer.steps_done())?,
                RunLog::resume(
                    &run.join(VALIDATION_FILE),
                    VALIDATION_HEADER,
                    trainer.steps_done(),
                )?,
            )
        } else {
            (
                RunLog::create(&run.join(LOG_FILE), LOG_HEADER)?,
                RunLog::create(&run.join(VALIDATION_FILE), VALIDATION_HEADER)?,
            )
        };
        let training = Self {
            trainer,
            run: run.to_path_buf(),
            log,
            validation,
            notes: merged.notes,
            _lock: lock,
        };
        if !resume {
            // The settings are on disk from the start.
            training.checkpoint()?;
        }
        Ok(training)
    }

    pub fn trainer(&self) -> &PriorTrainer {
        &self.trainer
    }

    /// Lines for the user about settings a resume changed.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Trains until `total` steps or until `stop` is set (checked after each step), then
    /// checkpoints.
    pub fn run(
        &mut self,
        total: u64,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(PriorEvent<'_>),
    ) -> anyhow::Result<PriorOutcome> {
        let start = self.trainer.steps_done();
        let (mut seconds, mut last, mut interrupted) = (0.0, None, false);
        while self.trainer.steps_done() < total {
            let t0 = Instant::now();
            let report = self.trainer.step().with_context(|| {
                format!("training step {} failed", self.trainer.steps_done() + 1)
            })?;
            let dt = t0.elapsed().as_secs_f64();
            seconds += dt;
            let t = report.terms;
            self.log.append(&format!(
                "{},{},{},{},{},{},{dt:.3}",
                report.step, t.total, t.maps, t.normal, t.render, report.skipped
            ))?;
            progress(PriorEvent::Step {
                report: &report,
                seconds: dt,
            });
            let cadence = self.trainer.config().cadence;
            if report.step.is_multiple_of(cadence.checkpoint_every) {
                self.checkpoint()?;
            }
            if cadence.snapshot_every > 0 && report.step.is_multiple_of(cadence.snapshot_every) {
                let score = self.snapshot()?;
                progress(PriorEvent::Validated {
                    step: report.step,
                    score: &score,
                });
            }
            last = Some(report);
            if stop.load(Ordering::SeqCst) {
                interrupted = true;
                break;
            }
        }
        self.checkpoint()?;
        Ok(PriorOutcome {
            interrupted,
            steps_run: self.trainer.steps_done() - start,
            steps_done: self.trainer.steps_done(),
            seconds,
            last,
        })
    }

    /// Writes the state, `train.json` and the prior's own files.
    fn checkpoint(&self) -> anyhow::Result<()> {
        let run = &self.run;
        self.trainer
            .save_state(run)
            .with_context(|| format!("cannot save the training state in {}", run.display()))?;
        write_atomic(
            &run.join(CONFIG_FILE),
            &serde_json::to_vec_pretty(self.trainer.config())?,
        )?;
        self.trainer.model().save(run, self.provenance(None))
    }

    /// Scores the current weights and writes them as `snapshots/step-NNNNNN/`.
    fn snapshot(&mut self) -> anyhow::Result<ValidationScore> {
        let step = self.trainer.steps_done();
        let count = self.trainer.config().cadence.validation_count as usize;
        let score = self.trainer.validate(count)?;
        let dir = self.run.join(SNAPSHOTS_DIR).join(format!("step-{step:06}"));
        self.trainer
            .model()
            .save(&dir, self.provenance(Some(&score)))?;
        self.validation.append(&format!(
            "{step},{},{},{},{},{}",
            score.normal_degrees,
            score.flat_normal_degrees,
            score.diffuse_rmse,
            score.roughness_rmse,
            score.terms.total
        ))?;
        Ok(score)
    }

    /// What the prior's manifest records of its training.
    fn provenance(&self, score: Option<&ValidationScore>) -> serde_json::Value {
        let c = self.trainer.config();
        serde_json::json!({
            "trained_by": "photomat train-prior",
            "step": self.trainer.steps_done(),
            "library": c.library,
            "split": "train",
            "exclude_licences": c.exclude_licences,
            "size": c.size,
            "batch": c.batch,
            "seed": c.seed,
            "validation": score,
        })
    }
}
