//! ×2 bilinear upsampling with a periodic (wrap-around) boundary, as two matrix products.
//!
//! The estimator's decoder (paper §4 "Implementation", UNet of Ronneberger et al. 2015)
//! doubles the resolution with bilinear interpolation before each skip concatenation.
//!
//! # Convention
//! `align_corners = False` (PyTorch's default, OpenGL texel centres): output texel `o` of a
//! side of length 2N samples the input at `s = (o + ½)/2 − ½`, i.e. texel `2i` at `i − ¼` and
//! texel `2i + 1` at `i + ¼`, so along each axis
//!
//! ```text
//! out[2i]     = ¾·x[i] + ¼·x[(i − 1) mod N]
//! out[2i + 1] = ¾·x[i] + ¼·x[(i + 1) mod N]
//! ```
//!
//! and the 2-D result is the separable product of the two axes. Neighbours wrap around
//! (periodic boundary) instead of being clamped: the upsampled image is one period of the
//! bilinear interpolation of the infinitely tiled input, so `upsample(roll(x, s)) =
//! roll(upsample(x), 2s)` exactly. Away from the border this equals PyTorch's
//! `F.interpolate(scale_factor=2, mode='bilinear', align_corners=False)`; at the border PyTorch
//! clamps. The reference implementation uses `align_corners=True`, whose sampling positions
//! depend on the distance to the border: it cannot commute with `roll` and would break the
//! tileable estimator, hence the deviation (recorded in the crate docs).
//!
//! # Implementation
//! Each axis is a constant sparse matrix `U` (2N × N, two non-zeros per row,
//! [`periodic_upsample_axis`]) applied by `photomat_kernels::fir::separable`: the compressed-row
//! passes that also run StyleGAN2's FIR filters, two multiply-adds per output element and axis,
//! differentiable to any order (the backward of a pass is the pass of `Uᵀ`). Under
//! `--candle-reference`, on other devices and dtypes the same matrices run densely as
//! `U_H · X · U_Wᵀ` by candle `matmul`s (candle 0.11 has no backward for its own bilinear
//! upsampling: `docs/candle-notes.md`, "Gradients that are wrong or missing, with no error").

use candle_core::{DType, Device, Result, Tensor, bail};
use photomat_kernels::fir::{AxisMatrix, separable};

/// Weight of the nearer input texel (distance ¼ texel) in ×2 bilinear interpolation.
const NEAR: f64 = 0.75;
/// Weight of the farther input texel (distance ¾ texel).
const FAR: f64 = 0.25;

/// The periodic ×2 bilinear interpolation matrix `U` of one axis: `out = U · x`.
///
/// Row `2i` holds ¾ at column `i` and ¼ at column `(i − 1) mod n`; row `2i + 1` holds ¾ at `i`
/// and ¼ at `(i + 1) mod n` (for n = 1 both land on column 0, which sums to 1). Every row sums
/// to 1, so constants are preserved exactly (¼ and ¾ are exact in every float format).
///
/// # Shapes
/// 2n × n; `n` ≥ 1.
pub fn periodic_upsample_axis(n: usize) -> Result<AxisMatrix> {
    upsample_axis(n, |i, odd| if odd { (i + 1) % n } else { (i + n - 1) % n })
}

/// [`periodic_upsample_axis`] for an axis that does not wrap around (a photo's): the
/// neighbour beyond an edge is the edge texel itself, so the outermost outputs repeat it.
///
/// # Shapes
/// 2n × n; `n` ≥ 1.
pub fn clamped_upsample_axis(n: usize) -> Result<AxisMatrix> {
    upsample_axis(n, |i, odd| {
        if odd {
            (i + 1).min(n - 1)
        } else {
            i.saturating_sub(1)
        }
    })
}

/// The ×2 bilinear matrix whose row `2i + odd` holds ¾ at column `i` and ¼ at the farther
/// neighbour `far(i, odd)`.
fn upsample_axis(n: usize, far: impl Fn(usize, bool) -> usize) -> Result<AxisMatrix> {
    if n == 0 {
        bail!("cannot upsample an axis of length 0");
    }
    let rows: Vec<Vec<(usize, f64)>> = (0..2 * n)
        .map(|o| {
            let (i, odd) = (o / 2, o % 2 == 1);
            vec![(i, NEAR), (far(i, odd), FAR)]
        })
        .collect();
    AxisMatrix::from_rows(n, &rows)
}

