//! The estimator training driver: a run folder opened fresh or resumed, the
//! [`EstimatorTrainer`] stepped to its total, and the run's cadence of checkpoints, `log.csv`
//! rows and training panels (PhotoMat, Zhou et al. 2023, §3 "Material map estimator").
//!
//! [`EstimatorTraining::open`] builds a fresh run from [`EstimatorSettings`] (the GAN model
//! folder and the BRDF model are required) or resumes the one in the folder, refusing a
//! setting that contradicts its `train.json`: the GAN folder, the BRDF model, E's width and
//! every training field but the step counts ([`TrainConfig::check_resume`]), which may grow.
//! [`EstimatorTraining::run`] stops after the current step when the stop flag is set (e.g. by a
//! Ctrl-C handler) and reports each step to a callback; a resumed run is bit-identical to an
//! uninterrupted one.
//!
//! The run folder is a complete model folder from the first checkpoint on (`estimator.json` +
//! `estimator.safetensors` next to a copy of the GAN's `gan.json` + `gan.safetensors`), plus
//! `train.json` + `train_state.safetensors`, `log.csv` (one row per step) and
//! `panels/step-NNNNNN.png` (per material: M's relighting | the analytic render | the maps).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::Device;
use photomat_core::image_io::{PlanarImage, PngBits, write_atomic, write_png};
use photomat_core::paths::absolute;
use photomat_core::previews::map_previews;
use photomat_core::sheet::grid;
use photomat_core::{FolderLock, Highlight, lookup};
use photomat_generator::GanModel;

use super::config::TrainConfig;
use super::state::{TRAIN_MANIFEST_FILE, TRAIN_STATE_FILE, TrainManifest, copy_gan_model};
use super::trainer::{EstimatorTrainer, StepReport};
use crate::{EstimatorConfig, EstimatorModel};

/// Default stage-1 steps for a new run (the paper trains 60 k; CPU runs set fewer).
pub const DEFAULT_STEPS: u64 = 60_000;
/// Default fine-tune steps for a new run (the paper trains 60 k).
pub const DEFAULT_FINETUNE_STEPS: u64 = 60_000;
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

