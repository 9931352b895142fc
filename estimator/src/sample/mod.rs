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

pub mod choice;
pub mod hextile;
pub mod summary;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use photomat_core::folder_lock::clear_previous_outputs;
use photomat_core::image_io::{PlanarImage, PngBits, write_atomic, write_png};
use photomat_core::map_files::{SaveOptions, folder_bytes, save_maps};
use photomat_core::previews::map_previews;
use photomat_core::sheet::{centre_crop, grid, resize_square};
use photomat_core::simplify::{SimplifyRecord, simplify};
use photomat_core::{Brdf, FlashGeometry, FolderLock, LightSet, MaterialMaps, render_with};
use photomat_generator::GanModel;
use photomat_generator::model_files::GAN_MANIFEST_FILE;

use crate::EstimatorModel;
use crate::model_files::ESTIMATOR_MANIFEST_FILE;
pub use choice::{BrdfChoice, Candidate, DEFAULT_TOLERANCE, ESTIMATORS_DIR, Selection};
pub use summary::{MaterialSummary, SampleSummary, SimplifyTotals, Timings};

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
    /// ([`choice::load_estimators`]).
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
        let estimators = choice::load_estimators(dir, gan.config().feature_channels, device)?;
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
                all.sort_by_cached_key(|e| choice::cost_key(e));
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

    /// Samples `options.count` materials into `out` (created, and locked while it is
    /// written: a second process on it fails naming this one), reporting to `progress`, and
    /// writes `out/contact_sheet.png` and `out/summary.json`. A folder that already holds
    /// samples is refused unless `options.overwrite`, which removes them first.
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
        let _lock = FolderLock::acquire(out, "photomat sample")?;
        clear_previous_samples(out, options.overwrite)?;
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
            materials.push(material.summary);
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
        Ok(summary)
    }
}

/// One run's fixed inputs.
struct Job<'a> {
    sampler: &'a Sampler,
    options: &'a SampleOptions,
    /// The estimators to draw on: one, or with `tolerance` (auto) every one, cheapest first.
    candidates: &'a [&'a EstimatorModel],
    tolerance: Option<f64>,
    geometry: &'a FlashGeometry,
    /// `geometry`'s texels within a photo's reach of their flash (L, 1, R, R)
    /// ([`FlashGeometry::within_photo_reach`]).
    in_photo_reach: Tensor,
    /// Side of each material in texels.
    size: usize,
    /// Side of each render and preview in the sheets.
    tile: usize,
}

/// One sampled material: its summary and, when asked for, its contact-sheet row.
struct Material {
    summary: MaterialSummary,
    sheet_row: Option<SheetRow>,
}

