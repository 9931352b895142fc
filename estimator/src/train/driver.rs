//! The estimator training driver: a run folder opened fresh or resumed, the
//! [`EstimatorTrainer`] stepped to its total, and the run's cadence of checkpoints, `log.csv`
//! rows and training panels (PhotoMat, Zhou et al. 2023, §3 "Material map estimator").
//!
//! [`EstimatorTraining::open`] builds a fresh run from [`EstimatorSettings`] (the GAN model
//! folder and the BRDF model are required) or resumes the one in the folder, refusing a
//! setting that contradicts its `train.json`: the GAN folder, the BRDF model, E's width and
//! every training setting but the step counts, which may grow, and the cadence of outputs
//! ([`super::settings`]).
//! [`EstimatorTraining::run`] stops after the current step when the stop flag is set (e.g. by a
//! Ctrl-C handler) and reports each step to a callback; a resumed run is bit-identical to an
//! uninterrupted one.
//!
//! The run folder is a complete model folder from the first checkpoint on (`estimator.json` +
//! `estimator.safetensors` next to a copy of the GAN's `gan.json` + `gan.safetensors`), plus
//! `train.json` + `train_state.safetensors`, `log.csv` (one row per step) and
//! `panels/step-NNNNNN.png` (per material: M's relighting | the analytic render | the maps).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::Context;
use candle_core::Device;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::previews::map_previews;
use photomat_core::sheet::grid;
use photomat_core::{FolderLock, Highlight, lookup};
use photomat_generator::GanModel;
use photomat_train::RunLog;

use super::settings::EstimatorSettings;
use super::state::{TRAIN_MANIFEST_FILE, TRAIN_STATE_FILE, TrainManifest, copy_gan_model};
use super::trainer::{EstimatorTrainer, StepReport};
use crate::EstimatorModel;

/// Materials shown in each training panel.
const PANEL_MATERIALS: u64 = 2;
/// Key mixed into the run seed for the panels' fixed materials (distinct from every step's).
const PANEL_SEED_KEY: u64 = 0x7061_6E65_6C73; // "panels"
/// Light of the panels: off-centre, so that both the highlight and the falloff show.
const PANEL_LIGHT: Highlight = Highlight { x: 0.2, y: 0.2 };
/// The run's per-step log (one row per step, [`LOG_HEADER`]'s columns).
pub const LOG_FILE: &str = "log.csv";
/// `log.csv` header.
const LOG_HEADER: &str = "step,stage,l1,gram,total,skipped,seconds";

/// How an [`EstimatorTraining::run`] ended.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorOutcome {
    /// Whether the stop flag ended it before the total.
    pub interrupted: bool,
    /// Steps run by this call.
    pub steps_run: u64,
    /// Steps done in total.
    pub steps_done: u64,
    /// Wall seconds of this call's steps.
    pub seconds: f64,
    /// The last step's report, if a step ran.
    pub last: Option<StepReport>,
    /// The last training panel.
    pub panel: PathBuf,
}

/// An estimator training run in its folder.
pub struct EstimatorTraining {
    trainer: EstimatorTrainer,
    run: PathBuf,
    gan_dir: PathBuf,
    log: RunLog,
    /// What the merge of the settings noted ([`EstimatorSettings::merge`]).
    notes: Vec<String>,
    // Held while the run is open: one writer per run folder.
    _lock: FolderLock,
}

impl EstimatorTraining {
    /// Opens the run in `run` (locked until the training is dropped: a second process on the
    /// folder fails naming this one): a fresh one from `settings` (an error if `run` already
    /// holds one; the GAN copy, E and the settings are written at once) or, on `resume`, the
    /// saved one after checking that no setting contradicts it (the cadence may change).
    pub fn open(
        run: &Path,
        settings: &EstimatorSettings,
        resume: bool,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let lock = FolderLock::acquire(run, "photomat train-estimator")?;
        photomat_train::check_run_folder(run, TRAIN_STATE_FILE, resume, "an estimator run")?;
        let saved = if resume {
            Some((TrainManifest::load(run)?, run.join(TRAIN_MANIFEST_FILE)))
        } else {
            None
        };
        let merged = settings.merge(saved.as_ref().map(|(m, f)| (m.clone(), f.as_path())))?;
        let (trainer, gan_dir) = build_trainer(run, merged.config, resume, device)?;
        let log_path = run.join(LOG_FILE);
        let log = if resume {
            RunLog::resume(&log_path, LOG_HEADER, trainer.steps_done())?
        } else {
            // The model folder is complete from the start: the GAN copy, E and the settings.
            copy_gan_model(&gan_dir, run)
                .with_context(|| format!("cannot copy the GAN model into {}", run.display()))?;
            checkpoint(&trainer, run, &gan_dir)?;
            RunLog::create(&log_path, LOG_HEADER)?
        };
        Ok(Self {
            trainer,
            run: run.to_path_buf(),
            gan_dir,
            log,
            notes: merged.notes,
            _lock: lock,
        })
    }

