//! Only the maps a material requires: a map that barely varies becomes a constant, a colour
//! map that is nearly grey becomes one channel, as long as the material still renders within a
//! tolerance of what it rendered before (`docs/trade.md`, "Simplified maps").
//!
//! [`simplify`] tries, map by map, the cheaper form of each parameter map of a model:
//! - **constant**: every texel set to the map's mean (per channel; for unit vectors the mean
//!   direction, normalised). The folder then stores one value per channel in `material.json`
//!   and no file ([`crate::map_files::SaveOptions::compact`]); renderers take it as a factor
//!   (glTF `roughnessFactor`, a MaterialX input value);
//! - **grey** (3-channel maps that are not unit vectors): every texel set to its Rec. 709
//!   luminance in all three channels, stored as a one-channel file.
//!
//! A form is kept when every one of the caller's errors of the whole material (typically L1s
//! of its renders against a reference, M's renders when sampling or the photo when capturing)
//! stays within its own `error_before · (1 + tolerance)`. Several errors let the caller guard
//! several things at once: the L1 of linear radiance is dominated by the highlight, the L1 of
//! display-encoded images by the texture away from it, and a simplification must keep both.
//! Every accepted form is judged together with those accepted before it, so the bounds hold
//! for the final maps, not per map. Maps with more
//! channels are tried first (they save the most bytes); a map's constant form before its grey
//! one.
//!
//! [`constant_value`] and [`is_grey`] recognise the simplified forms exactly (bitwise equal
//! texels), which is how the folder writer and the exporters decide to store a value instead
//! of an image: a map that is not exactly constant keeps its file.
//!
//! # Shapes
//! Maps (1, C, R, R), one material, as [`crate::map_files::save_maps`] takes them.

use candle_core::Tensor;

use crate::brdf::DifferentiableBrdf;
use crate::image_io::PlanarImage;
use crate::maps::MaterialMaps;
use crate::param::{ColorSpace, ParamSpec};
use crate::{Error, Result};

/// Rec. 709 luminance weights (linear rgb). They sum to 1, so a luminance stays inside any
/// range that holds the three channels.
pub const LUMINANCE: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// Shortest mean unit vector that still names a direction: below it the map's normals point
/// every way (a mean of unit vectors shorter than 1e-3 comes from cancellation, not a tilt).
const MIN_MEAN_DIRECTION: f32 = 1e-3;

/// One accepted simplification.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimplifyStep {
    /// The map's name.
    pub map: String,
    /// `constant` or `grey`.
    pub form: MapForm,
    /// The material's errors once this step (and the ones before it) is applied.
    pub error: Vec<f64>,
}

/// The cheaper form a map took.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MapForm {
    /// One value per channel.
    Constant(Vec<f32>),
    /// Three equal channels, stored as one.
    Grey,
}

/// What [`simplify`] did to a material, as recorded in its `material.json` and in a sample
/// run's summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimplifyRecord {
    /// The relative tolerance the steps were judged against.
    pub tolerance: f64,
    /// What each error measures, in the order of the error lists.
    pub metrics: Vec<String>,
    /// The material's errors before and after.
    pub error_before: Vec<f64>,
    /// See [`Self::error_before`].
    pub error_after: Vec<f64>,
    /// The accepted steps, in order.
    pub steps: Vec<SimplifyStep>,
    /// Bytes of the material folder (maps and manifest, without this record) before and after.
    pub bytes_before: u64,
    /// See [`Self::bytes_before`].
    pub bytes_after: u64,
}

/// What [`simplify`] did to a material.
#[derive(Debug, Clone)]
pub struct Simplified {
    /// The maps with every accepted step applied.
    pub maps: MaterialMaps,
    /// The accepted steps, in order.
    pub steps: Vec<SimplifyStep>,
    /// The caller's errors of the maps as they were.
    pub error_before: Vec<f64>,
    /// The caller's errors of [`Self::maps`].
    pub error_after: Vec<f64>,
    /// The relative tolerance the steps were judged against.
    pub tolerance: f64,
}

