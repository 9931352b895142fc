//! Hex-tiled maps of a sampled material: the maps repeated to 2×2 periods by Mikkelsen's
//! hex-tiling (JCGT 2022, `photomat_export::hextile`), one lattice per material, so the
//! repetition of any material, tileable or not, is hidden.

use anyhow::Context;
use candle_core::Device;
use photomat_core::image_io::PlanarImage;
use photomat_core::{Brdf, ColorSpace, MaterialMaps};
use photomat_export::hextile::{Content, HexTiling, hextile};

/// Hex-tile the maps of `brdf` to 2×2 periods with one lattice seeded by `seed`; the diffuse
/// albedo (display-encoded) guides the contrast-preserving weights.
///
/// # Shapes
/// maps (1, C, R, R) → (1, C, 2R, 2R).
pub fn hextile_maps(brdf: &Brdf, maps: &MaterialMaps, seed: u64) -> anyhow::Result<MaterialMaps> {
    let specs = brdf.params();
    let images = specs
        .iter()
        .map(|s| Ok(PlanarImage::from_tensor(maps.get(s.name)?)?))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let guide = specs
        .iter()
        .zip(&images)
        .find(|(s, i)| s.color_space == ColorSpace::Gamma22 && i.channels == 3)
        .map(|(s, i)| i.map(|v| s.color_space.to_stored(v)));
    let inputs: Vec<(&PlanarImage, Content)> = specs
        .iter()
        .zip(&images)
        .map(|(s, i)| {
            let content = match (s.color_space, i.channels) {
                (ColorSpace::UnitVector, 3) => Content::TangentNormal,
                _ => Content::Scalar,
            };
            (i, content)
        })
        .collect();
    let first = images.first().context("the model has no parameter maps")?;
    let (h, w) = (first.height, first.width);
    let tiling = HexTiling {
        seed,
        ..HexTiling::default()
    };
    let outputs = hextile(&tiling, &inputs, guide.as_ref(), 2 * h, 2 * w)?;
    let mut tiled = MaterialMaps::new();
    for (spec, image) in specs.iter().zip(outputs) {
        // Blends stay inside convex ranges; clamp the f32 rounding at the bounds.
        let image = image.map(|v| v.clamp(spec.range.0, spec.range.1));
        tiled.insert(spec.name, image.to_tensor(&Device::Cpu)?);
    }
    Ok(tiled)
}
