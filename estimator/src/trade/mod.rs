//! The speed/accuracy trade of BRDF models, measured on one GAN (`docs/trade.md`): for each
//! model specification, an estimator E trained with the *same* budget and seed, then every
//! model scored on one fixed, seeded set of materials and lights.
//!
//! - **Accuracy**: how well the analytic render of E's maps reproduces M's neural relighting of
//!   the same material (PhotoMat's own criterion, Zhou et al. 2023 §3): L1 of display-encoded
//!   images and SSIM ([`ssim`], Wang et al. 2004), per light and over all lights. The lights are
//!   the reference's five ([`LightSet::reference`]) and [`HELD_OUT_LIGHTS`] more drawn from a
//!   fixed seed (positions no estimator was tuned on).
//! - **Cost**: render and render + gradient time per megatexel ([`cost::render_costs`], all
//!   models timed together in interleaved rounds), E's
//!   parameters and mean training step time, and the bytes of one material's exported maps.
//!
//! Estimators are cached in `settings.cache` (one run folder per specification, named after it):
//! a folder trained with the same GAN files and settings is reused; one trained with others is
//! replaced; an interrupted one resumes where it stopped (a run folder of
//! [`crate::train::EstimatorTraining`]).
//!
//! ```no_run
//! use photomat_brdfs as _; // link the built-in plugins
//! use photomat_estimator::trade::{TradeSettings, TradeStudy};
//!
//! let settings = TradeSettings::new("models/demo".into(), vec!["lambert".into(), "ggx".into()], "T/estimators".into());
//! let stop = std::sync::atomic::AtomicBool::new(false);
//! let report = TradeStudy::new(settings).run("T".as_ref(), false, &stop, &mut |_event| Ok(()))?;
//! for entry in &report.entries {
//!     println!("{}: L1 {:.4}, {:.1} ms/Mtexel", entry.spec, entry.accuracy.l1_mean, entry.cost.render.eval_ms_per_megatexel);
//! }
//! # Ok::<(), anyhow::Error>(())
//! ```

pub mod cost;
pub mod plot;
pub mod report;
pub mod ssim;

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use photomat_core::image_io::write_atomic;
use photomat_core::output_folder::{OutputFolder, ResultKind};
use photomat_core::{FlashGeometry, LightSet, SplitMix64, lookup};
use photomat_generator::GanModel;
use photomat_generator::model_files::GAN_WEIGHTS_FILE;
use serde::{Deserialize, Serialize};

use crate::EstimatorModel;
use crate::model_files::ESTIMATOR_MANIFEST_FILE;
use crate::sample::{analytic_renders, neural_renders, per_light_l1};
use crate::train::{EstimatorSettings, EstimatorTraining, LOG_FILE};
pub use report::{Accuracy, Cost, TradeEntry, TradeReport};

/// Lights beyond the reference five, drawn uniformly over the central half of the material
/// from a fixed seed: enough to average out one unlucky position, few enough to stay cheap.
pub const HELD_OUT_LIGHTS: usize = 4;
/// Key mixed into the seed for the held-out lights (distinct from every training draw).
const HELD_OUT_SEED_KEY: u64 = 0x0068_656C_646F_7574; // "heldout"
/// Default stage-1 steps per estimator: about a minute per model at width ¼ on 2 CPU cores.
pub const DEFAULT_STEPS: u64 = 400;
/// Default fine-tune steps per estimator.
pub const DEFAULT_FINETUNE_STEPS: u64 = 100;
/// Default width multiplier of every E (the bundled model's).
pub const DEFAULT_WIDTH: f64 = 0.25;
/// Default number of evaluation materials.
pub const DEFAULT_MATERIALS: usize = 8;
/// Default evaluation side of a spatial (any-size) GAN: one photo width at the bundled
/// model's texel size, so the flash's highlight and falloff both show.
pub const DEFAULT_SPATIAL_SIDE: usize = 128;
/// The key file of a cached estimator: the settings it was trained with.
const CACHE_KEY_FILE: &str = "trade-key.json";
/// The report files.
pub const TABLE_FILE: &str = "trade.md";
/// The default cache of trained estimators inside a study's folder.
pub const CACHE_DIR: &str = "estimators";