impl Simplified {
    /// The record of this simplification, with the names of its errors and the folder sizes
    /// before and after.
    pub fn record(&self, metrics: &[&str], bytes_before: u64, bytes_after: u64) -> SimplifyRecord {
        SimplifyRecord {
            tolerance: self.tolerance,
            metrics: metrics.iter().map(|m| m.to_string()).collect(),
            error_before: self.error_before.clone(),
            error_after: self.error_after.clone(),
            steps: self.steps.clone(),
            bytes_before,
            bytes_after,
        }
    }
}

/// Simplifies `maps` of `brdf` (module docs): each candidate form is kept when
/// `error_of(candidate maps)[i] ≤ error_of(maps)[i] · (1 + tolerance)` for every i.
///
/// `error_of` is called once for the maps as they are and once per candidate (at most two per
/// map), and must return the same number of errors (at least one) each time. An error that is
/// not finite for the maps as they are is refused: there is nothing to stay within.
pub fn simplify<E: From<Error>>(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    tolerance: f64,
    mut error_of: impl FnMut(&MaterialMaps) -> std::result::Result<Vec<f64>, E>,
) -> std::result::Result<Simplified, E> {
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(Error::Invalid(format!(
            "the simplification tolerance must be a finite number ≥ 0, got {tolerance}"
        ))
        .into());
    }
    maps.validate(&brdf.name(), brdf.params())?;
    let error_before = error_of(maps)?;
    if error_before.is_empty() || error_before.iter().any(|e| !e.is_finite()) {
        return Err(Error::Invalid(format!(
            "cannot simplify: the material's errors are {error_before:?}"
        ))
        .into());
    }
    let bound: Vec<f64> = error_before.iter().map(|e| e * (1.0 + tolerance)).collect();
    let mut specs: Vec<&ParamSpec> = brdf.params().iter().collect();
    specs.sort_by_key(|s| std::cmp::Reverse(s.channels));
    let mut current = maps.clone();
    let mut steps = Vec::new();
    let mut error_after = error_before.clone();
    for spec in specs {
        let map = current.get(spec.name)?.clone();
        if constant_value(&map)?.is_some() {
            continue;
        }
        let mut forms = Vec::new();
        if let Some(value) = mean_value(&map, spec)? {
            forms.push((
                MapForm::Constant(value.clone()),
                constant_like(&map, &value)?,
            ));
        }
        if spec.channels == 3 && spec.color_space != ColorSpace::UnitVector && !is_grey(&map)? {
            forms.push((MapForm::Grey, grey_of(&map)?));
        }
        for (form, candidate) in forms {
            let mut trial = current.clone();
            trial.insert(spec.name, candidate);
            let error = error_of(&trial)?;
            if error.len() != bound.len() {
                return Err(Error::Invalid(format!(
                    "the simplifier's error function returned {} errors, then {}",
                    bound.len(),
                    error.len()
                ))
                .into());
            }
            if error.iter().zip(&bound).all(|(e, b)| e <= b) {
                current = trial;
                error_after = error.clone();
                steps.push(SimplifyStep {
                    map: spec.name.to_string(),
                    form,
                    error,
                });
                break;
            }
        }
    }
    Ok(Simplified {
        maps: current,
        steps,
        error_before,
        error_after,
        tolerance,
    })
}

/// The value of every channel when every texel of `map` is exactly (bitwise) the same,
/// `None` otherwise.
///
/// # Shapes
/// (1, C, R, R) → C values.
pub fn constant_value(map: &Tensor) -> Result<Option<Vec<f32>>> {
    let image = PlanarImage::from_tensor(map)?;
    let plane = image.texels();
    Ok((0..image.channels)
        .map(|c| {
            let channel = &image.data[c * plane..(c + 1) * plane];
            let first = channel[0];
            channel
                .iter()
                .all(|v| v.to_bits() == first.to_bits())
                .then_some(first)
        })
        .collect())
}

/// Whether `map` has three exactly (bitwise) equal channels.
///
/// # Shapes
/// (1, C, R, R); false unless C = 3.
pub fn is_grey(map: &Tensor) -> Result<bool> {
    let image = PlanarImage::from_tensor(map)?;
    let plane = image.texels();
    Ok(image.channels == 3
        && (0..plane).all(|t| {
            let r = image.data[t].to_bits();
            r == image.data[plane + t].to_bits() && r == image.data[2 * plane + t].to_bits()
        }))
}

