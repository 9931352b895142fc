//! One sampled material, from seed to folder (the module docs of [`super`] list the files): G
//! makes its neural material, every candidate estimator decodes and renders it and one is kept
//! (the first, or with `--brdf auto` the cheapest within tolerance,
//! [`crate::model_choice::choose`]), `--simplify` may simplify its maps, and its folder, its
//! extras (2×2 tilings, exports) and its contact-sheet row are written.

use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use candle_core::Tensor;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::map_files::{SaveOptions, folder_bytes, save_maps};
use photomat_core::previews::map_previews;
use photomat_core::sheet::{centre_crop, grid, resize_square};
use photomat_core::simplify::{SimplifyRecord, simplify};
use photomat_core::{Brdf, FlashGeometry, MaterialMaps};

use super::renders::{analytic_renders, mean, neural_renders, per_light_l1, per_light_l1_within};
use super::{
    Candidate, MaterialSummary, SHEET_MAX_TILE, SIMPLIFY_METRICS, SampleOptions, Sampler,
    Selection, Timings, finite_mean, hextile,
};
use crate::EstimatorModel;

/// One run's fixed inputs.
pub(super) struct Job<'a> {
    pub sampler: &'a Sampler,
    pub options: &'a SampleOptions,
    /// The estimators to draw on: one, or with `tolerance` (auto) every one, cheapest first.
    pub candidates: &'a [&'a EstimatorModel],
    pub tolerance: Option<f64>,
    pub geometry: &'a FlashGeometry,
    /// `geometry`'s texels within a photo's reach of their flash (L, 1, R, R)
    /// ([`FlashGeometry::within_photo_reach`]).
    pub in_photo_reach: Tensor,
    /// Side of each material in texels.
    pub size: usize,
    /// Side of each render and preview in the sheets.
    pub tile: usize,
}

/// One sampled material: its summary and, when asked for, its contact-sheet row.
pub(super) struct Material {
    pub summary: MaterialSummary,
    pub sheet_row: Option<SheetRow>,
}

/// One candidate estimator's decoding of a material.
struct Decoding<'a> {
    estimator: &'a EstimatorModel,
    /// (1, C, R, R) maps of the estimator's model.
    maps: MaterialMaps,
    /// Their display-encoded renders under the job's lights (L, 3, R, R).
    analytic: Tensor,
    /// Per-light L1 of `analytic` against M's renders (display values).
    l1: Vec<f64>,
    /// Mean L1 of linear radiance (what auto compares; NaN when not choosing).
    l1_linear: f64,
}

/// The 2×2 renders of `--tileable` and `--hextile` (display-encoded, twice the tile side).
struct Tilings {
    tiled: Option<PlanarImage>,
    /// The hex-tiled render and the hex-tiled shading maps of the innermost model.
    hex: Option<(PlanarImage, MaterialMaps)>,
}

