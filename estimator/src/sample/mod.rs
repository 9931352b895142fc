//! The sampler: a complete model folder (G_ema + M + E, [`crate::EstimatorModel`] next to a
//! [`photomat_generator::GanModel`]) turned into materials, following the reference tool's
//! sampler (PhotoMat, Zhou et al. 2023, §3; `docs/conventions.md` for the geometry).
//!
//! For each seed, G turns z(seed) into a neural material F (truncation ψ), E decodes F into the
//! maps of its BRDF model, and [`Sampler::run`] writes, under `OUT/seed-XXXX/`:
//! - `material/`: the map folder (engine format: PNG + float EXR + material.json);
//! - `neural.png` / `analytic.png`: M's relighting of F and the flash render of the maps under
//!   the reference's 5 lights ([`LightSet::reference`]), side by side;
//! - with [`SampleOptions::tileable`] (tileable models only) `tiled_2x2.png`: the maps repeated
//!   2×2 under the centred flash; with [`SampleOptions::hextile`], `hextile_2x2.png` and
//!   `material_hextile_2x2/`: the maps hex-tiled ([`hextile::hextile_maps`]) to 2×2 periods,
//!   rendered the same way. The 2×2 renders show the shading maps of the innermost model (an
//!   adapter's derived normal, so the relief keeps its slope) on the unit square, i.e. the
//!   material at half size;
//! - with [`SampleOptions::gltf`] / [`SampleOptions::mtlx`]: `export/material.gltf` (+ `.bin`)
//!   / `export/material.mtlx` and their textures (`photomat_export`).
//!
//! Plus, for the run, `OUT/contact_sheet.png` (a row per material, the first
//! [`SHEET_MAX_ROWS`], of map previews, the 5 analytic renders and the 5 neural renders, tiles
//! at most [`SHEET_MAX_TILE`] pixels; for a material larger than that, the row starts with
//! its first map's centre at one texel per pixel) and `OUT/summary.json` ([`SampleSummary`]).
//!
//! Seeds are S, S+1, …, S+N−1; a seed names the same material on every run (z and the noise
//! images are drawn from the seed, `GanModel::features_for_seeds`): same seed, same files.
//!
//! One [`photomat_core::FlashGeometry`] of the lights is built per run and handed to both M
//! (its ω) and the analytic renderer ([`photomat_core::render_with`]).
//!
//! A binary of one's own (e.g. with extra BRDF plugins linked in) samples like this:
//!
//! ```no_run
//! use photomat_brdfs as _; // link the built-in plugins the model folder may name
//! use photomat_estimator::sample::{SampleEvent, SampleOptions, Sampler};
//!
//! let sampler = Sampler::open("models/demo".as_ref(), &candle_core::Device::Cpu)?;
//! let options = SampleOptions { count: 8, hextile: true, ..SampleOptions::default() };
//! let summary = sampler.run(&options, "samples".as_ref(), &mut |event| {
//!     if let SampleEvent::Note(line) = event {
//!         eprintln!("{line}");
//!     }
//!     Ok(())
//! })?;
//! println!("L1 analytic vs neural: {:.4}", summary.l1_mean);
//! # Ok::<(), anyhow::Error>(())
//! ```

pub mod hextile;
mod material;
mod renders;
pub mod summary;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::{DType, Device};
use photomat_core::LightSet;
use photomat_core::image_io::{PngBits, write_atomic, write_png};
use photomat_core::output_folder::{OutputFolder, ResultKind};
use photomat_core::sheet::grid;
use photomat_generator::GanModel;
use photomat_generator::model_files::GAN_MANIFEST_FILE;

use crate::EstimatorModel;
pub use crate::model_choice::{
    BrdfChoice, Candidate, DEFAULT_TOLERANCE, ESTIMATORS_DIR, Selection,
};
use crate::model_files::ESTIMATOR_MANIFEST_FILE;
pub use summary::{MaterialSummary, SampleSummary, SimplifyTotals, Timings};

use material::{Job, aligned_rows};
pub(crate) use renders::{analytic_renders, finite_mean, neural_renders, per_light_l1};

/// Materials shown in the contact sheet (the first ones of the run): 64 rows of 128-pixel
/// tiles are already an 8,400-pixel-tall image; the per-material PNGs hold every material.
pub const SHEET_MAX_ROWS: usize = 64;

/// Largest tile side in the contact sheet, in pixels (tiles are shrunk to it).
pub const SHEET_MAX_TILE: usize = 128;

/// Texels relit and rendered per call: all 5 lights at up to 512² (≈ 1.3 M texels, a few
/// hundred MB of intermediates), fewer lights at a time above.
pub const LIGHT_BATCH_TEXELS: usize = 5 * 512 * 512;