/// What a trade study's folder holds: its table, record and plot, the first material's maps
/// per model, and (by default) the cache of trained estimators, which a new study of the same
/// folder takes over.
pub const TRADE: ResultKind = ResultKind {
    what: "a trade study",
    command: "photomat trade",
    entries: &[TABLE_FILE, JSON_FILE, PLOT_FILE, "maps", CACHE_DIR],
    kept: &[CACHE_DIR],
};
pub const JSON_FILE: &str = "trade.json";
pub const PLOT_FILE: &str = "trade.png";

/// What to compare and with what budget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TradeSettings {
    /// GAN model folder (gan.json + gan.safetensors).
    pub gan: PathBuf,
    /// BRDF model specifications, in the order given.
    pub brdfs: Vec<String>,
    /// Stage-1 steps of every estimator.
    pub steps: u64,
    /// Fine-tune steps of every estimator.
    pub finetune_steps: u64,
    /// Width multiplier of every estimator.
    pub width: f64,
    /// Seed of every estimator's training and of the evaluation set.
    pub seed: u64,
    /// Evaluation materials (seeds `seed`, `seed + 1`, …).
    pub materials: usize,
    /// Evaluation side in texels (`None`: [`DEFAULT_SPATIAL_SIDE`] for a spatial GAN, its
    /// resolution for a fixed-size one).
    pub size: Option<usize>,
    /// Folder of the cached estimators.
    pub cache: PathBuf,
}

impl TradeSettings {
    /// The defaults for `brdfs` on `gan`, caching estimators in `cache`.
    pub fn new(gan: PathBuf, brdfs: Vec<String>, cache: PathBuf) -> Self {
        Self {
            gan,
            brdfs,
            steps: DEFAULT_STEPS,
            finetune_steps: DEFAULT_FINETUNE_STEPS,
            width: DEFAULT_WIDTH,
            seed: 1,
            materials: DEFAULT_MATERIALS,
            size: None,
            cache,
        }
    }
}

/// Progress of a [`TradeStudy::run`].
#[derive(Debug, Clone, PartialEq)]
pub enum TradeEvent {
    /// Model `index` of `total` starts: its estimator is `reused` from the cache or trained.
    Model {
        index: usize,
        total: usize,
        spec: String,
        reused: bool,
    },
    /// A training step of the current model's estimator.
    Step { step: u64, total: u64, l1: f64 },
    /// A line worth showing (a replaced cache folder, …).
    Note(String),
}

/// The settings a cached estimator was trained with, compared before reuse.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct CacheKey {
    brdf: String,
    steps: u64,
    finetune_steps: u64,
    width: f64,
    seed: u64,
    /// gan.json's text: architecture and provenance of the GAN (its weights are compared
    /// byte for byte with the cached copy before reuse).
    gan_manifest: String,
}

/// A trade study: train or reuse one estimator per specification, then measure them all.
pub struct TradeStudy {
    settings: TradeSettings,
}

impl TradeStudy {
    pub fn new(settings: TradeSettings) -> Self {
        Self { settings }
    }

