//! Display previews of parameter maps: each map as a 3-channel image in the colour space its
//! files use (albedos gamma-encoded, scalars as grey, normals as 0.5·n + 0.5), plus the
//! normal an adapter derives (e.g. from a height map), so people can look at what they got.
//! The map files' colour spaces are those of `docs/conventions.md`.

use crate::image_io::PlanarImage;
use crate::{ColorSpace, DifferentiableBrdf, MaterialMaps, Result};

/// (name, 3-channel preview in [0, 1]) for every map of the model, in parameter order,
/// followed by the shading normal when the model derives it. Maps must have batch 1.
pub fn map_previews(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
) -> Result<Vec<(String, PlanarImage)>> {
    let mut out = Vec::new();
    for spec in brdf.params() {
        out.push((
            spec.name.to_string(),
            preview(
                &PlanarImage::from_tensor(maps.get(spec.name)?)?,
                spec.color_space,
            ),
        ));
    }
    let shading = brdf.shading_maps(maps)?;
    if !maps.contains("normal")
        && let Ok(normal) = shading.get("normal")
    {
        out.insert(
            out.len().saturating_sub(1),
            (
                "normal".to_string(),
                preview(&PlanarImage::from_tensor(normal)?, ColorSpace::UnitVector),
            ),
        );
    }
    Ok(out)
}

/// A map as 3 display channels: 1 channel → grey, 3 → as is, via `space.to_stored`.
fn preview(map: &PlanarImage, space: ColorSpace) -> PlanarImage {
    let encoded = map.map(|v| space.to_stored(v));
    if encoded.channels == 3 {
        return encoded;
    }
    let plane = encoded.height * encoded.width;
    let first = encoded.data[..plane].to_vec();
    PlanarImage {
        channels: 3,
        height: encoded.height,
        width: encoded.width,
        data: [first.clone(), first.clone(), first].concat(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_maps_repeat_their_plane_and_colour_maps_are_encoded() {
        let grey = PlanarImage::new(1, 1, 2, vec![0.25, 0.5]).unwrap();
        let p = preview(&grey, ColorSpace::Linear);
        assert_eq!((p.channels, p.height, p.width), (3, 1, 2));
        assert_eq!(p.data, vec![0.25, 0.5, 0.25, 0.5, 0.25, 0.5]);
        let normal = PlanarImage::new(3, 1, 1, vec![0.0, 0.0, 1.0]).unwrap();
        let p = preview(&normal, ColorSpace::UnitVector);
        assert_eq!(p.data, vec![0.5, 0.5, 1.0]);
    }
}
