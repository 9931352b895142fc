//! Unpadded strided `conv2d` with a faster CPU backward pass.
//!
//! candle 0.11 differentiates `conv2d` exactly, but on the CPU the input gradient goes through
//! a direct-loop `conv_transpose2d`: on the estimator's layers it ran at 0.2–0.8 GFLOP/s on
//! the 2-core build machine (e.g. 3×3, 96→32, 32², batch 4: 274 ms against 32 ms for the
//! forward conv2d), making E's backward pass ≈ 10× slower than its forward (`docs/candle-notes.md`,
//! "Speed", measured the same path at ≈ 11 GFLOP/s on a larger layer). Here the input gradient is
//! computed with `conv2d` itself (im2col + gemm), the standard polyphase decomposition of a
//! transposed convolution:
//!
//! For `y[i] = Σ_a x[s·i + a]·w[a]` (stride s, k taps, k a multiple of s), input position
//! `p = s·m + r` (phase r < s) receives `∂L/∂x[s·m + r] = Σ_t g[m − t]·w[s·t + r]`, a *full*
//! convolution of the output gradient g with the k/s-tap sub-kernel `w[r], w[r + s], …`;
//! i.e. a correlation of g zero-padded by k/s − 1 with that sub-kernel flipped. In 2-D there
//! are s² phases, computed by one convolution whose output channels hold every phase, then
//! interleaved. For s = 1 this is the familiar "correlate with the flipped, transposed
//! kernel".
//!
//! The weight gradient uses candle's own formula (a `conv2d` of the input with the output
//! gradient as kernel, dilated by the stride). The forward result is candle's `conv2d`; the
//! gradient is attached through a [`CustomOp3`] that copies the forward result and supplies
//! the backward above. Only first derivatives are provided (E needs no double backward).

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor, bail};

/// `x.conv2d(w, padding 0, stride, dilation 1, groups 1)` with the backward pass of the
/// module docs. Falls back to candle's own backward where the decomposition does not apply
/// (kernel not a multiple of the stride, or a non-CPU device, whose backends have their own
/// transposed convolutions).
///
/// # Shapes
/// x (B, C_in, H, W), w (C_out, C_in, k, k) → (B, C_out, (H − k)/s + 1, (W − k)/s + 1).
pub fn conv2d_fast_backward(x: &Tensor, w: &Tensor, stride: usize) -> Result<Tensor> {
    let (_b, _c, _h, _w) = x.dims4()?;
    let (_co, _ci, kh, kw) = w.dims4()?;
    let polyphase = x.device().is_cpu() && kh == kw && stride > 0 && kh % stride == 0;
    if !polyphase || !(x.track_op() || w.track_op()) {
        // candle's own conv2d: its backward where needed, no graph for constant inputs.
        return x.conv2d(w, 0, stride, 1, 1);
    }
    let y = x.detach().conv2d(&w.detach(), 0, stride, 1, 1)?;
    x.apply_op3(w, &y, ConvBackward { stride })
}

/// Carries the forward result unchanged; its backward is [`conv2d_fast_backward`]'s.
struct ConvBackward {
    stride: usize,
}