/// [`periodic_upsample_axis`] as a dense tensor.
///
/// # Shapes
/// (2n, n), `dtype` on `device`; `n` ≥ 1.
pub fn periodic_upsample_matrix(n: usize, dtype: DType, device: &Device) -> Result<Tensor> {
    periodic_upsample_axis(n)?.to_dense(dtype, device)
}

/// Periodic ×2 bilinear upsampling (`align_corners = False`, wrap-around; see the module docs).
///
/// # Shapes
/// (B, C, H, W) → (B, C, 2H, 2W); H, W ≥ 1. Any float dtype.
pub fn upsample2x_periodic(x: &Tensor) -> Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    separable(x, &periodic_upsample_axis(h)?, &periodic_upsample_axis(w)?)
}

/// ×2 bilinear upsampling of an image that does not wrap around (a photo's): the border texels
/// repeated beyond the edge ([`clamped_upsample_axis`]).
///
/// # Shapes
/// (B, C, H, W) → (B, C, 2H, 2W); H, W ≥ 1. Any float dtype.
pub fn upsample2x_clamped(x: &Tensor) -> Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    separable(x, &clamped_upsample_axis(h)?, &clamped_upsample_axis(w)?)
}

#[cfg(test)]
mod tests {
    use candle_core::Var;

    use super::*;
    use crate::test_util::{max_abs_diff, pseudo_random};

    /// Closed-form 1-D weights: (input offset, weight) pairs of output texel `o`.
    fn taps(o: usize) -> [(isize, f64); 2] {
        if o.is_multiple_of(2) {
            [(0, 0.75), (-1, 0.25)]
        } else {
            [(0, 0.75), (1, 0.25)]
        }
    }

    /// Element-by-element reference on one (h, w) plane with wrap-around indices.
    fn reference(x: &[f64], h: usize, w: usize) -> Vec<f64> {
        let mut out = vec![0.0; 4 * h * w];
        for r in 0..2 * h {
            for c in 0..2 * w {
                let mut acc = 0.0;
                for (di, wi) in taps(r) {
                    for (dj, wj) in taps(c) {
                        let i = ((r / 2) as isize + di).rem_euclid(h as isize) as usize;
                        let j = ((c / 2) as isize + dj).rem_euclid(w as isize) as usize;
                        acc += wi * wj * x[i * w + j];
                    }
                }
                out[r * 2 * w + c] = acc;
            }
        }
        out
    }

    #[test]
    fn upsample_of_a_constant_is_the_constant() -> Result<()> {
        let x = Tensor::full(0.3f32, (2, 3, 4, 8), &Device::Cpu)?;
        let y = upsample2x_periodic(&x)?;
        assert_eq!(y.dims4()?, (2, 3, 8, 16));
        // Rows of U sum to exactly 1, but each of the two f32 products rounds 0.3·¾ and the
        // sum: at most 4 half-ulps of 0.3 (≈ 6e-8) in all.
        assert!(max_abs_diff(&y, &Tensor::full(0.3f32, (2, 3, 8, 16), &Device::Cpu)?)? < 1e-7);
        Ok(())
    }

    #[test]
    fn upsample_of_a_ramp_wraps_around() -> Result<()> {
        // One row 0, 1, 2, 3 (a sawtooth when tiled): hand-computed ¼/¾ weights, the first and
        // last outputs mixing with the opposite edge (3 and 0).
        let x = Tensor::new(&[0f32, 1., 2., 3.], &Device::Cpu)?.reshape((1, 1, 1, 4))?;
        let y = upsample2x_periodic(&x)?;
        let expected = [0.75f32, 0.25, 0.75, 1.25, 1.75, 2.25, 2.75, 2.25];
        for row in 0..2 {
            // A 1-texel-tall input: both output rows equal the row (¾ + ¼ of itself).
            assert_eq!(y.get(0)?.get(0)?.get(row)?.to_vec1::<f32>()?, expected);
        }
        Ok(())
    }