    /// Runs the study and writes `out/trade.md`, `out/trade.json`, `out/trade.png` and, per
    /// model, `out/maps/<name>/` (the first material's maps), the folder whole when the study
    /// ends ([`TRADE`]: an earlier study is refused unless `overwrite`).
    /// Stops between training steps when `stop` is set (the estimator's checkpoint is kept, so
    /// the next run resumes it) and then returns an error saying so.
    pub fn run(
        &self,
        out: &Path,
        overwrite: bool,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(TradeEvent) -> anyhow::Result<()>,
    ) -> anyhow::Result<TradeReport> {
        let s = &self.settings;
        if s.brdfs.is_empty() {
            bail!("no BRDF model to compare: give at least one specification");
        }
        if s.materials == 0 {
            bail!("the number of evaluation materials must be at least 1");
        }
        // Every name is checked before anything is trained.
        let mut canonical = Vec::new();
        for spec in &s.brdfs {
            let name = lookup(spec)
                .with_context(|| format!("invalid BRDF specification '{spec}'"))?
                .name();
            if canonical.contains(&name) {
                bail!("'{spec}' names the model '{name}' a second time");
            }
            canonical.push(name);
        }
        // Written whole when the study ends; the default cache (`out/estimators`) is carried
        // over from an earlier study or an interrupted one ([`TRADE`]).
        let folder = OutputFolder::claim(out, TRADE, overwrite)?;
        let cache = match s.cache.strip_prefix(out) {
            Ok(rel) if rel == Path::new(CACHE_DIR) => folder.path().join(CACHE_DIR),
            Ok(_) => bail!(
                "the estimator cache {} lies inside the study's folder: use {} (the default) or \
                 a folder outside it",
                s.cache.display(),
                out.join(CACHE_DIR).display()
            ),
            Err(_) => s.cache.clone(),
        };
        let out = folder.path();
        let device = Device::Cpu;
        let gan = GanModel::load(&s.gan, &device)
            .with_context(|| format!("cannot load the GAN model in '{}'", s.gan.display()))?;
        let evaluation = Evaluation::new(&gan, s)?;

        let mut trained = Vec::new();
        for (index, spec) in canonical.iter().enumerate() {
            let dir = cache.join(folder_name(spec));
            let reused = self.prepare_cache(&dir, spec, progress)?;
            progress(TradeEvent::Model {
                index,
                total: canonical.len(),
                spec: spec.clone(),
                reused,
            })?;
            if !reused {
                self.train(&dir, spec, stop, progress)?;
            }
            let estimator = EstimatorModel::load(&dir, &device)
                .with_context(|| format!("cannot load the estimator in '{}'", dir.display()))?;
            trained.push((estimator, dir, reused));
        }
        // All models timed together, in interleaved rounds (`cost::render_costs`).
        let brdfs: Vec<_> = trained.iter().map(|(e, _, _)| e.brdf().clone()).collect();
        let render = cost::render_costs(&brdfs, s.seed)?;
        let mut entries = Vec::new();
        for ((estimator, dir, reused), render) in trained.iter().zip(render) {
            let maps_dir = out.join("maps").join(folder_name(&estimator.brdf().name()));
            entries.push(evaluation.entry(estimator, dir, &maps_dir, *reused, render)?);
        }
        let report = TradeReport::new(s.clone(), evaluation.lights_described(), entries);
        let mut json = serde_json::to_string_pretty(&report)?;
        json.push('\n');
        write_atomic(&out.join(JSON_FILE), json.as_bytes())?;
        write_atomic(&out.join(TABLE_FILE), report.markdown().as_bytes())?;
        plot::write_pareto_plot(&out.join(PLOT_FILE), &report)?;
        folder.commit()?;
        Ok(report)
    }