    /// The trainer (configuration, counters, models).
    pub fn trainer(&self) -> &EstimatorTrainer {
        &self.trainer
    }

    /// The GAN model folder E trains against.
    pub fn gan_dir(&self) -> &Path {
        &self.gan_dir
    }

    /// Lines for the user about the settings a resume changed (`note: …`).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Trains until the run's total or until `stop` is set (checked after each step), then
    /// checkpoints and writes a panel; `progress` sees each step's report and wall seconds.
    pub fn run(
        &mut self,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(&StepReport, f64),
    ) -> anyhow::Result<EstimatorOutcome> {
        let start_step = self.trainer.steps_done();
        let mut interrupted = false;
        let mut seconds_total = 0.0;
        let mut last = None;
        while !self.trainer.is_done() {
            let t0 = Instant::now();
            let report = self.trainer.step().with_context(|| {
                format!("training step {} failed", self.trainer.steps_done() + 1)
            })?;
            let seconds = t0.elapsed().as_secs_f64();
            seconds_total += seconds;
            self.log.append(&log_line(&report, seconds))?;
            progress(&report, seconds);
            let done = report.step;
            last = Some(report);
            if done % self.trainer.config().cadence.panel_every == 0 {
                self.write_panel()?;
            }
            if done % self.trainer.config().cadence.checkpoint_every == 0 {
                checkpoint(&self.trainer, &self.run, &self.gan_dir)?;
            }
            if stop.load(Ordering::SeqCst) {
                interrupted = true;
                break;
            }
        }
        checkpoint(&self.trainer, &self.run, &self.gan_dir)?;
        let panel = self.write_panel()?;
        Ok(EstimatorOutcome {
            interrupted,
            steps_run: self.trainer.steps_done() - start_step,
            steps_done: self.trainer.steps_done(),
            seconds: seconds_total,
            last,
            panel,
        })
    }

    /// Writes `run/panels/step-NNNNNN.png`: per material, M's relighting | the analytic
    /// render of E's maps (both under [`PANEL_LIGHT`]) | previews of the maps.
    fn write_panel(&self) -> anyhow::Result<PathBuf> {
        let trainer = &self.trainer;
        let dir = self.run.join("panels");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
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
        write_png(&path, &grid(&rows, 0.0)?, PngBits::Eight)?;
        Ok(path)
    }
}

/// The trainer of the run `manifest` describes (E's weights seeded for a fresh run, loaded
/// from `run`'s checkpoint for a resumed one), and its GAN folder.
fn build_trainer(
    run: &Path,
    manifest: TrainManifest,
    resume: bool,
    device: &Device,
) -> anyhow::Result<(EstimatorTrainer, PathBuf)> {
    let file = run.join(TRAIN_MANIFEST_FILE);
    let brdf = lookup(&manifest.brdf)
        .with_context(|| format!("{}: the run's BRDF model cannot be built", file.display()))?;
    let gan = GanModel::load(&manifest.gan, device)
        .with_context(|| format!("cannot load the GAN model {}", manifest.gan.display()))?;
    manifest
        .config
        .validate(gan.config().resolution)
        .context("invalid training settings")?;
    let model = if resume {
        EstimatorModel::new(
            brdf,
            manifest.architecture.clone(),
            candle_nn::VarMap::new(),
            device,
        )?
    } else {
        EstimatorModel::new_seeded(
            brdf,
            manifest.architecture.clone(),
            manifest.config.seed,
            device,
        )?
    };
    let mut trainer = EstimatorTrainer::new(gan, model, manifest.config)?;
    if resume {
        trainer.load_checkpoint(run)?;
    }
    Ok((trainer, manifest.gan))
}

/// Writes the training state, E's model files and `train.json` into `run`.
fn checkpoint(trainer: &EstimatorTrainer, run: &Path, gan_dir: &Path) -> anyhow::Result<()> {
    trainer
        .save_checkpoint(run, gan_dir)
        .with_context(|| format!("cannot save the checkpoint in {}", run.display()))
}

/// The `log.csv` row of step report `r` that took `seconds`.
fn log_line(r: &StepReport, seconds: f64) -> String {
    format!(
        "{},{},{},{},{},{},{seconds:.4}",
        r.step,
        r.stage.name(),
        r.l1,
        r.gram,
        r.total,
        r.skipped
    )
}
