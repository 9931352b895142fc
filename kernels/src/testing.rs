//! Deterministic inputs and comparisons for tests and benchmarks of these kernels and of the
//! crates built on them.
//!
//! candle's CPU random generator cannot be seeded, so reproducible inputs come from a
//! SplitMix64 stream (Steele, Lea & Flood, "Fast splittable pseudorandom number generators",
//! OOPSLA 2014), the same generator the rest of the workspace uses for its fixtures.

use candle_core::{DType, Device, Result, Shape, Tensor};

use crate::SplitMix64;

/// Values uniform in [−1, 1) from a SplitMix64 stream seeded by `seed`, converted to `dtype`.
///
/// # Shapes
/// Any shape; the values fill it in row-major order.
pub fn pseudo_random(
    shape: impl Into<Shape>,
    seed: u64,
    dtype: DType,
    device: &Device,
) -> Result<Tensor> {
    let shape = shape.into();
    let mut rng = SplitMix64(seed);
    let values: Vec<f64> = (0..shape.elem_count())
        .map(|_| rng.next_unit() * 2.0 - 1.0)
        .collect();
    Tensor::from_vec(values, shape, device)?.to_dtype(dtype)
}

/// max |a − b| over all elements, as f64 (NaN if either holds a NaN).
///
/// # Shapes
/// `a` and `b` of one shape (or broadcast-compatible as candle's `sub` allows).
pub fn max_abs_diff(a: &Tensor, b: &Tensor) -> Result<f64> {
    let d = (a - b)?
        .abs()?
        .flatten_all()?
        .to_dtype(DType::F64)?
        .to_vec1::<f64>()?;
    Ok(d.into_iter().fold(0.0, |m, v| {
        if v.is_nan() || m.is_nan() {
            f64::NAN
        } else {
            m.max(v)
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pseudo_random_is_reproducible_and_in_range() -> Result<()> {
        let a = pseudo_random((3, 5), 7, DType::F64, &Device::Cpu)?;
        let b = pseudo_random((3, 5), 7, DType::F64, &Device::Cpu)?;
        assert_eq!(max_abs_diff(&a, &b)?, 0.0);
        let c = pseudo_random((3, 5), 8, DType::F64, &Device::Cpu)?;
        assert!(
            max_abs_diff(&a, &c)? > 0.0,
            "another seed gives other values"
        );
        let v = a.flatten_all()?.to_vec1::<f64>()?;
        assert!(v.iter().all(|x| (-1.0..1.0).contains(x)));
        Ok(())
    }

    #[test]
    fn max_abs_diff_reports_nan() -> Result<()> {
        let a = Tensor::new(&[1.0f32, f32::NAN, 0.0], &Device::Cpu)?;
        let b = Tensor::new(&[1.0f32, 2.0, 5.0], &Device::Cpu)?;
        assert!(max_abs_diff(&a, &b)?.is_nan());
        Ok(())
    }
}
