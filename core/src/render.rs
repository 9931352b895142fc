//! The differentiable collocated-flash renderer (`docs/conventions.md`, "Geometry and
//! radiometry").
//!
//! Per texel: `radiance = I · f(ω, ω)·cos θ · / d²` with `I = π`, ω the direction to the flash
//! and d the distance to it; the display encoding is `clamp(x, 0, 1)^(1/2.2)`. Everything is
//! candle tensor algebra, so gradients reach every map (and, through adapters, the maps they
//! are derived from).

use candle_core::Tensor;

use crate::brdf::DifferentiableBrdf;
use crate::flash::{FLASH_INTENSITY, FlashGeometry, Highlight};
use crate::maps::MaterialMaps;
use crate::texel_ops::scale_texels;
use crate::{Error, Result};

/// Lower clamp before the 1/2.2 power: the slope of `x^(1/2.2)` is infinite at 0, at 1e-6 it
/// is ≈ 850 (finite gradients for black texels) while the encoded value 0.0019 stays below half
/// an 8-bit step.
pub const ENCODE_FLOOR: f64 = 1e-6;

/// Display gamma of photos and renders.
pub const DISPLAY_GAMMA: f64 = 2.2;

/// Linear radiance of `maps` under flashes at `highlights`.
///
/// # Shapes
/// maps: (B, C, R, R) with B = `highlights.len()`, or B = 1 to render one material under
/// every highlight; result (highlights.len(), 3, R, R).
pub fn render_radiance(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    highlights: &[Highlight],
) -> Result<Tensor> {
    let name = brdf.name();
    maps.validate_shapes(&name, brdf.params())?;
    let (batch, h, w) = maps.batch_and_size()?;
    if h != w {
        return Err(Error::InvalidMaps {
            model: name,
            reason: format!("the flash renderer needs square maps, got {h}×{w}"),
        });
    }
    if batch != 1 && batch != highlights.len() {
        return Err(Error::Invalid(format!(
            "{} highlight(s) for a batch of {batch} materials: give one per material, \
             or a single material",
            highlights.len()
        )));
    }
    let first = maps
        .iter()
        .next()
        .map(|(_, t)| t)
        .expect("validated non-empty");
    let geometry = FlashGeometry::new(highlights, h, first.dtype(), first.device())?;
    render_radiance_with(brdf, maps, &geometry)
}

/// Linear radiance under a prebuilt [`FlashGeometry`] (e.g. [`FlashGeometry::with_side`] for a
/// whole photo spanning side 2). Maps (B|1, C, R, R) must match the geometry's R×R grid.
/// Adapters that differentiate over texels (`height`) assume the unit square: on a square of
/// side s, divide their `scale` by s.
pub fn render_radiance_with(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    geometry: &FlashGeometry,
) -> Result<Tensor> {
    let (_, h, w) = maps.batch_and_size()?;
    let (_, _, gh, gw) = geometry.omega.dims4()?;
    if (h, w) != (gh, gw) {
        return Err(Error::Invalid(format!(
            "maps of {h}×{w} texels under a flash geometry of {gh}×{gw}"
        )));
    }
    let omega = &geometry.omega;
    let f_cos = brdf.eval(omega, omega, maps)?;
    Ok((scale_texels(&f_cos, &geometry.inv_dist2)? * FLASH_INTENSITY)?)
}

/// Display-encoded render in [0, 1] under a prebuilt [`FlashGeometry`]: [`encode_display`] of
/// [`render_radiance_with`]. Build the geometry once (e.g. [`crate::LightSet::geometry`]) and
/// hand its ω to the relighting MLP as well, so both see the same lights; [`render`] equals
/// this with the geometry built from its highlights.
///
/// # Shapes
/// maps (B|1, C, R, R), geometry over R×R with B lights → (B, 3, R, R).
pub fn render_with(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    geometry: &FlashGeometry,
) -> Result<Tensor> {
    maps.validate_shapes(&brdf.name(), brdf.params())?;
    let (batch, _, _) = maps.batch_and_size()?;
    let lights = geometry.omega.dim(0)?;
    if batch != 1 && batch != lights {
        return Err(Error::Invalid(format!(
            "{lights} light(s) for a batch of {batch} materials: give one per material, \
             or a single material"
        )));
    }
    encode_display(&render_radiance_with(brdf, maps, geometry)?)
}

/// `clamp(x, 0, 1)^(1/2.2)` with the [`ENCODE_FLOOR`] lower clamp: linear → display values.
pub fn encode_display(radiance: &Tensor) -> Result<Tensor> {
    Ok(radiance
        .clamp(ENCODE_FLOOR, 1.0)?
        .powf(1.0 / DISPLAY_GAMMA)?)
}

/// Display-encoded render in [0, 1]: [`encode_display`] of [`render_radiance`].
pub fn render(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    highlights: &[Highlight],
) -> Result<Tensor> {
    encode_display(&render_radiance(brdf, maps, highlights)?)
}

/// Encoded [0, 1] image → the networks' [−1, 1] range (`2x − 1`).
pub fn to_network_range(encoded: &Tensor) -> Result<Tensor> {
    Ok(encoded.affine(2.0, -1.0)?)
}