impl Job<'_> {
    /// Samples, renders and writes the material of `seed` into `folder`, with its contact-sheet
    /// row when `want_row`; `exported` sees the texture set of its export, if any.
    fn material(
        &self,
        seed: u64,
        folder: &Path,
        want_row: bool,
        timings: &mut Timings,
        exported: &mut dyn FnMut(&photomat_export::TextureSet) -> anyhow::Result<()>,
    ) -> anyhow::Result<Material> {
        let (gan, options) = (&self.sampler.gan, self.options);
        let stage = Instant::now();
        let features = gan.features_for_seeds_at(&[seed], options.psi, self.size)?;
        timings.generate += stage.elapsed().as_secs_f64();
        let stage = Instant::now();
        let neural = neural_renders(gan, &features, self.geometry)?;
        timings.relight += stage.elapsed().as_secs_f64();
        // Every candidate decodes and renders the material; one is kept.
        let mut scored = Vec::new();
        for estimator in self.candidates {
            let stage = Instant::now();
            let maps = estimator
                .estimate(&features)?
                .with_texel_size(gan.config().map_texel_size());
            timings.estimate += stage.elapsed().as_secs_f64();
            let stage = Instant::now();
            let analytic = analytic_renders(estimator.brdf(), &maps, self.geometry)?;
            timings.render += stage.elapsed().as_secs_f64();
            let l1 = per_light_l1(&analytic, &neural)?;
            let l1_linear = match self.tolerance {
                // Auto compares linear radiance (`choice` module docs).
                Some(_) => mean(&per_light_l1(
                    &analytic.powf(photomat_core::render::DISPLAY_GAMMA)?,
                    &neural.powf(photomat_core::render::DISPLAY_GAMMA)?,
                )?),
                None => f64::NAN,
            };
            scored.push((estimator, maps, analytic, l1, l1_linear));
        }
        let (chosen, selection) = match self.tolerance {
            None => (0, None),
            Some(tolerance) => {
                let candidates: Vec<Candidate> = scored
                    .iter()
                    .map(|(e, _, _, l1, l1_linear)| Candidate {
                        brdf: e.brdf().name(),
                        channels: e.brdf().channels(),
                        l1: mean(l1),
                        l1_linear: *l1_linear,
                    })
                    .collect();
                let k = choice::choose(&candidates, tolerance).with_context(|| {
                    format!("seed {seed}: no model renders the material with a finite error")
                })?;
                let selection = Selection {
                    chosen: candidates[k].brdf.clone(),
                    tolerance,
                    candidates,
                };
                (k, Some(selection))
            }
        };
        let (estimator, maps, analytic, l1, _) = scored.swap_remove(chosen);
        let brdf = estimator.brdf();
        let inner = brdf.innermost();
        let mut save_options = SaveOptions {
            selection: selection.as_ref().map(serde_json::to_value).transpose()?,
            ..SaveOptions::default()
        };
        let (maps, analytic, l1, simplification) = match options.simplify {
            None => (maps, analytic, l1, None),
            Some(tolerance) => {
                let stage = Instant::now();
                let simplified = self
                    .simplified(
                        brdf,
                        maps,
                        analytic,
                        l1,
                        &neural,
                        tolerance,
                        &mut save_options,
                    )
                    .with_context(|| format!("seed {seed}: cannot simplify the maps"))?;
                timings.simplify += stage.elapsed().as_secs_f64();
                simplified
            }
        };

        let stage = Instant::now();
        let tile = self.tile;
        let analytic_tiles = images(&analytic, tile)?;
        let neural_tiles = images(&neural, tile)?;
        let extras = (options.tileable || options.hextile)
            .then(|| brdf.shading_maps(&maps))
            .transpose()?;
        let mut tiled = None;
        let mut hex = None;
        if let Some(shading) = &extras {
            if options.tileable {
                let repeated = shading.map_tensors(|t| Ok(t.repeat((1, 1, 2, 2))?))?;
                tiled = Some(centre_render(&inner, &repeated, 2 * tile)?);
            }
            if options.hextile {
                let maps2 = hextile::hextile_maps(&inner, shading, seed)?;
                hex = Some((centre_render(&inner, &maps2, 2 * tile)?, maps2));
            }
        }
        timings.extras += stage.elapsed().as_secs_f64();

        let stage = Instant::now();
        save_maps(
            &folder.join("material"),
            brdf.as_ref(),
            &maps,
            &save_options,
        )
        .with_context(|| format!("cannot write the maps of seed {seed}"))?;
        let strip = |tiles: &[PlanarImage]| grid(&[tiles.to_vec()], 0.0);
        write_png(
            &folder.join("neural.png"),
            &strip(&neural_tiles)?,
            PngBits::Eight,
        )?;
        write_png(
            &folder.join("analytic.png"),
            &strip(&analytic_tiles)?,
            PngBits::Eight,
        )?;
        if let Some(image) = &tiled {
            write_png(&folder.join("tiled_2x2.png"), image, PngBits::Eight)?;
        }
        if let Some((image, maps2)) = &hex {
            write_png(&folder.join("hextile_2x2.png"), image, PngBits::Eight)?;
            save_maps(
                &folder.join("material_hextile_2x2"),
                inner.as_ref(),
                maps2,
                &SaveOptions::default(),
            )?;
        }
        if options.gltf || options.mtlx {
            let export = folder.join("export");
            let set = photomat_export::write_textures(&export, brdf.as_ref(), &maps)?;
            if options.gltf {
                photomat_export::write_gltf(&export, "material", &set)?;
            }
            if options.mtlx {
                photomat_export::write_materialx(&export, "material", &set)?;
            }
            exported(&set)?;
        }
        timings.write += stage.elapsed().as_secs_f64();

        let sheet_row = if want_row {
            let sheet_tile = tile.min(SHEET_MAX_TILE);
            let previews_full = map_previews(brdf.as_ref(), &maps)?;
            // A material larger than its tile starts its row with its first map's centre at
            // one texel per pixel, where the thumbnails average a fine lattice or grain away
            // (first, so that rows of models with fewer maps keep it in the same column).
            let mut row: Vec<PlanarImage> = previews_full
                .first()
                .filter(|(_, first)| first.width > sheet_tile)
                .map(|(_, first)| centre_crop(first, sheet_tile))
                .into_iter()
                .collect();
            row.extend(
                previews_full
                    .iter()
                    .map(|(_, p)| resize_square(p, sheet_tile)),
            );
            let previews = row.len();
            row.extend(analytic_tiles.iter().map(|t| resize_square(t, sheet_tile)));
            row.extend(neural_tiles.iter().map(|t| resize_square(t, sheet_tile)));
            Some(SheetRow {
                tiles: row,
                previews,
            })
        } else {
            None
        };
        let l1_in_reach = per_light_l1_within(&analytic, &neural, &self.in_photo_reach)?;
        Ok(Material {
            summary: MaterialSummary {
                seed,
                folder: folder.display().to_string(),
                brdf: brdf.name(),
                selection,
                simplification,
                l1_mean: mean(&l1),
                l1_per_light: l1,
                l1_within_photo_reach: finite_mean(&l1_in_reach),
                l1_within_photo_reach_per_light: l1_in_reach,
            },
            sheet_row,
        })
    }
}