/// The errors `--simplify` keeps within its tolerance, both against M's renders under the
/// reference lights: the L1 of linear radiance (dominated by the highlight, as `--brdf auto`
/// compares) and the L1 of display-encoded images (which also sees the texture away from it).
pub const SIMPLIFY_METRICS: [&str; 2] = ["l1_linear", "l1_display"];

/// Name of the contact sheet in the output folder.
pub const CONTACT_SHEET_FILE: &str = "contact_sheet.png";

/// Name of the run summary in the output folder.
pub const SUMMARY_FILE: &str = "summary.json";

/// What to sample and which extras to write.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleOptions {
    /// Number of materials (at least 1).
    pub count: usize,
    /// First seed; material k uses seed `seed + k` (wrapping).
    pub seed: u64,
    /// Truncation ψ: 1 samples the full distribution, smaller values stay nearer the average.
    pub psi: f64,
    /// Also write `tiled_2x2.png` (the model must be tileable).
    pub tileable: bool,
    /// Also hex-tile the maps to 2×2 periods: `hextile_2x2.png`, `material_hextile_2x2/`.
    pub hextile: bool,
    /// Also write `export/material.gltf` and its textures.
    pub gltf: bool,
    /// Also write `export/material.mtlx` and its textures.
    pub mtlx: bool,
    /// Side of each material in texels (`None`: the model's native side,
    /// [`photomat_generator::GeneratorConfig::sample_side`]: R for a fixed-size model, 512 for
    /// a spatial one). A spatial model makes any multiple of its cell that is also a multiple
    /// of the estimator's stride; its texel keeps its world size, so a larger side shows more
    /// of the material.
    pub size: Option<usize>,
    /// Side in pixels of each render and preview in the PNG sheets (`None`: the material's
    /// side); the maps keep the material's side.
    pub render_size: Option<usize>,
    /// Replace the samples already in the output folder (its `seed-*` folders, contact
    /// sheet and summary); without it a folder that holds samples is refused, so that two
    /// runs never mix and summary.json lists every seed folder there.
    pub overwrite: bool,
    /// Which estimator, and so which BRDF model, each material gets ([`choice`]).
    pub brdf: BrdfChoice,
    /// Simplify each material's maps ([`photomat_core::simplify`]) within this relative
    /// tolerance of both its errors against M's renders ([`SIMPLIFY_METRICS`]): constant maps
    /// become values in material.json and factors in the exports, near-grey colour maps one
    /// channel.
    pub simplify: Option<f64>,
}

impl Default for SampleOptions {
    fn default() -> Self {
        Self {
            count: 4,
            seed: 0,
            psi: 1.0,
            tileable: false,
            hextile: false,
            gltf: false,
            mtlx: false,
            size: None,
            render_size: None,
            overwrite: false,
            brdf: BrdfChoice::Default,
            simplify: None,
        }
    }
}

/// What [`Sampler::run`] reports while it works.
#[derive(Debug, Clone, PartialEq)]
pub enum SampleEvent {
    /// A line for the user (a caveat of the run or of an export mapping).
    Note(String),
    /// `done` of `total` materials are written.
    Material { done: usize, total: usize },
}

/// A loaded model folder, ready to sample.
pub struct Sampler {
    dir: PathBuf,
    gan: GanModel,
    /// The root estimator first, then those of `estimators/*/`, cheapest first
    /// ([`crate::model_choice::load_estimators`]).
    estimators: Vec<EstimatorModel>,
    /// Seconds spent loading.
    load_seconds: f64,
}

/// Whether `dir` holds a complete model folder; otherwise the name of the first manifest that
/// is missing.
pub fn missing_model_file(dir: &Path) -> Option<&'static str> {
    [GAN_MANIFEST_FILE, ESTIMATOR_MANIFEST_FILE]
        .into_iter()
        .find(|m| !dir.join(m).is_file())
}

