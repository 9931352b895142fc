//! StyleGAN2's modulated convolution (Karras et al. 2020, §2.2, eqs. 1–3) as one candle
//! custom op: input modulation, a convolution with a weight shared by the batch, and output
//! demodulation,
//!
//! ```text
//! y[b, o] = d[b, o] · conv(s[b, ·] ⊙ x[b, ·], W)[o]
//! ```
//!
//! with per-sample styles `s` (B, C_in) and demodulation coefficients `d` (B, C_out) computed
//! by the caller (`photomat_generator::modulated_conv`; StyleGAN2's non-fused path, the same
//! value as its grouped per-sample weights). Composed from candle ops this is two broadcast
//! multiplications around the convolution, and candle's backward turns each into five or more
//! passes over the full feature map (two products, a broadcast sum, and a zero-filled gradient
//! buffer plus an addition per operand); here the forward scales the input once, runs the
//! im2col + gemm convolution of [`crate::conv`] and scales its output rows in place, and the
//! backward is seven passes, the element-wise ones the fused per-plane ops of
//! [`crate::plane_ops`]:
//!
//! ```text
//! g' = d ⊙ dy,  gx = Gx(g', W)           (the convolution's input gradient)
//! dx = s ⊙ gx,  ds = Σ_hw x ⊙ gx,  dW = Gw(s ⊙ x, g'),  dd = Σ_hw dy ⊙ y / d
//! ```
//!
//! (`d > 0` always: it is an inverse square root). The backward is built from the
//! convolution's own differentiable ops and candle ops, so it can be differentiated again.
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices, and calls inside
//! [`crate::reference::with_reference_ops`], use [`modulated_conv2d_reference`].

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor, WithDType, bail};

use crate::alloc::output_buffer;
use crate::conv::{
    apply_input_grad, apply_weight_grad, conv2d_reference, fast_path, forward_into, needed,
};
use crate::conv_geometry::{Conv2dSpec, Geometry};
use crate::plane_ops::{map_planes, plane_dot, scale_planes, scale_planes_in_place};
use crate::storage::{contiguous, expect_shape};

/// `d ⊙ conv(s ⊙ x, W)` with `scales` = `s ‖ d` (B, C_in + C_out) when `demodulate`, `s`
/// alone (B, C_in) otherwise; stride, padding and padding mode from `spec`.
///
/// # Shapes
/// x (B, C_in, H, W), w (C_out, C_in, kh, kw), scales (B, C_in + C_out) or (B, C_in) →
/// (B, C_out, H_out, W_out) as [`crate::conv2d`].
pub fn modulated_conv2d(
    x: &Tensor,
    w: &Tensor,
    scales: &Tensor,
    demodulate: bool,
    spec: Conv2dSpec,
) -> Result<Tensor> {
    let g = Geometry::new(x.dims4()?, w.dims4()?, spec)?;
    let (b, ci, co) = (x.dim(0)?, x.dim(1)?, w.dim(0)?);
    let expected = if demodulate { (b, ci + co) } else { (b, ci) };
    if scales.dims2()? != expected {
        bail!(
            "modulated conv: scales of shape {:?}, expected {expected:?}",
            scales.dims()
        );
    }
    if !fast_path(x, w)? || !fast_path(x, scales)? || crate::reference::reference_ops() {
        return modulated_conv2d_reference(x, w, scales, demodulate, spec);
    }
    x.contiguous()?.apply_op3(
        &w.contiguous()?,
        &scales.contiguous()?,
        ModulatedConv { g, demodulate },
    )
}

/// The same operation from candle ops: broadcast products around [`conv2d_reference`].
///
/// # Shapes
/// As [`modulated_conv2d`].
pub fn modulated_conv2d_reference(
    input: &Tensor,
    weight: &Tensor,
    scales: &Tensor,
    demodulate: bool,
    spec: Conv2dSpec,
) -> Result<Tensor> {
    let (b, ci, _, _) = input.dims4()?;
    let co = weight.dim(0)?;
    let s = scales.narrow(1, 0, ci)?.reshape((b, ci, 1, 1))?;
    let y = conv2d_reference(&input.broadcast_mul(&s)?, weight, spec)?;
    if demodulate {
        y.broadcast_mul(&scales.narrow(1, ci, co)?.reshape((b, co, 1, 1))?)
    } else {
        Ok(y)
    }
}

/// (x, W, s ‖ d) → `d ⊙ conv(s ⊙ x, W)` (module docs).
struct ModulatedConv {
    g: Geometry,
    demodulate: bool,
}

