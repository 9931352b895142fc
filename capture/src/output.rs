//! A capture on disk (docs/capture.md, "Output"): the maps as a material folder, the renderer
//! textures and documents, the sheet (photo | re-render | error), the maps relit under eight
//! new flashes, and `capture.json`.

use std::path::Path;

use anyhow::Context;

use candle_core::{DType, Device, Tensor};
use photomat_core::image_io::{PlanarImage, PngBits, write_atomic, write_png};
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::render::{DISPLAY_GAMMA, render_radiance_with};
use photomat_core::sheet::grid;
use photomat_core::{FlashGeometry, Highlight, MaterialMaps, encode_display};
use serde::Serialize;

use crate::field_of_view::FovSource;
use crate::result::{Capture, CoarseStage, HighlightUsed};
use crate::square::new_flash_positions;

/// The fitted maps rendered under `lights` (flash positions on the captured square, e.g.
/// [`new_flash_positions`]), with the fitted gain, as display values: (L, 3, N, N).
pub fn relight(capture: &Capture, lights: &[Highlight]) -> anyhow::Result<Tensor> {
    render_on_square(capture, &capture.maps, capture.gain, lights)
}

/// `maps` of the capture's model rendered under `lights` on the captured square, times
/// `gain`, as display values: (L, 3, N, N).
fn render_on_square(
    capture: &Capture,
    maps: &MaterialMaps,
    gain: f64,
    lights: &[Highlight],
) -> anyhow::Result<Tensor> {
    let (_, _, n, _) = capture.photo.dims4()?;
    let geometry = FlashGeometry::with_side(lights, n, capture.side, DType::F32, &Device::Cpu)?;
    let radiance = render_radiance_with(capture.brdf.as_ref(), maps, &geometry)?;
    Ok(encode_display(&(radiance * gain)?)?)
}

/// What `capture.json` records.
#[derive(Debug, Serialize)]
struct CaptureRecord<'a> {
    brdf: String,
    size: usize,
    fov_degrees: f64,
    /// Where the field of view came from (given, EXIF, default).
    fov_source: FovSource,
    side: f64,
    texel_size: f64,
    highlight: &'a HighlightUsed,
    gain: f64,
    /// The fitted vignetting strength, when it was fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    vignetting: Option<f64>,
    /// The fitted ambient radiance, in the flash's units, when it was fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    ambient: Option<f64>,
    steps: usize,
    loss_first: Option<f64>,
    loss_last: Option<f64>,
    l1_encoded: f64,
    seconds: f64,
    /// The refinement's coarse stage (size, steps, seconds), when it had one.
    #[serde(skip_serializing_if = "Option::is_none")]
    coarse: Option<CoarseStage>,
    prior: Option<PriorRecord>,
    /// The relief prior, when it gave the start.
    #[serde(skip_serializing_if = "Option::is_none")]
    relief_prior: Option<ReliefPriorRecord>,
    /// How the model was chosen (`--brdf auto`): every candidate's error, the tolerance.
    #[serde(skip_serializing_if = "Option::is_none")]
    selection: Option<serde_json::Value>,
    /// The maps held at values known from elsewhere, when any were.
    #[serde(skip_serializing_if = "<[String]>::is_empty")]
    known_maps: &'a [String],
}

/// What `capture.json` records of the generator prior.
#[derive(Debug, Serialize)]
struct PriorRecord {
    model: String,
    steps: usize,
    loss_first: Option<f64>,
    loss_last: Option<f64>,
    /// L1 of E's maps rendered under the photo's flash, before refinement, encoded domain.
    l1_encoded_before_refinement: f64,
    display_gain: f64,
    seconds: f64,
}

/// What `capture.json` records of the relief prior.
#[derive(Debug, Serialize)]
struct ReliefPriorRecord {
    model: String,
    /// L1 of the prior's maps rendered under the photo's flash (with `gain`), before
    /// refinement, encoded domain.
    l1_encoded_before_refinement: f64,
    gain: f64,
    seconds: f64,
}