/// The settings of a run; `None` keeps the default (fresh run) or the saved value (resume).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EstimatorSettings {
    /// GAN model folder (required for a fresh run).
    pub gan: Option<PathBuf>,
    /// BRDF model specification E decodes into (required for a fresh run).
    pub brdf: Option<String>,
    /// Steps of stage 1.
    pub steps: Option<u64>,
    /// Steps of the fine-tune.
    pub finetune_steps: Option<u64>,
    /// Materials per step.
    pub batch: Option<usize>,
    /// Adam learning rate of stage 1.
    pub lr: Option<f64>,
    /// Adam learning rate of the fine-tune.
    pub finetune_lr: Option<f64>,
    /// VGG19 weights for the Gram loss (`None`: the seeded random conv bank).
    pub vgg19: Option<PathBuf>,
    /// Width multiplier of E's channels (fresh default 1).
    pub width: Option<f64>,
    /// Seed of the run.
    pub seed: Option<u64>,
    /// Steps between training panels ([`TrainConfig::cadence`]).
    pub panel_every: Option<u64>,
    /// Steps between checkpoints ([`TrainConfig::cadence`]).
    pub checkpoint_every: Option<u64>,
}

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
    log: std::fs::File,
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
        let state = run.join(TRAIN_STATE_FILE);
        if resume && !state.exists() {
            bail!(
                "cannot resume: {} does not exist (start the run without --resume)",
                state.display()
            );
        }
        if !resume && state.exists() {
            bail!(
                "{} already holds an estimator run; continue it with --resume or choose another --out",
                run.display()
            );
        }
        let (trainer, gan_dir) = if resume {
            resumed(run, settings, device)?
        } else {
            fresh(settings, device)?
        };
        let log = if resume {
            open_log(run, Some(trainer.steps_done()))?
        } else {
            // The model folder is complete from the start: the GAN copy, E and the settings.
            copy_gan_model(&gan_dir, run)
                .with_context(|| format!("cannot copy the GAN model into {}", run.display()))?;
            checkpoint(&trainer, run, &gan_dir)?;
            open_log(run, None)?
        };
        Ok(Self {
            trainer,
            run: run.to_path_buf(),
            gan_dir,
            log,
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
            log_row(&mut self.log, &report, seconds)?;
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

/// `config` with every training setting that was given applied.
fn apply_settings(mut config: TrainConfig, settings: &EstimatorSettings) -> TrainConfig {
    if let Some(v) = settings.steps {
        config.steps = v;
    }
    if let Some(v) = settings.finetune_steps {
        config.finetune_steps = v;
    }
    if let Some(v) = settings.batch {
        config.batch = v;
    }
    if let Some(v) = settings.lr {
        config.lr = v;
    }
    if let Some(v) = settings.finetune_lr {
        config.finetune_lr = v;
    }
    if let Some(v) = settings.seed {
        config.seed = v;
    }
    if let Some(path) = &settings.vgg19 {
        config.vgg19 = Some(absolute(path));
    }
    if let Some(v) = settings.panel_every {
        config.cadence.panel_every = v;
    }
    if let Some(v) = settings.checkpoint_every {
        config.cadence.checkpoint_every = v;
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

/// A new run from the settings, and its GAN folder.
fn fresh(
    settings: &EstimatorSettings,
    device: &Device,
) -> anyhow::Result<(EstimatorTrainer, PathBuf)> {
    let Some(gan_dir) = settings.gan.as_deref().map(absolute) else {
        bail!("--gan RUN is required for a new run (a `photomat train-gan` output folder)");
    };
    let Some(spec) = &settings.brdf else {
        bail!("--brdf SPEC is required for a new run (`photomat brdfs` lists the models)");
    };
    let brdf = lookup(spec).context("invalid --brdf")?;
    let gan = GanModel::load(&gan_dir, device)
        .with_context(|| format!("cannot load the GAN model {}", gan_dir.display()))?;
    let config = apply_settings(
        TrainConfig {
            steps: DEFAULT_STEPS,
            finetune_steps: DEFAULT_FINETUNE_STEPS,
            ..TrainConfig::default()
        },
        settings,
    );
    config
        .validate(gan.config().resolution)
        .context("invalid training settings")?;
    let arch = architecture(&gan, brdf.channels(), settings.width.unwrap_or(1.0))?;
    let model = EstimatorModel::new_seeded(brdf, arch, config.seed, device)?;
    let trainer = EstimatorTrainer::new(gan, model, config)?;
    Ok((trainer, gan_dir))
}

/// The run in `run`, after checking that no given setting contradicts its `train.json`.
fn resumed(
    run: &Path,
    settings: &EstimatorSettings,
    device: &Device,
) -> anyhow::Result<(EstimatorTrainer, PathBuf)> {
    let saved = TrainManifest::load(run)?;
    let file = run.join(TRAIN_MANIFEST_FILE);
    let mut conflicts = Vec::new();
    if let Some(gan) = settings.gan.as_deref().map(absolute)
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
    if let Some(spec) = &settings.brdf {
        let given = lookup(spec).context("invalid --brdf")?.name();
        if given != saved.brdf {
            conflicts.push(format!("--brdf {given} contradicts brdf = {}", saved.brdf));
        }
    }
    let gan = GanModel::load(&saved.gan, device)
        .with_context(|| format!("cannot load the run's GAN model {}", saved.gan.display()))?;
    if let Some(width) = settings.width {
        let given = architecture(&gan, brdf.channels(), width)?;
        if given != saved.architecture {
            conflicts.push(format!(
                "--width {width} gives encoder widths {:?}, which contradicts the run's {:?}",
                given.encoder_channels, saved.architecture.encoder_channels
            ));
        }
    }
    let config = apply_settings(saved.config.clone(), settings);
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
    trainer.load_checkpoint(run)?;
    Ok((trainer, saved.gan))
}

/// Writes the training state, E's model files and `train.json` into `run`.
fn checkpoint(trainer: &EstimatorTrainer, run: &Path, gan_dir: &Path) -> anyhow::Result<()> {
    trainer
        .save_checkpoint(run, gan_dir)
        .with_context(|| format!("cannot save the checkpoint in {}", run.display()))
}

/// Opens `run/log.csv` for appending: a new file with the header, or on resume the existing
/// rows up to step `keep` (rows of steps after the checkpoint are dropped: they are redone).
fn open_log(run: &Path, keep: Option<u64>) -> anyhow::Result<std::fs::File> {
    let path = run.join(LOG_FILE);
    let mut text = format!("{LOG_HEADER}\n");
    if let Some(keep) = keep
        && let Ok(old) = std::fs::read_to_string(&path)
    {
        text.push_str(&kept_rows(&old, keep));
    }
    write_atomic(&path, text.as_bytes())?;
    std::fs::OpenOptions::new()
        .append(true)
        .open(&path)
        .with_context(|| format!("cannot open {}", path.display()))
}

/// The data rows of the log text `old` (header skipped) whose step is at most `keep`.
fn kept_rows(old: &str, keep: u64) -> String {
    let mut text = String::new();
    for line in old.lines().skip(1) {
        let step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
        if step.is_some_and(|s| s <= keep) {
            text.push_str(line);
            text.push('\n');
        }
    }
    text
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resumed_logs_keep_rows_up_to_the_checkpoint() {
        let old = format!("{LOG_HEADER}\n1,aligned,0.1\n2,aligned,0.2\n3,finetune,0.3\n");
        assert_eq!(kept_rows(&old, 2), "1,aligned,0.1\n2,aligned,0.2\n");
        assert_eq!(kept_rows(&old, 0), "");
    }

    #[test]
    fn settings_override_only_what_is_given() {
        let base = TrainConfig::default();
        assert_eq!(
            apply_settings(base.clone(), &EstimatorSettings::default()),
            base
        );
        let given = EstimatorSettings {
            steps: Some(3),
            seed: Some(9),
            ..EstimatorSettings::default()
        };
        let c = apply_settings(base.clone(), &given);
        assert_eq!((c.steps, c.seed, c.batch), (3, 9, base.batch));
    }
}