impl Job<'_> {
    /// Samples, renders and writes the material of `seed` into `folder`, with its contact-sheet
    /// row when `want_row`; `exported` sees the texture set of its export, if any.
    pub fn material(
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

        let mut decodings = self.decodings(&features, &neural, timings)?;
        let (chosen, selection) = self.choose(seed, &decodings)?;
        let Decoding {
            estimator,
            maps,
            analytic,
            l1,
            ..
        } = decodings.swap_remove(chosen);
        let brdf = estimator.brdf();
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
        let analytic_tiles = images(&analytic, self.tile)?;
        let neural_tiles = images(&neural, self.tile)?;
        let tilings = self.tilings(brdf, &maps, seed)?;
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
        write_tilings(folder, brdf, &tilings)?;
        self.export(folder, brdf, &maps, exported)?;
        timings.write += stage.elapsed().as_secs_f64();

        let sheet_row = want_row
            .then(|| sheet_row(brdf, &maps, &analytic_tiles, &neural_tiles, self.tile))
            .transpose()?;
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

    /// Every candidate's decoding of `features` (1, F, R, R), rendered and compared with M's
    /// renders `neural`.
    fn decodings(
        &self,
        features: &Tensor,
        neural: &Tensor,
        timings: &mut Timings,
    ) -> anyhow::Result<Vec<Decoding<'_>>> {
        let texel = self.sampler.gan.config().map_texel_size();
        let mut decodings = Vec::with_capacity(self.candidates.len());
        for &estimator in self.candidates {
            let stage = Instant::now();
            let maps = estimator.estimate(features)?.with_texel_size(texel);
            timings.estimate += stage.elapsed().as_secs_f64();
            let stage = Instant::now();
            let analytic = analytic_renders(estimator.brdf(), &maps, self.geometry)?;
            timings.render += stage.elapsed().as_secs_f64();
            let l1 = per_light_l1(&analytic, neural)?;
            let l1_linear = match self.tolerance {
                // Auto compares linear radiance (`model_choice` module docs).
                Some(_) => {
                    let gamma = photomat_core::render::DISPLAY_GAMMA;
                    mean(&per_light_l1(&analytic.powf(gamma)?, &neural.powf(gamma)?)?)
                }
                None => f64::NAN,
            };
            decodings.push(Decoding {
                estimator,
                maps,
                analytic,
                l1,
                l1_linear,
            });
        }
        Ok(decodings)
    }

    /// Which decoding is kept: the only one, or with a tolerance (auto) the cheapest within it,
    /// with the record of the choice.
    fn choose(
        &self,
        seed: u64,
        decodings: &[Decoding],
    ) -> anyhow::Result<(usize, Option<Selection>)> {
        let Some(tolerance) = self.tolerance else {
            return Ok((0, None));
        };
        let candidates: Vec<Candidate> = decodings
            .iter()
            .map(|d| Candidate {
                brdf: d.estimator.brdf().name(),
                channels: d.estimator.brdf().channels(),
                l1: mean(&d.l1),
                l1_linear: d.l1_linear,
            })
            .collect();
        let k = crate::model_choice::choose(&candidates, tolerance).with_context(|| {
            format!("seed {seed}: no model renders the material with a finite error")
        })?;
        let selection = Selection {
            chosen: candidates[k].brdf.clone(),
            tolerance,
            candidates,
        };
        Ok((k, Some(selection)))
    }

    /// The 2×2 renders the options ask for, of the innermost model's shading maps (an
    /// adapter's derived normal, so that the relief keeps its slope).
    fn tilings(&self, brdf: &Brdf, maps: &MaterialMaps, seed: u64) -> anyhow::Result<Tilings> {
        let options = self.options;
        let mut tilings = Tilings {
            tiled: None,
            hex: None,
        };
        if !(options.tileable || options.hextile) {
            return Ok(tilings);
        }
        let inner = brdf.innermost();
        let shading = brdf.shading_maps(maps)?;
        let side = 2 * self.tile;
        if options.tileable {
            let repeated = shading.map_tensors(|t| Ok(t.repeat((1, 1, 2, 2))?))?;
            tilings.tiled = Some(centre_render(&inner, &repeated, side)?);
        }
        if options.hextile {
            let hex_maps = hextile::hextile_maps(&inner, &shading, seed)?;
            tilings.hex = Some((centre_render(&inner, &hex_maps, side)?, hex_maps));
        }
        Ok(tilings)
    }

    /// `export/` with the glTF and MaterialX files the options ask for; `exported` sees the
    /// texture set.
    fn export(
        &self,
        folder: &Path,
        brdf: &Brdf,
        maps: &MaterialMaps,
        exported: &mut dyn FnMut(&photomat_export::TextureSet) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        let options = self.options;
        if !(options.gltf || options.mtlx) {
            return Ok(());
        }
        let export = folder.join("export");
        let set = photomat_export::write_textures(&export, brdf.as_ref(), maps)?;
        if options.gltf {
            photomat_export::write_gltf(&export, "material", &set)?;
        }
        if options.mtlx {
            photomat_export::write_materialx(&export, "material", &set)?;
        }
        exported(&set)
    }

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

/// `tiled_2x2.png`, and `hextile_2x2.png` with the hex-tiled maps `material_hextile_2x2/`.
fn write_tilings(folder: &Path, brdf: &Brdf, tilings: &Tilings) -> anyhow::Result<()> {
    if let Some(image) = &tilings.tiled {
        write_png(&folder.join("tiled_2x2.png"), image, PngBits::Eight)?;
    }
    if let Some((image, hex_maps)) = &tilings.hex {
        write_png(&folder.join("hextile_2x2.png"), image, PngBits::Eight)?;
        save_maps(
            &folder.join("material_hextile_2x2"),
            brdf.innermost().as_ref(),
            hex_maps,
            &SaveOptions::default(),
        )?;
    }
    Ok(())
}

/// The material's contact-sheet row: map previews, then the analytic and neural renders, each
/// at most [`SHEET_MAX_TILE`] pixels.
fn sheet_row(
    brdf: &Brdf,
    maps: &MaterialMaps,
    analytic_tiles: &[PlanarImage],
    neural_tiles: &[PlanarImage],
    tile: usize,
) -> anyhow::Result<SheetRow> {
    let sheet_tile = tile.min(SHEET_MAX_TILE);
    let previews_full = map_previews(brdf.as_ref(), maps)?;
    // A material larger than its tile starts its row with its first map's centre at one texel
    // per pixel, where the thumbnails average a fine lattice or grain away (first, so that
    // rows of models with fewer maps keep it in the same column).
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
    Ok(SheetRow {
        tiles: row,
        previews,
    })
}

/// One material's contact-sheet row: its map previews (after the detail tile of a large
/// material), then its renders.
pub(super) struct SheetRow {
    tiles: Vec<PlanarImage>,
    /// How many of `tiles` come before the renders (the detail tile and the map previews).
    previews: usize,
}

/// The rows as one grid's rows, black tiles inserted after the previews of a model with fewer
/// maps (auto mixes models) so that every row's renders share columns.
pub(super) fn aligned_rows(rows: Vec<SheetRow>) -> Vec<Vec<PlanarImage>> {
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