/// The sheet's panels between the photo and the re-render (a generator prior's relighting and
/// E's maps, or the relief prior's maps, each rendered under the photo's flash) and what
/// `capture.json` records of the prior.
fn prior_panels(
    capture: &Capture,
) -> anyhow::Result<(Vec<Tensor>, Option<PriorRecord>, Option<ReliefPriorRecord>)> {
    let (_, _, n, _) = capture.photo.dims4()?;
    let (row, col) = capture.highlight.pixel;
    let photo_flash = Highlight::from_pixel_on(row, col, n, capture.side);
    let l1 = |image: &Tensor| -> anyhow::Result<f64> {
        Ok((image - &capture.photo)?
            .abs()?
            .mean_all()?
            .to_scalar::<f32>()? as f64)
    };
    if let Some(prior) = &capture.prior {
        let inversion = &prior.inversion;
        let gain = inversion.display_gain.powf(DISPLAY_GAMMA);
        let before = render_on_square(capture, &prior.maps, gain, &[photo_flash])?;
        let record = PriorRecord {
            model: prior.model.clone(),
            steps: inversion.losses.len(),
            loss_first: inversion.losses.first().copied(),
            loss_last: inversion.losses.last().copied(),
            l1_encoded_before_refinement: l1(&before)?,
            display_gain: inversion.display_gain,
            seconds: inversion.seconds,
        };
        return Ok((vec![inversion.relit.clone(), before], Some(record), None));
    }
    if let Some(relief) = &capture.relief_prior {
        let before = render_on_square(capture, &relief.maps, relief.gain, &[photo_flash])?;
        let record = ReliefPriorRecord {
            model: relief.model.clone(),
            l1_encoded_before_refinement: l1(&before)?,
            gain: relief.gain,
            seconds: relief.seconds,
        };
        return Ok((vec![before], None, Some(record)));
    }
    Ok((Vec::new(), None, None))
}

/// The renderer documents [`write_capture`] writes beside the texture set in `out/export/`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Exports {
    /// `export/material.gltf` (glTF 2.0 with `KHR_materials_specular`).
    pub gltf: bool,
    /// `export/material.mtlx` (MaterialX, `UsdPreviewSurface`).
    pub mtlx: bool,
}

/// Writes `out/material/` (the maps: PNG + EXR + material.json), `out/export/` (the
/// renderer textures of [`photomat_export::write_textures`]: base colour, roughness,
/// specular colour and, unless the normals are flat, a tangent-space `normal.png`, which a
/// height model derives from its height; plus the documents `exports` asks for),
/// `out/sheet.png` (photo | re-render | ×4 absolute error; with a prior, M's relighting of
/// the inverted material and the render of E's maps before refinement come between the
/// photo and the re-render), `out/relit.png` (the maps under the eight
/// [`new_flash_positions`], in a row) and `out/capture.json`. Returns the texture set.
pub fn write_capture(
    capture: &Capture,
    out: &Path,
    exports: Exports,
) -> anyhow::Result<photomat_export::TextureSet> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create '{}'", out.display()))?;
    let selection = capture
        .selection
        .as_ref()
        .map(serde_json::to_value)
        .transpose()?;
    save_maps(
        &out.join("material"),
        capture.brdf.as_ref(),
        &capture.maps,
        &SaveOptions {
            selection: selection.clone(),
            ..SaveOptions::default()
        },
    )?;
    let export = out.join("export");
    let textures = photomat_export::write_textures(&export, capture.brdf.as_ref(), &capture.maps)?;
    if exports.gltf {
        photomat_export::write_gltf(&export, "material", &textures)?;
    }
    if exports.mtlx {
        photomat_export::write_materialx(&export, "material", &textures)?;
    }
    let error = (&capture.render - &capture.photo)?.abs()?;
    let l1 = error.mean_all()?.to_scalar::<f32>()? as f64;
    // ×4: errors of a few % of the range must show.
    let mut panels = vec![capture.photo.clone()];
    let (prior_panels, prior_record, relief_prior_record) = prior_panels(capture)?;
    panels.extend(prior_panels);
    panels.push(capture.render.clone());
    panels.push((error * 4.0)?.clamp(0.0, 1.0)?);
    let row = panels
        .iter()
        .map(|t| PlanarImage::from_tensor(&t.squeeze(0)?))
        .collect::<photomat_core::Result<Vec<_>>>()?;
    write_png(&out.join("sheet.png"), &grid(&[row], 0.0)?, PngBits::Eight)?;
    let relit = relight(capture, &new_flash_positions(capture.side))?.clamp(0.0, 1.0)?;
    let relit = PlanarImage::batch_from_tensor(&relit)?;
    write_png(
        &out.join("relit.png"),
        &grid(&[relit], 0.0)?,
        PngBits::Eight,
    )?;
    let (_, _, n, _) = capture.photo.dims4()?;
    let record = CaptureRecord {
        brdf: capture.brdf.name(),
        size: n,
        fov_degrees: capture.fov.degrees,
        fov_source: capture.fov.source,
        side: capture.side,
        texel_size: capture.side / n as f64,
        highlight: &capture.highlight,
        gain: capture.gain,
        vignetting: capture.vignetting,
        ambient: capture.ambient,
        steps: capture.losses.len(),
        loss_first: capture.losses.first().copied(),
        loss_last: capture.losses.last().copied(),
        l1_encoded: l1,
        seconds: capture.seconds,
        coarse: capture.coarse,
        prior: prior_record,
        relief_prior: relief_prior_record,
        selection,
        known_maps: &capture.known_maps,
    };
    write_atomic(
        &out.join("capture.json"),
        &serde_json::to_vec_pretty(&record)?,
    )?;
    Ok(textures)
}