impl ModulatedConv {
    fn run<T: WithDType>(&self, x: &[T], w: &[T], scales: &[T]) -> Vec<T> {
        let g = &self.g;
        let x_shape = g.x_shape();
        let [_, ci, h, wd] = x_shape.dims() else {
            unreachable!("NCHW geometry")
        };
        let y_shape = g.y_shape();
        let [_, co, ho, wo] = y_shape.dims() else {
            unreachable!("NCHW geometry")
        };
        let stride = if self.demodulate { ci + co } else { *ci };
        let xs = map_planes(
            x,
            h * wd,
            |i| scales[(i / ci) * stride + i % ci],
            |x, s| x * s,
        );
        // SAFETY: `forward_into` writes every element of `y`.
        let mut y = unsafe { output_buffer(y_shape.elem_count()) };
        forward_into(g, &xs, w, &mut y, crate::alloc::thread_count());
        if self.demodulate {
            scale_planes_in_place(&mut y, ho * wo, |i| scales[(i / co) * stride + ci + i % co]);
        }
        y
    }
}

impl CustomOp3 for ModulatedConv {
    fn name(&self) -> &'static str {
        "photomat-modulated-conv2d"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        weight: &CpuStorage,
        l_weight: &Layout,
        scales: &CpuStorage,
        l_scales: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let name = self.name();
        expect_shape(lx, &self.g.x_shape(), name, "input")?;
        expect_shape(l_weight, &self.g.w_shape(), name, "weight")?;
        let out = match (x, weight, scales) {
            (CpuStorage::F32(x), CpuStorage::F32(weight), CpuStorage::F32(scales)) => {
                let (x, weight) = (
                    contiguous(x, lx, name)?,
                    contiguous(weight, l_weight, name)?,
                );
                CpuStorage::F32(self.run(x, weight, contiguous(scales, l_scales, name)?))
            }
            (CpuStorage::F64(x), CpuStorage::F64(weight), CpuStorage::F64(scales)) => {
                let (x, weight) = (
                    contiguous(x, lx, name)?,
                    contiguous(weight, l_weight, name)?,
                );
                CpuStorage::F64(self.run(x, weight, contiguous(scales, l_scales, name)?))
            }
            _ => bail!("{name}: operands must all be f32 or all f64"),
        };
        Ok((out, self.g.y_shape()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        scales: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let ci = x.dim(1)?;
        let co = y.dim(1)?;
        let s = scales.narrow(1, 0, ci)?;
        let (gd, d) = if self.demodulate {
            let d = scales.narrow(1, ci, co)?;
            (scale_planes(grad, &d)?, Some(d))
        } else {
            (grad.clone(), None)
        };
        // The input gradient of the plain conv feeds both x's and the input scales' gradients;
        // each gradient is computed only when its operand is in the graph (`needed`: a frozen
        // generator's weights when a photo is inverted, say).
        let gx = if x.track_op() || scales.track_op() {
            Some(apply_input_grad(self.g, &gd, w)?)
        } else {
            None
        };
        let dx = needed(x, || scale_planes(gx.as_ref().expect("gx"), &s))?;
        let dw = needed(w, || apply_weight_grad(self.g, &scale_planes(x, &s)?, &gd))?;
        let dscales = needed(scales, || {
            let ds = plane_dot(gx.as_ref().expect("gx"), x)?;
            match &d {
                Some(d) => Tensor::cat(&[ds, plane_dot(grad, y)?.div(d)?], 1),
                None => Ok(ds),
            }
        })?;
        Ok((dx, dw, dscales))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::conv_geometry::PaddingMode;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    /// Value and gradients of L = Σ g ⊙ op(x, w, scales) w.r.t. the three operands.
    fn grads(
        op: fn(&Tensor, &Tensor, &Tensor, bool, Conv2dSpec) -> Result<Tensor>,
        vars: [&Var; 3],
        g: &Tensor,
        demodulate: bool,
        spec: Conv2dSpec,
    ) -> Result<Vec<Tensor>> {
        let [x, w, s] = vars;
        let y = op(
            x.as_tensor(),
            w.as_tensor(),
            s.as_tensor(),
            demodulate,
            spec,
        )?;
        let store = (&y * g)?.sum_all()?.backward()?;
        let mut out = vec![y];
        for v in vars {
            out.push(store.get(v.as_tensor()).cloned().expect("a gradient"));
        }
        Ok(out)
    }

    /// Each operand's gradient is computed only when it is in the graph: with the weights or
    /// the input constant, the others' gradients are the full backward's, and the constant
    /// gets none.
    #[test]
    fn constant_operands_get_no_gradient_and_the_others_the_full_ones() -> Result<()> {
        let dev = Device::Cpu;
        let spec = Conv2dSpec::zeros(1, 1);
        let x = Var::from_tensor(&pseudo_random((2, 3, 5, 6), 1, DType::F64, &dev)?)?;
        let w = Var::from_tensor(&pseudo_random((4, 3, 3, 3), 2, DType::F64, &dev)?)?;
        let s = Var::from_tensor(&((pseudo_random((2, 7), 3, DType::F64, &dev)? * 0.5)? + 1.0)?)?;
        let g = pseudo_random((2, 4, 5, 6), 4, DType::F64, &dev)?;
        let full = grads(modulated_conv2d, [&x, &w, &s], &g, true, spec)?;
        for frozen in [1, 0] {
            let t = |i: usize, v: &Var| {
                if i == frozen {
                    v.as_tensor().detach()
                } else {
                    v.as_tensor().clone()
                }
            };
            let (xt, wt) = (t(0, &x), t(1, &w));
            let y = modulated_conv2d(&xt, &wt, s.as_tensor(), true, spec)?;
            let store = (&y * &g)?.sum_all()?.backward()?;
            for (i, v) in [&x, &w, &s].into_iter().enumerate() {
                match store.get(v.as_tensor()) {
                    Some(d) => assert!(max_abs_diff(d, &full[i + 1])? < 1e-12, "operand {i}"),
                    None => assert_eq!(i, frozen, "operand {i} lost its gradient"),
                }
            }
        }
        Ok(())
    }

    #[test]
    fn modulated_conv_matches_the_candle_composition_and_its_gradients() -> Result<()> {
        let dev = Device::Cpu;
        // (B, C_in, H, W, C_out, k, padding, mode, demodulate): the synthesis layers' 3×3
        // "same" convs (zeros, circular) and the toFeature 1×1, odd sizes, batch 1, and a map
        // large enough for the rayon split.
        let cases = [
            (2, 3, 5, 6, 4, 3, 1, PaddingMode::Zeros, true),
            (1, 4, 7, 5, 3, 3, 1, PaddingMode::Circular, true),
            (3, 5, 4, 4, 2, 1, 0, PaddingMode::Zeros, false),
            (2, 16, 64, 64, 8, 3, 1, PaddingMode::Circular, true),
        ];
        for (i, (b, ci, h, w, co, k, p, mode, demod)) in cases.into_iter().enumerate() {
            let spec = Conv2dSpec {
                stride: 1,
                padding: p,
                mode,
            };
            let seed = 10 * i as u64;
            let x = Var::from_tensor(&pseudo_random((b, ci, h, w), seed, DType::F64, &dev)?)?;
            let wt = Var::from_tensor(&pseudo_random((co, ci, k, k), seed + 1, DType::F64, &dev)?)?;
            let n = if demod { ci + co } else { ci };
            // Scales in (0.5, 1.5): d > 0 as the caller's inverse square root guarantees.
            let s = (pseudo_random((b, n), seed + 2, DType::F64, &dev)? * 0.5)? + 1.0;
            let s = Var::from_tensor(&s?)?;
            let g = pseudo_random(
                (b, co, h + 2 * p + 1 - k, w + 2 * p + 1 - k),
                seed + 3,
                DType::F64,
                &dev,
            )?;
            let fast = grads(modulated_conv2d, [&x, &wt, &s], &g, demod, spec)?;
            let reference = grads(modulated_conv2d_reference, [&x, &wt, &s], &g, demod, spec)?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                assert_eq!(a.dims(), r.dims());
                // f64 sums of ≤ 16·9·4096 products of O(1) values in another order, scaled by
                // the map size: 1e-9 relative to the largest entry.
                let scale = r.abs()?.max_all()?.to_scalar::<f64>()?.max(1.0);
                assert!(
                    max_abs_diff(a, r)? < 1e-9 * scale,
                    "case {i}, output {j} (0: y, 1: dx, 2: dW, 3: dscales)"
                );
            }
            // f32: one forward, loose (ε = 6e-8, ≤ 144-term sums).
            let f32s = [x.as_tensor(), wt.as_tensor(), s.as_tensor()]
                .map(|t| t.to_dtype(DType::F32).expect("f32"));
            let y32 = modulated_conv2d(&f32s[0], &f32s[1], &f32s[2], demod, spec)?;
            assert!(max_abs_diff(&y32.to_dtype(DType::F64)?, &reference[0])? < 1e-4);
        }
        Ok(())
    }

    #[test]
    fn modulated_conv_rejects_scales_of_the_wrong_shape() -> Result<()> {
        let dev = Device::Cpu;
        let x = Tensor::zeros((2, 3, 4, 4), DType::F32, &dev)?;
        let w = Tensor::zeros((5, 3, 3, 3), DType::F32, &dev)?;
        let s = Tensor::zeros((2, 3), DType::F32, &dev)?;
        let spec = Conv2dSpec::zeros(1, 1);
        let err = modulated_conv2d(&x, &w, &s, true, spec).expect_err("needs s ‖ d");
        assert!(err.to_string().contains("expected (2, 8)"), "{err}");
        assert!(modulated_conv2d(&x, &w, &s, false, spec).is_ok());
        Ok(())
    }
}