    /// Whether `dir` holds a finished estimator for `spec` trained with these settings and
    /// GAN; a folder trained with others is removed (with a note) so that training starts
    /// afresh, an unfinished one with the same key is left to resume.
    fn prepare_cache(
        &self,
        dir: &Path,
        spec: &str,
        progress: &mut dyn FnMut(TradeEvent) -> anyhow::Result<()>,
    ) -> anyhow::Result<bool> {
        let key = self.cache_key(spec)?;
        let key_path = dir.join(CACHE_KEY_FILE);
        if !dir.exists() {
            return Ok(false);
        }
        let saved: Option<CacheKey> = std::fs::read_to_string(&key_path)
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok());
        let same_weights = std::fs::read(dir.join(GAN_WEIGHTS_FILE)).ok()
            == std::fs::read(self.settings.gan.join(GAN_WEIGHTS_FILE)).ok();
        if saved.as_ref() == Some(&key) && same_weights {
            return Ok(dir.join(ESTIMATOR_MANIFEST_FILE).is_file() && finished(dir, &key)?);
        }
        progress(TradeEvent::Note(format!(
            "{}: trained with other settings or another GAN; training it again",
            dir.display()
        )))?;
        std::fs::remove_dir_all(dir)
            .with_context(|| format!("cannot remove the stale cache folder {}", dir.display()))?;
        Ok(false)
    }

    fn cache_key(&self, spec: &str) -> anyhow::Result<CacheKey> {
        let s = &self.settings;
        let manifest = s
            .gan
            .join(photomat_generator::model_files::GAN_MANIFEST_FILE);
        Ok(CacheKey {
            brdf: spec.to_string(),
            steps: s.steps,
            finetune_steps: s.finetune_steps,
            width: s.width,
            seed: s.seed,
            gan_manifest: std::fs::read_to_string(&manifest)
                .with_context(|| format!("cannot read {}", manifest.display()))?,
        })
    }

    /// Trains (or resumes) the estimator for `spec` in `dir` to the study's budget.
    fn train(
        &self,
        dir: &Path,
        spec: &str,
        stop: &AtomicBool,
        progress: &mut dyn FnMut(TradeEvent) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let s = &self.settings;
        let resume = dir.join(crate::train::state::TRAIN_STATE_FILE).exists();
        let settings = EstimatorSettings {
            gan: Some(s.gan.clone()),
            brdf: Some(spec.to_string()),
            steps: Some(s.steps),
            finetune_steps: Some(s.finetune_steps),
            width: Some(s.width),
            seed: Some(s.seed),
            // A panel at the end only (the study reads none); a checkpoint every 100 steps, so
            // that an interrupted study loses little.
            panel_every: Some(u64::MAX),
            checkpoint_every: Some(100),
            ..EstimatorSettings::default()
        };
        let mut training = EstimatorTraining::open(dir, &settings, resume, &Device::Cpu)
            .with_context(|| format!("cannot open the estimator run for '{spec}'"))?;
        let key = serde_json::to_string_pretty(&self.cache_key(spec)?)?;
        write_atomic(&dir.join(CACHE_KEY_FILE), key.as_bytes())?;
        let total = s.steps + s.finetune_steps;
        let mut failed = None;
        let outcome = training.run(stop, &mut |report, _| {
            if failed.is_none()
                && let Err(e) = progress(TradeEvent::Step {
                    step: report.step,
                    total,
                    l1: report.l1,
                })
            {
                failed = Some(e);
            }
        })?;
        if let Some(e) = failed {
            return Err(e);
        }
        if outcome.interrupted {
            bail!(
                "interrupted while training the estimator for '{spec}' (step {} of {total}); its \
                 state is saved in {}, and the same command resumes it",
                outcome.steps_done,
                dir.display()
            );
        }
        Ok(())
    }
}

/// Whether the run in `dir` has done every step of `key`'s budget.
/// (A run without a log has done no step.)
fn finished(dir: &Path, key: &CacheKey) -> anyhow::Result<bool> {
    if !dir.join(LOG_FILE).is_file() {
        return Ok(false);
    }
    let last_step = log_column(dir, "step")?.into_iter().fold(0.0, f64::max);
    Ok(last_step >= (key.steps + key.finetune_steps) as f64)
}

/// A cache folder name for a specification: `height(ggx, scale=0.02)` → `height-ggx-scale-0.02`.
pub fn folder_name(spec: &str) -> String {
    let mut name = String::new();
    for c in spec.chars() {
        if c.is_ascii_alphanumeric() || c == '.' || c == '_' {
            name.push(c);
        } else if !name.ends_with('-') && !name.is_empty() {
            name.push('-');
        }
    }
    name.trim_end_matches('-').to_string()
}

/// The fixed evaluation set: materials, lights, and M's relighting of each material under
/// every light (computed once, shared by every model).
struct Evaluation {
    features: Vec<Tensor>,
    neural: Vec<Tensor>,
    geometry: FlashGeometry,
    lights: LightSet,
    /// Lights that are the reference's five (the rest are held out).
    reference_count: usize,
    texel_size: Option<f64>,
}

impl Evaluation {
    fn new(gan: &GanModel, s: &TradeSettings) -> anyhow::Result<Self> {
        let config = gan.config();
        let default = config.spatial.as_ref().map(|_| DEFAULT_SPATIAL_SIDE);
        let side = config.sample_side(s.size.or(default))?;
        let reference = LightSet::reference();
        let mut rng = SplitMix64(s.seed ^ HELD_OUT_SEED_KEY);
        // Held-out highlights over the central half, where photos put them.
        let held_out = LightSet::uniform(HELD_OUT_LIGHTS, || 0.25 + 0.5 * rng.next_unit());
        let mut highlights = reference.highlights().to_vec();
        highlights.extend_from_slice(held_out.highlights());
        let lights = LightSet::from_highlights(highlights);
        let world_side = config.world_side(side)?;
        let geometry = lights.geometry_on(side, world_side, DType::F32, gan.device())?;
        let mut features = Vec::new();
        let mut neural = Vec::new();
        for k in 0..s.materials {
            let seed = s.seed.wrapping_add(k as u64);
            let f = gan.features_for_seeds_at(&[seed], 1.0, side)?;
            neural.push(neural_renders(gan, &f, &geometry)?);
            features.push(f);
        }
        Ok(Self {
            features,
            neural,
            geometry,
            lights,
            reference_count: reference.len(),
            texel_size: config.map_texel_size(),
        })
    }

