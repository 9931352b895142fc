//! Comparisons for tests and benchmarks of these kernels and of the crates built on them.
//!
//! Their deterministic inputs come from the workspace's seeded generator,
//! `photomat_core::rng::pseudo_random` (SplitMix64); this crate uses it in its tests and
//! benchmarks only, through a dev-dependency, so that the kernels do not depend on core.

use candle_core::{DType, Result, Tensor};

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
    use candle_core::Device;

    #[test]
    fn max_abs_diff_reports_nan() -> Result<()> {
        let a = Tensor::new(&[1.0f32, f32::NAN, 0.0], &Device::Cpu)?;
        let b = Tensor::new(&[1.0f32, 2.0, 5.0], &Device::Cpu)?;
        assert!(max_abs_diff(&a, &b)?.is_nan());
        Ok(())
    }

    #[test]
    fn max_abs_diff_is_the_largest_gap() -> Result<()> {
        let a = Tensor::new(&[1.0f32, -2.0, 0.5], &Device::Cpu)?;
        let b = Tensor::new(&[1.5f32, 1.0, 0.5], &Device::Cpu)?;
        assert_eq!(max_abs_diff(&a, &b)?, 3.0);
        assert_eq!(max_abs_diff(&a, &a)?, 0.0);
        Ok(())
    }
}