impl Job<'_> {
    /// `--simplify`: the maps simplified within `tolerance` of both [`SIMPLIFY_METRICS`]
    /// against M's renders `neural`, their renders and per-light L1 (the ones given when no
    /// map could be simplified), and the record, which `save_options` then carries with
    /// `compact` set.
    #[allow(clippy::too_many_arguments)]
    fn simplified(
        &self,
        brdf: &Brdf,
        maps: MaterialMaps,
        analytic: Tensor,
        l1: Vec<f64>,
        neural: &Tensor,
        tolerance: f64,
        save_options: &mut SaveOptions,
    ) -> anyhow::Result<(MaterialMaps, Tensor, Vec<f64>, Option<SimplifyRecord>)> {
        let gamma = photomat_core::render::DISPLAY_GAMMA;
        let linear_neural = neural.powf(gamma)?;
        let simplified = simplify(brdf.as_ref(), &maps, tolerance, |m| {
            let analytic = analytic_renders(brdf, m, self.geometry)?;
            let linear = analytic.powf(gamma)?;
            Ok::<_, anyhow::Error>(vec![
                mean(&per_light_l1(&linear, &linear_neural)?),
                mean(&per_light_l1(&analytic, neural)?),
            ])
        })?;
        let bytes_before = folder_bytes(brdf.as_ref(), &maps, save_options)?;
        save_options.compact = true;
        let bytes_after = folder_bytes(brdf.as_ref(), &simplified.maps, save_options)?;
        let record = simplified.record(&SIMPLIFY_METRICS, bytes_before, bytes_after);
        save_options.simplification = Some(serde_json::to_value(&record)?);
        if simplified.steps.is_empty() {
            return Ok((maps, analytic, l1, Some(record)));
        }
        let analytic = analytic_renders(brdf, &simplified.maps, self.geometry)?;
        let l1 = per_light_l1(&analytic, neural)?;
        Ok((simplified.maps, analytic, l1, Some(record)))
    }
}

/// Lights per call of M or the renderer at a side of `side` texels: all of them up to
/// [`LIGHT_BATCH_TEXELS`] texels, fewer above (M's and the renderer's intermediates scale with
/// the batch: 5 lights of a 1024² material would hold gigabytes at once).
fn lights_per_call(geometry: &FlashGeometry, side: usize) -> anyhow::Result<usize> {
    let lights = geometry.omega.dim(0)?;
    Ok((LIGHT_BATCH_TEXELS / (side * side)).clamp(1, lights))
}

