//! The renders a sampled material is judged by: M's relighting of its neural material and the
//! analytic render of its maps under the same lights, in groups of lights that bound the
//! memory, and their per-light L1 (over the whole material, or over the texels within a
//! photo's reach of their flash, [`photomat_core::FlashGeometry::within_photo_reach`]).

use candle_core::{DType, Tensor};
use photomat_core::{Brdf, FlashGeometry, MaterialMaps, render_with};
use photomat_generator::GanModel;

use super::LIGHT_BATCH_TEXELS;

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
pub(crate) fn mean(values: &[f64]) -> f64 {
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
