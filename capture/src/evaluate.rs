//! How good a capture is, against a material whose maps are known: the measures of the
//! validation protocol in docs/capture.md ("Validation"), after MatFusion's (Sartor and
//! Peers 2023): renders under flash positions the photo did not show, and per-map errors.
//!
//! One photo under one flash with unknown exposure and white balance fixes neither the
//! absolute brightness nor the colour balance of the maps, so both measures first take out one
//! per-channel scale, the colour scale (what a user corrects with a single colour picker): the
//! one that gives the fit's held-out renders the truth's channel means ([`channel_scale`]).

use std::path::Path;

use anyhow::Context;
use candle_core::{D, DType, Device, Tensor};
use photomat_core::image_io::read_exr;
use photomat_core::render::render_radiance_with;
use photomat_core::{Brdf, FlashGeometry, Highlight, MaterialMaps, encode_display};

/// Mean linear radiance the held-out renders are exposed to before encoding: an
/// auto-exposure's mid grey, so that the display-domain error means the same on a dark
/// material and a bright one.
pub const EXPOSED_MEAN: f64 = 0.18;

/// Linear radiance of `maps` of `brdf` under `lights` (flash positions on a centred square
/// of world side `side`, flash at height 1), on an N×N grid: (L, 3, N, N).
pub fn radiance_on_square(
    brdf: &Brdf,
    maps: &MaterialMaps,
    lights: &[Highlight],
    side: f64,
) -> anyhow::Result<Tensor> {
    let (_, n, _) = maps.batch_and_size()?;
    let geometry = FlashGeometry::with_side(lights, n, side, DType::F32, &Device::Cpu)?;
    Ok(render_radiance_with(brdf.as_ref(), maps, &geometry)?)
}

/// The held-out flashes of one photo of a Mitsuba capture set (`validation/run.sh
/// --capture-set`, validation/README.md: `photo` is its entry in `simulation.json`, whose
/// `held_out` list gives each flash position on the square and its render): the lights, and
/// the true material's linear renders under them, (L, 3, N, N).
pub fn read_held_out(
    set: &Path,
    photo: &serde_json::Value,
) -> anyhow::Result<(Vec<Highlight>, Tensor)> {
    let name = photo["photo"].as_str().unwrap_or("?");
    let held_out = photo["held_out"].as_array().with_context(|| {
        format!("{name}: no held_out; render the set with `validation/run.sh --capture-set`")
    })?;
    let mut lights = Vec::new();
    let mut renders = Vec::new();
    for h in held_out {
        let xy = h["highlight"]
            .as_array()
            .with_context(|| format!("{name}: a held-out flash without its highlight"))?;
        let coordinate = |i: usize| {
            xy.get(i)
                .and_then(|v| v.as_f64())
                .with_context(|| format!("{name}: a held-out highlight is not [x, y]"))
        };
        lights.push(Highlight::new(coordinate(0)?, coordinate(1)?));
        let render = h["render"]
            .as_str()
            .with_context(|| format!("{name}: a held-out flash without its render"))?;
        renders.push(read_exr(&set.join(render))?.to_tensor(&Device::Cpu)?);
    }
    Ok((lights, Tensor::cat(&renders, 0)?))
}

/// Per-channel means of a (B, 3, H, W) tensor over everything else: (1, 3, 1, 1).
fn channel_means(t: &Tensor) -> candle_core::Result<Tensor> {
    t.mean_keepdim(0)?
        .mean_keepdim(D::Minus1)?
        .mean_keepdim(D::Minus2)
}

/// The per-channel factor that gives `fitted` the channel means of `truth` (both
/// (B, 3, H, W)): (1, 3, 1, 1).
pub fn channel_scale(fitted: &Tensor, truth: &Tensor) -> candle_core::Result<Tensor> {
    // The floor keeps a black fit finite; its error is then the truth's own brightness.
    channel_means(truth)?.broadcast_div(&channel_means(fitted)?.maximum(1e-8)?)
}

/// Display-domain L1 of `fitted` against `truth`, both linear radiance (L, 3, N, N) under the
/// same lights: the truth is exposed to a mean of [`EXPOSED_MEAN`], the fit is given the
/// truth's per-channel means (module docs), both are display-encoded, and the mean absolute
/// difference over lights, channels and texels is returned.
pub fn held_out_l1(fitted: &Tensor, truth: &Tensor) -> anyhow::Result<f64> {
    let mean = truth.mean_all()?.to_scalar::<f32>()? as f64;
    anyhow::ensure!(
        mean > 0.0 && mean.is_finite(),
        "the truth's renders are black or not finite (mean {mean})"
    );
    let truth = (truth * (EXPOSED_MEAN / mean))?;
    let scaled = fitted.broadcast_mul(&channel_scale(fitted, &truth)?)?;
    let l1 = (encode_display(&scaled)? - encode_display(&truth)?)?
        .abs()?
        .mean_all()?;
    Ok(l1.to_scalar::<f32>()? as f64)
}

/// Per-map errors of fitted maps against known ones.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapErrors {
    /// RMSE of the diffuse albedo, after the colour scale (module docs).
    pub diffuse_rmse: f64,
    /// RMSE of the specular F0, after the same scale (one exposure scales both).
    pub specular_rmse: f64,
    /// RMSE of the perceptual roughness (α = r²).
    pub roughness_rmse: f64,
    /// Mean angle between the fitted and the true shading normals, in degrees.
    pub normal_degrees: f64,
}