/// M's relighting of `features` under every light of `geometry`, display-encoded in [0, 1]
/// ([`photomat_generator::relight::to_display`]), in groups of lights that bound the memory.
///
/// # Shapes
/// features (1, F, R, R) → (lights, 3, R, R).
pub(crate) fn neural_renders(
    gan: &GanModel,
    features: &Tensor,
    geometry: &FlashGeometry,
) -> anyhow::Result<Tensor> {
    let lights = geometry.omega.dim(0)?;
    let per_call = lights_per_call(geometry, features.dim(3)?)?;
    let mut neural = Vec::new();
    for first in (0..lights).step_by(per_call) {
        let n = per_call.min(lights - first);
        let group = geometry.narrow(first, n)?;
        let repeated = features.repeat((n, 1, 1, 1))?;
        neural.push(gan.relight().forward(&repeated, &group.omega)?);
    }
    Ok(photomat_generator::relight::to_display(&Tensor::cat(
        &neural, 0,
    )?)?)
}

/// The analytic render of `maps` in `brdf` under every light of `geometry`, display-encoded in
/// [0, 1], in the same groups of lights as [`neural_renders`].
///
/// # Shapes
/// maps (1, C, R, R) → (lights, 3, R, R).
pub(crate) fn analytic_renders(
    brdf: &Brdf,
    maps: &MaterialMaps,
    geometry: &FlashGeometry,
) -> anyhow::Result<Tensor> {
    let lights = geometry.omega.dim(0)?;
    let (_, side, _) = maps.batch_and_size()?;
    let per_call = lights_per_call(geometry, side)?;
    let mut analytic = Vec::new();
    for first in (0..lights).step_by(per_call) {
        let group = geometry.narrow(first, per_call.min(lights - first))?;
        analytic.push(render_with(brdf.as_ref(), maps, &group)?);
    }
    Ok(Tensor::cat(&analytic, 0)?)
}

/// One material's contact-sheet row: its map previews (after the detail tile of a large
/// material), then its renders.
struct SheetRow {
    tiles: Vec<PlanarImage>,
    /// How many of `tiles` come before the renders (the detail tile and the map previews).
    previews: usize,
}

/// The rows as one grid's rows, black tiles inserted after the previews of a model with fewer
/// maps (auto mixes models) so that every row's renders share columns.
fn aligned_rows(rows: Vec<SheetRow>) -> Vec<Vec<PlanarImage>> {
    let most = rows.iter().map(|r| r.previews).max().unwrap_or(0);
    rows.into_iter()
        .map(|mut row| {
            if let Some(first) = row.tiles.first() {
                let blank = PlanarImage::filled(first.channels, first.height, first.width, 0.0);
                let at = row.previews;
                row.tiles
                    .splice(at..at, std::iter::repeat_n(blank, most - row.previews));
            }
            row.tiles
        })
        .collect()
}

/// Mean absolute difference per light of two (lights, 3, R, R) batches.
pub(crate) fn per_light_l1(a: &Tensor, b: &Tensor) -> anyhow::Result<Vec<f64>> {
    Ok((a - b)?
        .abs()?
        .flatten_from(1)?
        .mean(1)?
        .to_dtype(DType::F64)?
        .to_vec1()?)
}

/// Per light, the mean |a − b| over the texels where `mask` is 1: (L, C, R, R) renders and an
/// (L, 1, R, R) 0/1 mask give L values, NaN for a light whose mask is empty.
pub(crate) fn per_light_l1_within(
    a: &Tensor,
    b: &Tensor,
    mask: &Tensor,
) -> anyhow::Result<Vec<f64>> {
    let channels = a.dim(1)? as f64;
    let mask = mask.to_dtype(a.dtype())?;
    let sums: Vec<f64> = (a - b)?
        .abs()?
        .broadcast_mul(&mask)?
        .flatten_from(1)?
        .sum(1)?
        .to_dtype(DType::F64)?
        .to_vec1()?;
    let counts: Vec<f64> = mask
        .flatten_from(1)?
        .sum(1)?
        .to_dtype(DType::F64)?
        .to_vec1()?;
    Ok(sums
        .iter()
        .zip(&counts)
        .map(|(s, n)| {
            if *n > 0.0 {
                s / (n * channels)
            } else {
                f64::NAN
            }
        })
        .collect())
}