    #[test]
    fn upsample_matches_closed_form_bilinear_weights() -> Result<()> {
        // Non-square, batch and channels > 1: catches swapped axes and plane mix-ups.
        let (b, c, h, w) = (2, 3, 4, 6);
        let x = pseudo_random((b, c, h, w), 21, DType::F64, &Device::Cpu)?;
        let y = upsample2x_periodic(&x)?;
        assert_eq!(y.dims4()?, (b, c, 2 * h, 2 * w));
        for bi in 0..b {
            for ci in 0..c {
                let plane = x.get(bi)?.get(ci)?.flatten_all()?.to_vec1::<f64>()?;
                let got = y.get(bi)?.get(ci)?.flatten_all()?.to_vec1::<f64>()?;
                for (g, e) in got.iter().zip(reference(&plane, h, w)) {
                    // 4-term sums in f64, different association than the matmul's.
                    assert!((g - e).abs() < 1e-14, "{g} vs {e}");
                }
            }
        }
        Ok(())
    }

    #[test]
    fn upsample_commutes_with_roll() -> Result<()> {
        let x = pseudo_random((1, 2, 8, 4), 4, DType::F32, &Device::Cpu)?;
        let a = upsample2x_periodic(&x.roll(3, 2)?.roll(-1, 3)?)?;
        let b = upsample2x_periodic(&x)?.roll(6, 2)?.roll(-2, 3)?;
        // Identical weights on identical values; only the summation order of the two taps can
        // differ (the dense row visits columns in index order, and wrapped taps swap places):
        // ≤ 1 ulp per axis of values in [−1, 1], i.e. < 2.5e-7.
        assert!(max_abs_diff(&a, &b)? < 2.5e-7);
        Ok(())
    }

    #[test]
    fn upsample_gradient_matches_finite_differences() -> Result<()> {
        // L = Σ g ⊙ up(x) is linear in x, so central differences are exact up to rounding:
        // |error| ≲ ε_f64·|L|/δ ≈ 1e-16·10/1e-3 = 1e-12, far under the 1e-9 tolerance.
        let (h, w) = (3, 5);
        let x0 = pseudo_random((1, 2, h, w), 8, DType::F64, &Device::Cpu)?;
        let g = pseudo_random((1, 2, 2 * h, 2 * w), 9, DType::F64, &Device::Cpu)?;
        let loss_of = |x: &Tensor| -> Result<f64> {
            (upsample2x_periodic(x)? * &g)?
                .sum_all()?
                .to_scalar::<f64>()
        };
        let x = Var::from_tensor(&x0)?;
        let grads = (upsample2x_periodic(x.as_tensor())? * &g)?
            .sum_all()?
            .backward()?;
        let analytic = grads
            .get(x.as_tensor())
            .expect("x is a variable")
            .flatten_all()?
            .to_vec1::<f64>()?;
        let base = x0.flatten_all()?.to_vec1::<f64>()?;
        let delta = 1e-3;
        for (k, a) in analytic.iter().enumerate() {
            let mut plus = base.clone();
            let mut minus = base.clone();
            plus[k] += delta;
            minus[k] -= delta;
            let lp = loss_of(&Tensor::from_vec(plus, x0.shape(), &Device::Cpu)?)?;
            let lm = loss_of(&Tensor::from_vec(minus, x0.shape(), &Device::Cpu)?)?;
            let fd = (lp - lm) / (2.0 * delta);
            assert!(
                (a - fd).abs() < 1e-9,
                "texel {k}: backward {a} vs finite difference {fd}"
            );
        }
        // And the adjoint in closed form: ∂L/∂x = U_Hᵀ · G · U_W per plane.
        let u_h = periodic_upsample_matrix(h, DType::F64, &Device::Cpu)?;
        let u_w = periodic_upsample_matrix(w, DType::F64, &Device::Cpu)?;
        let adjoint = u_h
            .t()?
            .broadcast_left(2)?
            .matmul(&g.squeeze(0)?.matmul(&u_w.broadcast_left(2)?)?)?;
        let adjoint = adjoint.flatten_all()?.to_vec1::<f64>()?;
        for (a, b) in analytic.iter().zip(&adjoint) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        Ok(())
    }

    #[test]
    fn upsample_matrix_rows_sum_to_one_even_for_tiny_axes() -> Result<()> {
        for n in 1..4 {
            let u = periodic_upsample_matrix(n, DType::F64, &Device::Cpu)?;
            assert_eq!(u.dims2()?, (2 * n, n));
            assert_eq!(u.sum(1)?.to_vec1::<f64>()?, vec![1.0; 2 * n]);
        }
        assert!(periodic_upsample_matrix(0, DType::F32, &Device::Cpu).is_err());
        Ok(())
    }
}