    /// The lights as `[x, y, held_out]` rows for the report.
    fn lights_described(&self) -> Vec<report::LightRow> {
        self.lights
            .highlights()
            .iter()
            .enumerate()
            .map(|(i, h)| report::LightRow {
                x: h.x,
                y: h.y,
                held_out: i >= self.reference_count,
            })
            .collect()
    }

    /// Scores `estimator` on every material and light, with its model's measured `render`
    /// cost, and writes the first material's maps to `maps_dir`.
    fn entry(
        &self,
        estimator: &EstimatorModel,
        run: &Path,
        maps_dir: &Path,
        reused: bool,
        render: cost::RenderCost,
    ) -> anyhow::Result<TradeEntry> {
        let brdf = estimator.brdf();
        let lights = self.lights.len();
        let mut l1_sum = vec![0.0; lights];
        let mut ssim_sum = vec![0.0; lights];
        let mut map_bytes = None;
        for (k, (features, neural)) in self.features.iter().zip(&self.neural).enumerate() {
            let maps = estimator
                .estimate(features)?
                .with_texel_size(self.texel_size);
            let analytic = analytic_renders(brdf, &maps, &self.geometry)?;
            let l1 = per_light_l1(&analytic, neural)?;
            let ssim = ssim::ssim(&analytic, neural)?;
            for i in 0..lights {
                l1_sum[i] += l1[i];
                ssim_sum[i] += ssim[i];
            }
            if k == 0 {
                map_bytes = Some(cost::write_and_measure(maps_dir, brdf, &maps)?);
            }
        }
        let n = self.features.len() as f64;
        let l1_per_light: Vec<f64> = l1_sum.iter().map(|v| v / n).collect();
        let ssim_per_light: Vec<f64> = ssim_sum.iter().map(|v| v / n).collect();
        Ok(TradeEntry {
            spec: brdf.name(),
            channels: brdf.channels(),
            estimator_dir: run.display().to_string(),
            reused,
            accuracy: Accuracy::new(l1_per_light, ssim_per_light, self.reference_count),
            cost: Cost {
                render,
                estimator_parameters: estimator.estimator().config().num_parameters(),
                step_seconds: mean_step_seconds(run)?,
                map_bytes: map_bytes.context("no evaluation material")?,
            },
            pareto: false,
        })
    }
}

/// Mean wall seconds per training step, from the run's `log.csv`.
fn mean_step_seconds(run: &Path) -> anyhow::Result<f64> {
    let seconds = log_column(run, "seconds")?;
    if seconds.is_empty() {
        bail!("{} holds no training step", run.join(LOG_FILE).display());
    }
    Ok(seconds.iter().sum::<f64>() / seconds.len() as f64)
}

/// The values of `column` in the run's `log.csv`, one per step row (rows where it does not
/// parse are skipped).
fn log_column(run: &Path, column: &str) -> anyhow::Result<Vec<f64>> {
    let log = run.join(LOG_FILE);
    let text =
        std::fs::read_to_string(&log).with_context(|| format!("cannot read {}", log.display()))?;
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default();
    let index = header
        .split(',')
        .position(|c| c == column)
        .with_context(|| format!("{} has no '{column}' column", log.display()))?;
    Ok(lines
        .filter_map(|line| line.split(',').nth(index)?.parse().ok())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folder_names_are_plain_and_distinct() {
        assert_eq!(
            folder_name("height(ggx, scale=0.02)"),
            "height-ggx-scale-0.02"
        );
        assert_eq!(
            folder_name("ggx(shadowing=correlated)"),
            "ggx-shadowing-correlated"
        );
        assert_eq!(folder_name("coated"), "coated");
        assert_ne!(folder_name("ggx(fresnel=constant)"), folder_name("ggx"));
    }
}