impl Sampler {
    /// Loads the model folder `dir` (gan.json + gan.safetensors, estimator.json +
    /// estimator.safetensors, and any `estimators/*/`) and checks that every E reads the
    /// features G produces.
    pub fn open(dir: &Path, device: &Device) -> anyhow::Result<Self> {
        let start = Instant::now();
        let gan = GanModel::load(dir, device)
            .with_context(|| format!("cannot load the GAN model in '{}'", dir.display()))?;
        let estimators =
            crate::model_choice::load_estimators(dir, gan.config().feature_channels, device)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            gan,
            estimators,
            load_seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The GAN (G_ema + M).
    pub fn gan(&self) -> &GanModel {
        &self.gan
    }

    /// The default (root) estimator E with its BRDF model.
    pub fn estimator(&self) -> &EstimatorModel {
        &self.estimators[0]
    }

    /// Every estimator of the folder: the default first, then the others cheapest first.
    pub fn estimators(&self) -> &[EstimatorModel] {
        &self.estimators
    }

    /// The estimators `choice` draws on, cheapest first for auto; an error naming the
    /// available models when a named one is missing.
    pub fn candidates(&self, choice: &BrdfChoice) -> anyhow::Result<Vec<&EstimatorModel>> {
        match choice {
            BrdfChoice::Default => Ok(vec![&self.estimators[0]]),
            BrdfChoice::Named(spec) => {
                let name = photomat_core::lookup(spec)
                    .with_context(|| format!("invalid --brdf '{spec}'"))?
                    .name();
                self.estimators
                    .iter()
                    .find(|e| e.brdf().name() == name)
                    .map(|e| vec![e])
                    .with_context(|| {
                        format!(
                            "the model folder '{}' has no estimator for '{name}'; it has: {} \
                             (train one with `photomat train-estimator --gan {} --brdf '{name}'` \
                             and put its estimator.json and estimator.safetensors in {}/<name>/)",
                            self.dir.display(),
                            self.brdf_names().join(", "),
                            self.dir.display(),
                            ESTIMATORS_DIR
                        )
                    })
            }
            BrdfChoice::Auto { .. } => {
                let mut all: Vec<&EstimatorModel> = self.estimators.iter().collect();
                all.sort_by_cached_key(|e| crate::model_choice::cost_key(e));
                Ok(all)
            }
        }
    }

    /// The BRDF models of the folder's estimators, default first.
    pub fn brdf_names(&self) -> Vec<String> {
        self.estimators.iter().map(|e| e.brdf().name()).collect()
    }

    /// The lights of the neural and analytic renders: the reference's five, placed relative
    /// to the material's extent (a spatial model's N-texel material covers N × texel size
    /// world units; [`LightSet::geometry_on`]).
    pub fn lights(&self) -> LightSet {
        LightSet::reference()
    }

    /// The side in texels of the materials of a run asked for `size` (module docs): the
    /// GAN's [`photomat_generator::GeneratorConfig::sample_side`], also checked against the
    /// estimator's stride, with an error naming the possible sides.
    pub fn material_side(&self, size: Option<usize>) -> anyhow::Result<usize> {
        let config = self.gan.config();
        let side = config.sample_side(size)?;
        let stride = self
            .estimators
            .iter()
            .map(|e| e.estimator().config().total_stride())
            .fold(1, |a, b| a * b / gcd(a, b));
        if side % stride != 0 {
            let step = stride * config.cell_size() / gcd(stride, config.cell_size());
            bail!(
                "a material side of {side} texels is not possible with this model: the \
                 estimator reads sides that are multiples of {stride} and the generator makes \
                 multiples of {}; use a multiple of {step} (e.g. {})",
                config.cell_size(),
                side.div_ceil(step) * step
            );
        }
        Ok(side)
    }

    /// Samples `options.count` materials into `out`, reporting to `progress`, with
    /// `out/contact_sheet.png` and `out/summary.json`. The folder is written whole when the
    /// run ends ([`photomat_core::output_folder`]: locked, a second process on it fails naming
    /// this one; an error or a kill leaves it as it was). A folder that already holds samples
    /// is refused unless `options.overwrite`, which replaces them whole; one holding files a
    /// sample run does not write is refused. The material side's memory is checked first.
    pub fn run(
        &self,
        options: &SampleOptions,
        out: &Path,
        progress: &mut dyn FnMut(SampleEvent) -> anyhow::Result<()>,
    ) -> anyhow::Result<SampleSummary> {
        let start = Instant::now();
        let config = self.gan.config();
        if !options.psi.is_finite() {
            bail!("ψ must be a finite number, got {}", options.psi);
        }
        if options.count == 0 {
            bail!("the number of materials must be at least 1");
        }
        if options.tileable && !config.tileable {
            bail!(
                "--tileable: the model in '{}' is not tileable (gan.json: architecture.tileable \
                 = false), its materials have seams when repeated; train one with `photomat \
                 train-gan --tileable`, or use --hextile, which hides the repetition of any \
                 material",
                self.dir.display()
            );
        }
        let candidates = self.candidates(&options.brdf)?;
        let tolerance = match options.brdf {
            BrdfChoice::Auto { tolerance } => Some(tolerance),
            _ => None,
        };
        let resolution = self.material_side(options.size)?;
        let lights = self.lights();
        let world_side = config.world_side(resolution)?;
        let geometry = lights.geometry_on(resolution, world_side, DType::F32, self.gan.device())?;
        check_memory(resolution, config.channel_multiplier)?;
        // Written whole or not at all: an earlier run's samples are refused unless
        // overwritten, and a killed run leaves them as they were.
        let result = OutputFolder::claim(out, SAMPLES, options.overwrite)?;
        let (output, out) = (out, result.path());
        if options.hextile && !config.tileable {
            progress(SampleEvent::Note(
                "note: the model is not tileable; the maps' own border seam can show inside \
                 the hexagons of hextile_2x2.png"
                    .into(),
            ))?;
        }
        let mut timings = Timings {
            load: self.load_seconds + start.elapsed().as_secs_f64(),
            ..Timings::default()
        };
        let job = Job {
            sampler: self,
            options,
            candidates: &candidates,
            tolerance,
            geometry: &geometry,
            in_photo_reach: geometry.within_photo_reach()?,
            size: resolution,
            tile: options.render_size.unwrap_or(resolution),
        };
        let mut rows = Vec::new();
        let mut materials = Vec::new();
        let mut notes_shown = false;
        for k in 0..options.count {
            let seed = options.seed.wrapping_add(k as u64);
            let folder = out.join(format!("seed-{seed:04}"));
            let want_row = rows.len() < SHEET_MAX_ROWS;
            let material = job.material(seed, &folder, want_row, &mut timings, &mut |set| {
                if notes_shown {
                    return Ok(());
                }
                notes_shown = true;
                for note in &set.dropped {
                    progress(SampleEvent::Note(format!("export: dropped {note}")))?;
                }
                for note in &set.approximations {
                    progress(SampleEvent::Note(format!("export: approximation: {note}")))?;
                }
                Ok(())
            })?;
            rows.extend(material.sheet_row);
            // The summary names where the material will be, not where it is written first.
            let mut summary = material.summary;
            summary.folder = output.join(format!("seed-{seed:04}")).display().to_string();
            materials.push(summary);
            progress(SampleEvent::Material {
                done: k + 1,
                total: options.count,
            })?;
        }

        let stage = Instant::now();
        write_png(
            &out.join(CONTACT_SHEET_FILE),
            &grid(&aligned_rows(rows), 0.0)?,
            PngBits::Eight,
        )?;
        timings.write += stage.elapsed().as_secs_f64();
        timings.total = self.load_seconds + start.elapsed().as_secs_f64();
        let summary = SampleSummary::new(
            self.dir.display().to_string(),
            match tolerance {
                Some(_) => "auto".to_string(),
                None => candidates[0].brdf().name(),
            },
            resolution,
            options.psi,
            config.tileable,
            lights.highlights().iter().map(|h| [h.x, h.y]).collect(),
            materials,
            timings,
        );
        let mut text = serde_json::to_string_pretty(&summary)?;
        text.push('\n');
        write_atomic(&out.join(SUMMARY_FILE), text.as_bytes())?;
        result.commit()?;
        Ok(summary)
    }
}

/// What a sample run's output folder holds.
pub const SAMPLES: ResultKind = ResultKind {
    what: "samples",
    command: "photomat sample",
    entries: &["seed-*", CONTACT_SHEET_FILE, SUMMARY_FILE],
    kept: &[],
};

/// Peak memory of sampling one material of `side`² texels: about 1.3 kB per texel on top of
/// 256 MB for the bundled model (channel multiplier ⅛; measured 2026-12-08: 0.43 GB at 512²,
/// 1.18 GB at 1024², 5.46 GB at 2048²), the per-texel part growing with the generator's
/// channel multiplier.
pub fn sample_memory_bytes(side: usize, channel_multiplier: f64) -> u64 {
    let per_texel = 1300.0 * (channel_multiplier / 0.125).max(1.0);
    (256u64 << 20) + (per_texel * (side * side) as f64) as u64
}

/// Refuses a material side whose estimated peak exceeds the memory available, naming the
/// largest side that fits.
fn check_memory(side: usize, channel_multiplier: f64) -> anyhow::Result<()> {
    let estimate = |s: usize| sample_memory_bytes(s, channel_multiplier);
    photomat_core::memory::check(estimate(side), &format!("--size {side}"), |available| {
        let sides = (1..=128).map(|k| 32 * k);
        match photomat_core::memory::largest_fitting(sides, estimate, available) {
            Some((s, bytes)) => format!(
                "use --size {s} (about {}) or less",
                photomat_core::memory::format_bytes(bytes)
            ),
            None => "free some memory".to_string(),
        }
    })?;
    Ok(())
}

/// Greatest common divisor (Euclid).
fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}