impl CustomOp3 for ConvBackward {
    fn name(&self) -> &'static str {
        "conv2d-polyphase-backward"
    }

    /// Copy of the third argument (the forward result computed by candle's `conv2d`).
    fn cpu_fwd(
        &self,
        _x: &CpuStorage,
        _lx: &Layout,
        _w: &CpuStorage,
        _lw: &Layout,
        y: &CpuStorage,
        ly: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let Some((start, end)) = ly.contiguous_offsets() else {
            bail!("conv2d-polyphase-backward: the forward result must be contiguous");
        };
        let copy = match y {
            CpuStorage::F16(v) => CpuStorage::F16(v[start..end].to_vec()),
            CpuStorage::F32(v) => CpuStorage::F32(v[start..end].to_vec()),
            CpuStorage::F64(v) => CpuStorage::F64(v[start..end].to_vec()),
            other => bail!(
                "conv2d-polyphase-backward: unsupported dtype {:?}",
                other.dtype()
            ),
        };
        Ok((copy, ly.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let grad_x = input_gradient(grad, w, self.stride, x.dims4()?)?;
        let grad_w = weight_gradient(x, grad, self.stride, w.dims4()?)?;
        Ok((Some(grad_x), Some(grad_w), None))
    }
}

/// ∂L/∂x of an unpadded conv by polyphase decomposition (module docs), all s² phases in one
/// `conv2d`: their flipped sub-kernels are stacked along the output channels.
///
/// # Shapes
/// grad (B, C_out, Hg, Wg), w (C_out, C_in, k, k) → (B, C_in, H, W). The phases cover
/// s·(Hg + k/s − 1) rows, the input height when (H − k) is a multiple of s; otherwise the
/// trailing rows (read by no output) get zero gradient.
fn input_gradient(
    grad: &Tensor,
    w: &Tensor,
    stride: usize,
    (b, ci, h, wd): (usize, usize, usize, usize),
) -> Result<Tensor> {
    let (co, _, k, _) = w.dims4()?;
    let (s, taps) = (stride, k / stride);
    // Phase (ry, rx), flipped tap (a, c) reads kernel entry (s·(taps−1−a) + ry, s·(taps−1−c) + rx):
    // a permutation of the k² entries, gathered with one index_select.
    let mut idx = Vec::with_capacity(k * k);
    for ry in 0..s {
        for rx in 0..s {
            for a in 0..taps {
                for c in 0..taps {
                    let (p, q) = (s * (taps - 1 - a) + ry, s * (taps - 1 - c) + rx);
                    idx.push((p * k + q) as u32);
                }
            }
        }
    }
    let idx = Tensor::new(idx.as_slice(), w.device())?;
    let kernels = w
        .reshape((co * ci, k * k))?
        .index_select(&idx, 1)?
        .reshape((co, ci, s * s, taps, taps))?
        .permute((2, 1, 0, 3, 4))? // (s², C_in, C_out, taps, taps)
        .contiguous()?
        .reshape((s * s * ci, co, taps, taps))?;
    let phases = grad.conv2d(&kernels, taps - 1, 1, 1, 1)?; // (B, s²·C_in, H', W')
    let (_, _, hp, wp) = phases.dims4()?;
    let full = if s == 1 {
        phases
    } else {
        phases
            .reshape((b, s, s, ci, hp, wp))?
            .permute((0, 3, 4, 1, 5, 2))? // (B, C_in, H', ry, W', rx)
            .contiguous()?
            .reshape((b, ci, s * hp, s * wp))?
    };
    if s * hp == h && s * wp == wd {
        Ok(full)
    } else {
        full.pad_with_zeros(2, 0, h - s * hp)?
            .pad_with_zeros(3, 0, wd - s * wp)
    }
}

/// ∂L/∂w exactly as candle's conv2d backward computes it: the input (channels as batch)
/// correlated with the output gradient (batch as channels), dilated by the stride.
///
/// # Shapes
/// x (B, C_in, H, W), grad (B, C_out, Hg, Wg) → (C_out, C_in, k, k).
fn weight_gradient(
    x: &Tensor,
    grad: &Tensor,
    stride: usize,
    (_co, _ci, kh, kw): (usize, usize, usize, usize),
) -> Result<Tensor> {
    let g = x
        .transpose(0, 1)?
        .conv2d(&grad.transpose(0, 1)?, 0, 1, stride, 1)?
        .transpose(0, 1)?;
    let (_, _, gh, gw) = g.dims4()?;
    if gh > kh || gw > kw {
        g.narrow(2, 0, kh)?.narrow(3, 0, kw)
    } else {
        Ok(g)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    /// Gradients of L = Σ g ⊙ conv(x, w) through both backward passes.
    fn grads(fast: bool, x: &Var, w: &Var, g: &Tensor, stride: usize) -> Result<(Tensor, Tensor)> {
        let y = if fast {
            conv2d_fast_backward(x.as_tensor(), w.as_tensor(), stride)?
        } else {
            x.as_tensor().conv2d(w.as_tensor(), 0, stride, 1, 1)?
        };
        let store = (y * g)?.sum_all()?.backward()?;
        let get = |v: &Var| {
            store
                .get(v.as_tensor())
                .cloned()
                .expect("variable has a gradient")
        };
        Ok((get(x), get(w)))
    }

    #[test]
    fn fast_backward_matches_candle_conv2d_backward() -> Result<()> {
        // candle's conv2d backward is exact (`docs/candle-notes.md`, checked against PyTorch and
        // finite differences); the polyphase pass must agree to f64 rounding.
        let dev = Device::Cpu;
        // (4, 2, 11, 9): (H − k) odd, so the last input row and column are never read.
        let cases = [
            (3, 1, 7, 9),
            (4, 2, 10, 8),
            (4, 2, 11, 9),
            (1, 1, 4, 5),
            (4, 4, 8, 12),
            (3, 1, 3, 3),
        ];
        for (k, s, h, w) in cases {
            let x = Var::from_tensor(&pseudo_random((2, 3, h, w), 1, DType::F64, &dev)?)?;
            let wt = Var::from_tensor(&pseudo_random((4, 3, k, k), 2, DType::F64, &dev)?)?;
            let y = x.as_tensor().conv2d(wt.as_tensor(), 0, s, 1, 1)?;
            let g = pseudo_random(y.shape(), 3, DType::F64, &dev)?;
            let fast_y = conv2d_fast_backward(x.as_tensor(), wt.as_tensor(), s)?;
            assert_eq!(max_abs_diff(&fast_y, &y)?, 0.0, "forward k{k} s{s}");
            let (fx, fw) = grads(true, &x, &wt, &g, s)?;
            let (rx, rw) = grads(false, &x, &wt, &g, s)?;
            assert_eq!(fx.dims(), rx.dims());
            // Sums of ≤ 4·9·2 products of O(1) values in another order: ≪ 1e-12.
            assert!(max_abs_diff(&fx, &rx)? < 1e-12, "input gradient k{k} s{s}");
            assert!(max_abs_diff(&fw, &rw)? < 1e-12, "weight gradient k{k} s{s}");
        }
        Ok(())
    }

    #[test]
    fn fast_backward_input_gradient_matches_finite_differences() -> Result<()> {
        // Independent of candle's conv backward: L is linear in x, so central differences
        // are exact up to rounding (≈ 1e-16·|L|/δ ≈ 1e-12 for δ = 1e-3).
        let dev = Device::Cpu;
        let (k, s) = (4, 2);
        let x0 = pseudo_random((1, 2, 6, 6), 4, DType::F64, &dev)?;
        let wt = pseudo_random((3, 2, k, k), 5, DType::F64, &dev)?;
        let g = pseudo_random((1, 3, 2, 2), 6, DType::F64, &dev)?;
        let x = Var::from_tensor(&x0)?;
        let store = (conv2d_fast_backward(x.as_tensor(), &wt, s)? * &g)?
            .sum_all()?
            .backward()?;
        let analytic = store
            .get(x.as_tensor())
            .expect("gradient")
            .flatten_all()?
            .to_vec1::<f64>()?;
        let base = x0.flatten_all()?.to_vec1::<f64>()?;
        let loss = |v: Vec<f64>| -> Result<f64> {
            let x = Tensor::from_vec(v, x0.shape(), &dev)?;
            (x.conv2d(&wt, 0, s, 1, 1)? * &g)?
                .sum_all()?
                .to_scalar::<f64>()
        };
        let delta = 1e-3;
        for (i, a) in analytic.iter().enumerate() {
            let (mut p, mut m) = (base.clone(), base.clone());
            p[i] += delta;
            m[i] -= delta;
            let fd = (loss(p)? - loss(m)?) / (2.0 * delta);
            assert!((a - fd).abs() < 1e-9, "x[{i}]: {a} vs {fd}");
        }
        Ok(())
    }

    #[test]
    fn fast_backward_falls_back_where_phases_do_not_apply() -> Result<()> {
        // 3×3 stride 2: k is not a multiple of s, candle's own backward is used; values and
        // gradients must still be those of conv2d.
        let dev = Device::Cpu;
        let x = Var::from_tensor(&pseudo_random((1, 2, 7, 7), 9, DType::F64, &dev)?)?;
        let w = Var::from_tensor(&pseudo_random((3, 2, 3, 3), 10, DType::F64, &dev)?)?;
        let g = pseudo_random((1, 3, 3, 3), 11, DType::F64, &dev)?;
        let (fx, fw) = grads(true, &x, &w, &g, 2)?;
        let (rx, rw) = grads(false, &x, &w, &g, 2)?;
        assert_eq!(max_abs_diff(&fx, &rx)?, 0.0);
        assert_eq!(max_abs_diff(&fw, &rw)?, 0.0);
        Ok(())
    }

    #[test]
    fn fast_backward_is_skipped_without_gradients() -> Result<()> {
        let dev = Device::Cpu;
        let x = pseudo_random((1, 2, 6, 6), 7, DType::F32, &dev)?;
        let w = pseudo_random((3, 2, 3, 3), 8, DType::F32, &dev)?;
        let y = conv2d_fast_backward(&x, &w, 1)?;
        assert!(!y.track_op(), "constant inputs build no graph");
        assert_eq!(max_abs_diff(&y, &x.conv2d(&w, 0, 1, 1, 1)?)?, 0.0);
        Ok(())
    }
}