/// The mean of a non-empty list.
fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The mean of the finite values of a list; NaN when there is none.
pub(crate) fn finite_mean(values: &[f64]) -> f64 {
    let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        f64::NAN
    } else {
        mean(&finite)
    }
}

/// Greatest common divisor (Euclid).
fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The display-encoded render of `maps` under the centred flash, resized to `side`.
fn centre_render(brdf: &Brdf, maps: &MaterialMaps, side: usize) -> anyhow::Result<PlanarImage> {
    let image = photomat_core::render(brdf.as_ref(), maps, &[photomat_core::Highlight::CENTER])?;
    Ok(resize_square(&PlanarImage::from_tensor(&image)?, side))
}

/// The items of a (B, 3, R, R) batch as images resized to `side`.
fn images(batch: &Tensor, side: usize) -> anyhow::Result<Vec<PlanarImage>> {
    (0..batch.dim(0)?)
        .map(|i| {
            Ok(resize_square(
                &PlanarImage::from_tensor(&batch.narrow(0, i, 1)?)?,
                side,
            ))
        })
        .collect()
}

/// What a sample run writes directly under its output folder, besides `seed-*` folders.
const SAMPLE_FILES: [&str; 2] = [CONTACT_SHEET_FILE, SUMMARY_FILE];

/// Whether `name` is a material folder of a sample run: `seed-` and the seed's digits.
fn is_seed_folder(name: &str) -> bool {
    name.strip_prefix("seed-")
        .is_some_and(|digits| !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()))
}

/// Refuses an `out` that holds a previous run's samples, or with `overwrite` removes them
/// (the `seed-*` folders, the contact sheet and the summary; nothing else in `out`).
fn clear_previous_samples(out: &Path, overwrite: bool) -> anyhow::Result<()> {
    let entries =
        std::fs::read_dir(out).with_context(|| format!("cannot list '{}'", out.display()))?;
    let mut previous = Vec::new();
    let mut folders = 0;
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
        if (is_dir && is_seed_folder(&name)) || (!is_dir && SAMPLE_FILES.contains(&name.as_str())) {
            folders += usize::from(is_dir);
            previous.push(entry.path());
        }
    }
    let summary = previous.iter().any(|p| p.ends_with(SUMMARY_FILE));
    clear_previous_outputs(out, &previous, overwrite, || {
        format!(
            "already holds samples ({folders} seed folder(s){}); add --overwrite to replace \
             them, or choose another --out",
            if summary { ", summary.json" } else { "" }
        )
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The masked L1 averages over the masked texels only, and is NaN where none is.
    #[test]
    fn l1_within_a_mask_averages_only_the_masked_texels() -> anyhow::Result<()> {
        let device = candle_core::Device::Cpu;
        // Two lights, 3 channels, 2×2 texels: |a − b| is 0.1 on the left column, 0.5 on the right.
        let diff =
            Tensor::new(&[[0.1f32, 0.5], [0.1, 0.5]], &device)?.broadcast_as((2, 3, 2, 2))?;
        let b = Tensor::zeros((2, 3, 2, 2), DType::F32, &device)?;
        let a = (&b + diff)?;
        let left = Tensor::new(&[[1f32, 0.0], [1.0, 0.0]], &device)?.reshape((1, 1, 2, 2))?;
        let mask = Tensor::cat(
            &[left, Tensor::zeros((1, 1, 2, 2), DType::F32, &device)?],
            0,
        )?;
        let l1 = per_light_l1_within(&a, &b, &mask)?;
        assert!((l1[0] - 0.1).abs() < 1e-7, "{l1:?}");
        assert!(l1[1].is_nan());
        assert!((finite_mean(&l1) - 0.1).abs() < 1e-7);
        assert!((mean(&per_light_l1(&a, &b)?) - 0.3).abs() < 1e-7);
        Ok(())
    }
}
