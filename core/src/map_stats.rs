//! The spread of a material's maps: per map and channel the mean and standard deviation over
//! the texels, and for the shading normal (the innermost model's, so a height map's derived
//! normal counts) the spread of its angle from the mean normal. These are the numbers that
//! say whether a generated material has the variation of real ones: flat normals show as a
//! normal-angle spread near 0°, uniform roughness as a roughness std near 0
//! (docs/benchmarks/bundled-model.md, "Size generalisation, map spread and noise inputs").
//!
//! `photomat map-stats DIR…` prints them for material folders.

use candle_core::{DType, Tensor};
use serde::Serialize;

use crate::{Brdf, Error, MaterialMaps, Result};

/// Mean and standard deviation of one map's channels over the texels.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChannelSpread {
    /// Map name.
    pub name: String,
    /// Mean per channel.
    pub mean: Vec<f64>,
    /// Population standard deviation per channel.
    pub std: Vec<f64>,
}

/// The spread of one material's maps ([`map_spread`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapSpread {
    /// Every map of the model, in the model's order.
    pub maps: Vec<ChannelSpread>,
    /// Root-mean-square angle in degrees between each texel's shading normal and the mean
    /// normal; `None` when the innermost model has no `normal` map.
    pub normal_angle_rms_deg: Option<f64>,
    /// Angle in degrees between the mean normal and +z (a tilted material's overall slope).
    pub normal_mean_tilt_deg: Option<f64>,
}

/// The spread of `maps` of model `brdf` (one material: batch 1).
pub fn map_spread(brdf: &Brdf, maps: &MaterialMaps) -> Result<MapSpread> {
    let mut spreads = Vec::new();
    for spec in brdf.params() {
        let map = maps.get(spec.name)?;
        let (b, _, _, _) = map.dims4()?;
        if b != 1 {
            return Err(Error::Invalid(format!(
                "map spread is per material: map '{}' holds a batch of {b}",
                spec.name
            )));
        }
        let (mean, std) = channel_moments(map)?;
        spreads.push(ChannelSpread {
            name: spec.name.to_string(),
            mean,
            std,
        });
    }
    let shading = brdf.shading_maps(maps)?;
    let (rms, tilt) = if shading.contains("normal") {
        let (rms, tilt) = normal_spread(shading.get("normal")?)?;
        (Some(rms), Some(tilt))
    } else {
        (None, None)
    };
    Ok(MapSpread {
        maps: spreads,
        normal_angle_rms_deg: rms,
        normal_mean_tilt_deg: tilt,
    })
}

/// Per-channel mean and population std of a (1, C, H, W) map, in f64.
fn channel_moments(map: &Tensor) -> Result<(Vec<f64>, Vec<f64>)> {
    let flat = map.to_dtype(DType::F64)?.flatten_from(2)?.squeeze(0)?; // (C, N)
    let mean = flat.mean_keepdim(1)?;
    let var = flat.broadcast_sub(&mean)?.sqr()?.mean(1)?;
    let mean: Vec<f64> = mean.squeeze(1)?.to_vec1()?;
    let std: Vec<f64> = var.to_vec1::<f64>()?.into_iter().map(f64::sqrt).collect();
    Ok((mean, std))
}

/// RMS angle (degrees) of unit normals (1, 3, H, W) from their normalised mean, and the
/// mean's tilt from +z.
fn normal_spread(normal: &Tensor) -> Result<(f64, f64)> {
    let flat = normal.to_dtype(DType::F64)?.flatten_from(2)?.squeeze(0)?; // (3, N)
    let norm = flat.sqr()?.sum_keepdim(0)?.sqrt()?;
    let unit = flat.broadcast_div(&norm)?;
    let mean = unit.mean_keepdim(1)?;
    let mean = mean.broadcast_div(&mean.sqr()?.sum_keepdim(0)?.sqrt()?)?;
    // clamp: rounding can put a dot product of unit vectors a few ulps beyond ±1.
    let cos = unit.broadcast_mul(&mean)?.sum(0)?.clamp(-1.0, 1.0)?;
    let angles: Vec<f64> = cos.to_vec1::<f64>()?.into_iter().map(f64::acos).collect();
    let rms = (angles.iter().map(|a| a * a).sum::<f64>() / angles.len() as f64).sqrt();
    let z = mean.to_vec2::<f64>()?[2][0];
    Ok((rms.to_degrees(), z.clamp(-1.0, 1.0).acos().to_degrees()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn normal_spread_of_a_two_facet_surface_is_its_half_angle() {
        // Half the texels tilted +10° about y, half −10°: every normal is 10° from the mean.
        let t = 10f64.to_radians();
        let mut data = Vec::new();
        for (x, z) in [(t.sin(), t.cos()), (-t.sin(), t.cos())] {
            data.push(vec![x; 8]);
            data.push(vec![0.0; 8]);
            data.push(vec![z; 8]);
        }
        // Channels x, y, z over 16 texels: the first 8 one facet, the last 8 the other.
        let channel = |c: usize| [data[c].clone(), data[3 + c].clone()].concat();
        let values: Vec<f64> = (0..3).flat_map(channel).collect();
        let normal = Tensor::from_vec(values, (1, 3, 4, 4), &Device::Cpu).unwrap();
        let (rms, tilt) = normal_spread(&normal).unwrap();
        assert!((rms - 10.0).abs() < 1e-9, "{rms}");
        assert!(tilt.abs() < 1e-6, "{tilt}");
    }

    #[test]
    fn channel_moments_are_the_population_ones() {
        let map = Tensor::from_vec(vec![1f32, 3.0, 1.0, 3.0], (1, 1, 2, 2), &Device::Cpu).unwrap();
        let (mean, std) = channel_moments(&map).unwrap();
        assert_eq!((mean, std), (vec![2.0], vec![1.0]));
    }
}