/// The constant a map would take: its per-channel mean, normalised for unit vectors (`None`
/// when their mean has no direction).
fn mean_value(map: &Tensor, spec: &ParamSpec) -> Result<Option<Vec<f32>>> {
    let image = PlanarImage::from_tensor(map)?;
    let plane = image.texels();
    let mut value: Vec<f32> = (0..image.channels)
        .map(|c| {
            let sum: f64 = image.data[c * plane..(c + 1) * plane]
                .iter()
                .map(|&v| f64::from(v))
                .sum();
            (sum / plane as f64) as f32
        })
        .collect();
    if spec.color_space == ColorSpace::UnitVector {
        let length = value.iter().map(|v| v * v).sum::<f32>().sqrt();
        if length < MIN_MEAN_DIRECTION {
            return Ok(None);
        }
        value.iter_mut().for_each(|v| *v /= length);
    }
    // A mean of in-range texels is in range; rounding to f32 may step a ulp outside.
    let (lo, hi) = spec.range;
    Ok(Some(value.into_iter().map(|v| v.clamp(lo, hi)).collect()))
}

/// A map of `map`'s shape, dtype and device holding `value` in every texel.
fn constant_like(map: &Tensor, value: &[f32]) -> Result<Tensor> {
    let (_, c, h, w) = map.dims4()?;
    let plane = h * w;
    let data: Vec<f32> = value
        .iter()
        .flat_map(|&v| std::iter::repeat_n(v, plane))
        .collect();
    Ok(PlanarImage::new(c, h, w, data)?
        .to_tensor(map.device())?
        .to_dtype(map.dtype())?)
}

/// The luminance of a 3-channel `map` in all three channels.
fn grey_of(map: &Tensor) -> Result<Tensor> {
    let image = PlanarImage::from_tensor(map)?;
    let plane = image.texels();
    let luminance: Vec<f32> = (0..plane)
        .map(|t| {
            (0..3)
                .map(|c| LUMINANCE[c] * image.data[c * plane + t])
                .sum()
        })
        .collect();
    let data = [luminance.clone(), luminance.clone(), luminance].concat();
    Ok(PlanarImage::new(3, image.height, image.width, data)?
        .to_tensor(map.device())?
        .to_dtype(map.dtype())?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    fn image_tensor(channels: usize, side: usize, f: impl Fn(usize, usize) -> f32) -> Tensor {
        let plane = side * side;
        let data = (0..channels * plane)
            .map(|i| f(i / plane, i % plane))
            .collect();
        PlanarImage::new(channels, side, side, data)
            .unwrap()
            .to_tensor(&Device::Cpu)
            .unwrap()
    }

    #[test]
    fn exact_forms_are_recognised_and_near_ones_are_not() {
        let flat = image_tensor(3, 4, |c, _| 0.1 * c as f32);
        assert_eq!(constant_value(&flat).unwrap(), Some(vec![0.0, 0.1, 0.2]));
        let nearly = image_tensor(1, 4, |_, t| if t == 5 { 0.5 + 1e-7 } else { 0.5 });
        assert_eq!(constant_value(&nearly).unwrap(), None);
        let grey = image_tensor(3, 4, |_, t| t as f32 / 16.0);
        assert!(is_grey(&grey).unwrap());
        assert!(!is_grey(&flat).unwrap());
        assert!(!is_grey(&image_tensor(1, 4, |_, _| 0.3)).unwrap());
    }

    #[test]
    fn grey_is_the_luminance_and_stays_in_range() {
        let map = image_tensor(3, 2, |c, _| [1.0, 0.0, 1.0][c]);
        let grey = PlanarImage::from_tensor(&grey_of(&map).unwrap()).unwrap();
        let expect = LUMINANCE[0] + LUMINANCE[2];
        assert!(grey.data.iter().all(|&v| (v - expect).abs() < 1e-7));
    }
}