/// Mean angle, in degrees, between two fields of unit normals (B, 3, H, W).
pub fn mean_normal_angle_degrees(a: &Tensor, b: &Tensor) -> candle_core::Result<f64> {
    let cosine = (a * b)?
        .sum_keepdim(1)?
        // Unit vectors' dot products may exceed 1 by rounding; acos needs [−1, 1].
        .clamp(-1.0, 1.0)?;
    let cosines = cosine.flatten_all()?.to_vec1::<f32>()?;
    let total: f64 = cosines
        .iter()
        .map(|c| (*c as f64).acos().to_degrees())
        .sum();
    Ok(total / cosines.len() as f64)
}

/// Compares the shading maps (`Brdf::shading_maps`: a height model's normals derived) of
/// `fitted` under `fitted_brdf` with those of `truth` under `truth_brdf`, the fitted diffuse
/// and specular multiplied by `scale` (1, 3, 1, 1) first: the colour scale that gives the
/// fit's renders the truth's channel means ([`channel_scale`] of the two renders under the
/// same lights), since radiance is linear in both maps. (A scale taken from the diffuse maps
/// alone blows up when a fit puts its light in the specular and leaves the diffuse near
/// black.) Both must have `diffuse`, `specular`, `roughness` and (after shading) `normal`
/// maps of the same size.
pub fn map_errors(
    fitted_brdf: &Brdf,
    fitted: &MaterialMaps,
    scale: &Tensor,
    truth_brdf: &Brdf,
    truth: &MaterialMaps,
) -> anyhow::Result<MapErrors> {
    let fitted = fitted_brdf.shading_maps(fitted)?;
    let truth = truth_brdf.shading_maps(truth)?;
    let rmse = |a: &Tensor, b: &Tensor| -> anyhow::Result<f64> {
        Ok(((a - b)?.sqr()?.mean_all()?.to_scalar::<f32>()? as f64).sqrt())
    };
    let scaled =
        |name: &str| -> anyhow::Result<Tensor> { Ok(fitted.get(name)?.broadcast_mul(scale)?) };
    let degrees = mean_normal_angle_degrees(fitted.get("normal")?, truth.get("normal")?)?;
    Ok(MapErrors {
        diffuse_rmse: rmse(&scaled("diffuse")?, truth.get("diffuse")?)?,
        specular_rmse: rmse(&scaled("specular")?, truth.get("specular")?)?,
        roughness_rmse: rmse(fitted.get("roughness")?, truth.get("roughness")?)?,
        normal_degrees: degrees,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use photomat_brdfs as _; // link the built-in BRDF plugins

    fn maps(diffuse: f32, normal: [f32; 3]) -> MaterialMaps {
        let n = 4;
        let full = |v: f32, c: usize| Tensor::full(v, (1, c, n, n), &Device::Cpu).unwrap();
        let len = normal.iter().map(|x| x * x).sum::<f32>().sqrt();
        let normal = Tensor::new(&normal.map(|x| x / len), &Device::Cpu)
            .unwrap()
            .reshape((1, 3, 1, 1))
            .unwrap()
            .broadcast_as((1, 3, n, n))
            .unwrap()
            .contiguous()
            .unwrap();
        MaterialMaps::new()
            .with("diffuse", full(diffuse, 3))
            .with("specular", full(0.04, 3))
            .with("roughness", full(0.5, 1))
            .with("normal", normal)
    }

    #[test]
    fn map_errors_ignore_a_colour_scale_and_measure_the_normal_angle() {
        let brdf = photomat_core::lookup("ggx").unwrap();
        let truth = maps(0.4, [0.0, 0.0, 1.0]);
        // Twice as bright, normals tilted by 10° about x.
        let tilt = 10f32.to_radians();
        let fitted = maps(0.8, [0.0, tilt.sin(), tilt.cos()]);
        // Renders twice as bright as the truth's get the scale ½.
        let scale = Tensor::full(0.5f32, (1, 3, 1, 1), &Device::Cpu).unwrap();
        let e = map_errors(&brdf, &fitted, &scale, &brdf, &truth).unwrap();
        assert!(e.diffuse_rmse < 1e-6, "{e:?}");
        // The same scale makes the fitted F0 0.02.
        assert!((e.specular_rmse - 0.02).abs() < 1e-6, "{e:?}");
        assert!(e.roughness_rmse < 1e-6, "{e:?}");
        assert!((e.normal_degrees - 10.0).abs() < 1e-3, "{e:?}");
    }

    #[test]
    fn held_out_l1_is_zero_for_a_scaled_copy_and_grows_with_a_pattern_error() {
        let truth = Tensor::rand(0.01f32, 0.2, (2, 3, 8, 8), &Device::Cpu).unwrap();
        let scaled = (&truth * 3.0).unwrap();
        assert!(held_out_l1(&scaled, &truth).unwrap() < 1e-6);
        let flat = truth.ones_like().unwrap();
        assert!(held_out_l1(&flat, &truth).unwrap() > 0.05);
        assert!(held_out_l1(&flat, &truth.zeros_like().unwrap()).is_err());
    }
}
