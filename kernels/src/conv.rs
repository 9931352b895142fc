//! 2-D convolution on the CPU as candle custom ops, with zero or circular padding, whose
//! forward, input gradient and weight gradient are each a custom op whose own backward is
//! built from the other two — so the op is differentiable to any order (R1 in the
//! discriminator, `docs/neural-models.md`, "GAN training").
//!
//! The three ops are bilinear and close under differentiation. Writing `F(x, W)` (forward),
//! `Gx(dy, W)` (input gradient) and `Gw(x, dy)` (weight gradient), the adjoint identities
//! `⟨dy, F(x, W)⟩ = ⟨x, Gx(dy, W)⟩ = ⟨W, Gw(x, dy)⟩` give every backward:
//! `F: (Gx(g, W), Gw(x, g))`, `Gx(dy, W): (F(g, W), Gw(g, dy))`, `Gw(x, dy): (Gx(dy, g), F(x, g))`.
//!
//! Each map runs on one of two kernel families, chosen here per call:
//!
//! - im2col + `gemm` ([`crate::im2col`]), the lowering to matrix products;
//! - on CPUs with a vector family ([`crate::simd`]: AVX-512, or AVX2 + FMA), f32
//!   convolutions other than pointwise ones run on the direct kernels instead, which read a
//!   padded copy of the input in place rather than `col(x)` (`docs/benchmarks/conv-kernels.md`, "A direct
//!   convolution kernel"; `docs/benchmarks/cpu-kernels.md`): forwards whose output rows hold
//!   at least one vector (16 texels on AVX-512, 8 on AVX2) and the input gradients of such
//!   stride-1 convolutions ([`crate::direct_conv`]), strided input gradients phase by phase
//!   ([`crate::strided_input_grad`]), and weight gradients over at least 1024 output texels
//!   ([`crate::direct_weight_grad`]). Pointwise convolutions (whose `col(x)` is `x` itself),
//!   narrower layers and f64 stay on im2col. The family is the calling thread's
//!   ([`crate::simd::SimdFamily::active`]), read once per op.
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices and dtypes fall back to
//! [`conv2d_reference`] (candle's `conv2d`, circular padding by `narrow` + `cat`), as does
//! every call inside [`crate::reference::with_reference_ops`].

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, DType, Layout, Result, Shape, Tensor, WithDType, bail};

use crate::alloc::output_buffer;
use crate::conv_geometry::Geometry;
pub use crate::conv_geometry::{Conv2dSpec, PaddingMode};
use crate::simd::SimdFamily;
use crate::storage::{contiguous, expect_shape};
use crate::{direct_conv, direct_weight_grad, im2col, strided_input_grad};

/// Convolution (cross-correlation, as in candle and PyTorch) of `x` with `w`.
///
/// # Shapes
/// x (B, C_in, H, W), w (C_out, C_in, kh, kw) → (B, C_out, H_out, W_out) with
/// `H_out = (H + 2·padding − kh)/stride + 1` (floor), likewise `W_out`.
///
/// Circular padding must not exceed the image (`padding ≤ min(H, W)`), as in PyTorch.
pub fn conv2d(x: &Tensor, w: &Tensor, spec: Conv2dSpec) -> Result<Tensor> {
    let g = Geometry::new(x.dims4()?, w.dims4()?, spec)?;
    if !fast_path(x, w)? || crate::reference::reference_ops() {
        return conv2d_reference(x, w, spec);
    }
    apply_forward(g, x, w)
}

/// The same convolution from candle's own ops: circular padding by `narrow` + `cat`, then
/// candle's `conv2d` (zero padding by its `padding` argument). Exact and differentiable to any
/// order (`docs/candle-notes.md`, "Gradients that were checked and are right"); the reference the
/// tests compare against and the path for devices and dtypes [`conv2d`] does not handle.
///
/// # Shapes
/// As [`conv2d`].
pub fn conv2d_reference(x: &Tensor, w: &Tensor, spec: Conv2dSpec) -> Result<Tensor> {
    Geometry::new(x.dims4()?, w.dims4()?, spec)?;
    match spec.mode {
        PaddingMode::Zeros => x.conv2d(w, spec.padding, spec.stride, 1, 1),
        PaddingMode::Circular => {
            let p = spec.padding;
            let wrap = |t: &Tensor, dim: usize| -> Result<Tensor> {
                if p == 0 {
                    return Ok(t.clone());
                }
                let n = t.dim(dim)?;
                Tensor::cat(&[&t.narrow(dim, n - p, p)?, t, &t.narrow(dim, 0, p)?], dim)
            };
            wrap(&wrap(x, 2)?, 3)?.conv2d(w, 0, spec.stride, 1, 1)
        }
    }
}

/// Whether both operands can take the custom-op path (CPU, same dtype, f32 or f64).
pub(crate) fn fast_path(a: &Tensor, b: &Tensor) -> Result<bool> {
    if a.dtype() != b.dtype() {
        bail!("conv2d: dtypes differ ({:?}, {:?})", a.dtype(), b.dtype());
    }
    Ok(a.device().is_cpu() && b.device().is_cpu() && matches!(a.dtype(), DType::F32 | DType::F64))
}

/// The family of the direct kernels for a call on this thread: [`SimdFamily::active`]
/// unless the environment variable `PHOTOMAT_NO_DIRECT_CONV` is set, which sends every
/// convolution to im2col + `gemm` (same-binary A/B measurements, `docs/benchmarks/conv-kernels.md`; read
/// once per process).
fn direct_family() -> SimdFamily {
    static ENABLED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if *ENABLED.get_or_init(|| std::env::var_os("PHOTOMAT_NO_DIRECT_CONV").is_none()) {
        SimdFamily::active()
    } else {
        SimdFamily::Scalar
    }
}

/// The three operands as f32 slices, with the direct kernels' family, when `T` is f32 and a
/// vector family may run.
#[allow(clippy::type_complexity)]
fn as_f32<'a, T: WithDType>(
    a: &'a [T],
    b: &'a [T],
    out: &'a mut [T],
) -> Option<((&'a [f32], &'a [f32], &'a mut [f32]), SimdFamily)> {
    let family = direct_family();
    if T::DTYPE != DType::F32 || family == SimdFamily::Scalar {
        return None;
    }
    // SAFETY: `T` is f32 (its DTYPE says so), so the slices' elements are f32.
    let slices = unsafe {
        (
            std::slice::from_raw_parts(a.as_ptr() as *const f32, a.len()),
            std::slice::from_raw_parts(b.as_ptr() as *const f32, b.len()),
            std::slice::from_raw_parts_mut(out.as_mut_ptr() as *mut f32, out.len()),
        )
    };
    Some((slices, family))
}

/// Forward: writes every element of `y` (B·C_out·H_out·W_out), on the direct kernels when
/// they take the geometry, else on im2col + `gemm`. Reads the kernel family of the calling
/// thread ([`SimdFamily::active`]).
pub(crate) fn forward_into<T: WithDType>(
    g: &Geometry,
    x: &[T],
    w: &[T],
    y: &mut [T],
    threads: usize,
) {
    if let Some(((x, w, y), family)) = as_f32(x, w, y)
        && direct_conv::supports_forward(g, family)
    {
        direct_conv::forward(g, x, w, y, (threads, family));
        return;
    }
    im2col::forward(g, x, w, y, threads);
}

/// Input gradient: writes every element of `dx` (B·C_in·H·W) from `dy` and `w`.
fn input_grad_into<T: WithDType>(g: &Geometry, dy: &[T], w: &[T], dx: &mut [T], threads: usize) {
    if let Some(((dy, w, dx), family)) = as_f32(dy, w, dx) {
        if direct_conv::supports_input_grad(g, family) {
            direct_conv::input_grad(g, dy, w, dx, (threads, family));
            return;
        }
        if strided_input_grad::supports(g, family) {
            strided_input_grad::input_grad(g, dy, w, dx, (threads, family));
            return;
        }
    }
    im2col::input_grad(g, dy, w, dx, threads);
}

/// Weight gradient: writes every element of `dw` (C_out·C_in·kh·kw) from `x` and `dy`.
fn weight_grad_into<T: WithDType>(g: &Geometry, x: &[T], dy: &[T], dw: &mut [T], threads: usize) {
    if let Some(((x, dy, dw), family)) = as_f32(x, dy, dw)
        && direct_weight_grad::prefers(g, family)
    {
        direct_weight_grad::weight_grad(g, x, dy, dw, (threads, family));
        return;
    }
    im2col::weight_grad(g, x, dy, dw, threads);
}

/// Which of the three bilinear maps an op computes.
#[derive(Clone, Copy)]
enum Kind {
    Forward,
    InputGrad,
    WeightGrad,
}

/// Runs one of the three kernels on CPU storages, allocating its output uninitialised
/// (`output_buffer`): each `_into` function writes all of it.
fn run(
    kind: Kind,
    g: &Geometry,
    name: &str,
    (a, la): (&CpuStorage, &Layout),
    (b, lb): (&CpuStorage, &Layout),
) -> Result<(CpuStorage, Shape)> {
    let (sa, sb, out) = match kind {
        Kind::Forward => (g.x_shape(), g.w_shape(), g.y_shape()),
        Kind::InputGrad => (g.y_shape(), g.w_shape(), g.x_shape()),
        Kind::WeightGrad => (g.x_shape(), g.y_shape(), g.w_shape()),
    };
    expect_shape(la, &sa, name, "first operand")?;
    expect_shape(lb, &sb, name, "second operand")?;
    let threads = crate::alloc::thread_count();
    fn go<T: WithDType>(
        kind: Kind,
        g: &Geometry,
        a: &[T],
        b: &[T],
        len: usize,
        threads: usize,
    ) -> Vec<T> {
        // SAFETY: each of the three `_into` functions writes every element of its output.
        let mut out = unsafe { output_buffer(len) };
        match kind {
            Kind::Forward => forward_into(g, a, b, &mut out, threads),
            Kind::InputGrad => input_grad_into(g, a, b, &mut out, threads),
            Kind::WeightGrad => weight_grad_into(g, a, b, &mut out, threads),
        }
        out
    }
    let n = out.elem_count();
    let storage = match (a, b) {
        (CpuStorage::F32(a), CpuStorage::F32(b)) => {
            let (a, b) = (contiguous(a, la, name)?, contiguous(b, lb, name)?);
            CpuStorage::F32(go(kind, g, a, b, n, threads))
        }
        (CpuStorage::F64(a), CpuStorage::F64(b)) => {
            let (a, b) = (contiguous(a, la, name)?, contiguous(b, lb, name)?);
            CpuStorage::F64(go(kind, g, a, b, n, threads))
        }
        (a, b) => bail!(
            "{name}: unsupported dtypes {:?}, {:?}",
            a.dtype(),
            b.dtype()
        ),
    };
    Ok((storage, out))
}

/// `F(x, w)`: the forward convolution.
struct Forward(Geometry);
/// `Gx(dy, w)`: the input gradient.
struct InputGrad(Geometry);
/// `Gw(x, dy)`: the weight gradient.
struct WeightGrad(Geometry);

fn apply_forward(g: Geometry, x: &Tensor, w: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&w.contiguous()?, Forward(g))
}

pub(crate) fn apply_input_grad(g: Geometry, dy: &Tensor, w: &Tensor) -> Result<Tensor> {
    dy.contiguous()?.apply_op2(&w.contiguous()?, InputGrad(g))
}

pub(crate) fn apply_weight_grad(g: Geometry, x: &Tensor, dy: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&dy.contiguous()?, WeightGrad(g))
}

/// The gradient with respect to `operand`, computed only when the backward pass will use it:
/// candle asks a custom op for both operands' gradients, and drops those of operands outside
/// the graph (a constant input such as the estimator's neural material, or a frozen layer's
/// weights), so each of those would be a convolution's worth of work thrown away.
pub(crate) fn needed(
    operand: &Tensor,
    grad: impl FnOnce() -> Result<Tensor>,
) -> Result<Option<Tensor>> {
    operand.track_op().then(grad).transpose()
}

impl CustomOp2 for Forward {
    fn name(&self) -> &'static str {
        "photomat-conv2d"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        w: &CpuStorage,
        lw: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        run(Kind::Forward, &self.0, self.name(), (x, lx), (w, lw))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        g: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((
            needed(x, || apply_input_grad(self.0, g, w))?,
            needed(w, || apply_weight_grad(self.0, x, g))?,
        ))
    }
}

impl CustomOp2 for InputGrad {
    fn name(&self) -> &'static str {
        "photomat-conv2d-input-grad"
    }

    fn cpu_fwd(
        &self,
        dy: &CpuStorage,
        ldy: &Layout,
        w: &CpuStorage,
        lw: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        run(Kind::InputGrad, &self.0, self.name(), (dy, ldy), (w, lw))
    }

    fn bwd(
        &self,
        dy: &Tensor,
        w: &Tensor,
        _dx: &Tensor,
        g: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((
            needed(dy, || apply_forward(self.0, g, w))?,
            needed(w, || apply_weight_grad(self.0, g, dy))?,
        ))
    }
}

impl CustomOp2 for WeightGrad {
    fn name(&self) -> &'static str {
        "photomat-conv2d-weight-grad"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        dy: &CpuStorage,
        ldy: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        run(Kind::WeightGrad, &self.0, self.name(), (x, lx), (dy, ldy))
    }

    fn bwd(
        &self,
        x: &Tensor,
        dy: &Tensor,
        _dw: &Tensor,
        g: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((
            needed(x, || apply_input_grad(self.0, dy, g))?,
            needed(dy, || apply_forward(self.0, x, g))?,
        ))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::simd::with_simd_family;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    /// (B, C_in, H, W, C_out, k, stride, padding).
    type Case = (usize, usize, usize, usize, usize, usize, usize, usize);

    /// The project's kernels (1×1, 3×3, 4×4), strides 1 and 2, odd sizes, batch 1,
    /// non-square images, padding 0–2.
    const CASES: &[Case] = &[
        (2, 3, 8, 8, 4, 3, 1, 1),
        (1, 2, 7, 9, 3, 3, 1, 1),
        (3, 4, 9, 7, 5, 3, 2, 1),
        (2, 3, 8, 10, 4, 4, 2, 1),
        (1, 5, 11, 9, 2, 4, 2, 1),
        (2, 6, 5, 7, 3, 1, 1, 0),
        (1, 3, 7, 5, 4, 1, 2, 0),
        (2, 2, 6, 6, 3, 3, 1, 2),
        (1, 2, 5, 6, 2, 4, 1, 0),
        (4, 2, 4, 4, 3, 3, 1, 1),
    ];

    /// y and the gradients of L = Σ g ⊙ y w.r.t. x and w, through `conv`.
    fn value_and_grads(
        conv: fn(&Tensor, &Tensor, Conv2dSpec) -> Result<Tensor>,
        x: &Var,
        w: &Var,
        g: &Tensor,
        spec: Conv2dSpec,
    ) -> Result<(Tensor, Tensor, Tensor)> {
        let y = conv(x.as_tensor(), w.as_tensor(), spec)?;
        let store = (&y * g)?.sum_all()?.backward()?;
        let get = |v: &Var| store.get(v.as_tensor()).cloned().expect("a gradient");
        Ok((y, get(x), get(w)))
    }

    fn check_against_reference(mode: PaddingMode, dtype: DType, tol: f64) -> Result<()> {
        let dev = Device::Cpu;
        for (seed, &(b, ci, h, w, co, k, s, p)) in CASES.iter().enumerate() {
            let spec = Conv2dSpec {
                stride: s,
                padding: p,
                mode,
            };
            let seed = 10 * seed as u64;
            let x = Var::from_tensor(&pseudo_random((b, ci, h, w), seed, dtype, &dev)?)?;
            let wt = Var::from_tensor(&pseudo_random((co, ci, k, k), seed + 1, dtype, &dev)?)?;
            let reference = conv2d_reference(x.as_tensor(), wt.as_tensor(), spec)?;
            let g = pseudo_random(reference.shape(), seed + 2, dtype, &dev)?;
            let (y, dx, dw) = value_and_grads(conv2d, &x, &wt, &g, spec)?;
            let (ry, rdx, rdw) = value_and_grads(conv2d_reference, &x, &wt, &g, spec)?;
            let case = format!("{mode:?} {dtype:?} x{:?} k{k} s{s} p{p}", (b, ci, h, w));
            assert_eq!(y.dims(), ry.dims(), "{case}");
            assert!(max_abs_diff(&y, &ry)? < tol, "forward {case}");
            assert!(max_abs_diff(&dx, &rdx)? < tol, "input gradient {case}");
            assert!(max_abs_diff(&dw, &rdw)? < tol, "weight gradient {case}");
        }
        Ok(())
    }

    #[test]
    fn conv_zero_padding_matches_candle_conv2d_and_its_gradients() -> Result<()> {
        // f64 sums of ≤ 2·5·16·(B·H·W ≤ 300) O(1) products in another order: rounding
        // ≈ 1e-13 at most; 1e-10 leaves margin and still catches any wrong tap (O(0.1)).
        check_against_reference(PaddingMode::Zeros, DType::F64, 1e-10)
    }

    /// With one operand a constant, the backward pass computes only the other's gradient
    /// (`needed`): it must still be the reference's, and of the right operand.
    #[test]
    fn a_constant_operand_gets_no_gradient_and_the_other_the_right_one() -> Result<()> {
        let dev = Device::Cpu;
        let spec = Conv2dSpec::zeros(1, 1);
        let x = Var::from_tensor(&pseudo_random((2, 3, 6, 5), 1, DType::F64, &dev)?)?;
        let w = Var::from_tensor(&pseudo_random((4, 3, 3, 3), 2, DType::F64, &dev)?)?;
        let g = pseudo_random((2, 4, 6, 5), 3, DType::F64, &dev)?;
        let (_, rdx, rdw) = value_and_grads(conv2d_reference, &x, &w, &g, spec)?;
        let grads = |x: &Tensor, w: &Tensor| -> Result<_> {
            (&conv2d(x, w, spec)? * &g)?.sum_all()?.backward()
        };
        let store = grads(&x.as_tensor().detach(), w.as_tensor())?;
        assert!(max_abs_diff(store.get(w.as_tensor()).expect("dw"), &rdw)? < 1e-10);
        let store = grads(x.as_tensor(), &w.as_tensor().detach())?;
        assert!(max_abs_diff(store.get(x.as_tensor()).expect("dx"), &rdx)? < 1e-10);
        assert!(store.get(w.as_tensor()).is_none());
        Ok(())
    }

    #[test]
    fn conv_circular_padding_matches_narrow_cat_reference() -> Result<()> {
        check_against_reference(PaddingMode::Circular, DType::F64, 1e-10)
    }

    #[test]
    fn conv_f32_matches_candle_conv2d() -> Result<()> {
        // f32: sums of ≤ 300 terms of magnitude ≤ 1, ε = 6e-8 ⇒ ≲ 300·6e-8 ≈ 2e-5 worst case.
        check_against_reference(PaddingMode::Zeros, DType::F32, 1e-4)?;
        check_against_reference(PaddingMode::Circular, DType::F32, 1e-4)
    }

    /// conv2d through every kernel family this CPU runs (the family forced on the calling
    /// thread, as a user's `PHOTOMAT_SIMD` would): forward and both gradients of layers the
    /// direct kernels take (3×3 same, 4×4 stride 2, the discriminator's 3×3 stride 2 on 33
    /// columns, zero and circular) equal the f64 reference. What runs where is the family's
    /// choice; the op must give the same values on each.
    #[test]
    fn conv_on_every_kernel_family_matches_the_reference() -> Result<()> {
        let dev = Device::Cpu;
        let layers = [
            ((2, 6, 12, 32), 5, 3, Conv2dSpec::zeros(1, 1)),
            ((2, 6, 12, 32), 5, 3, Conv2dSpec::circular(1, 1)),
            ((1, 4, 16, 32), 7, 4, Conv2dSpec::circular(2, 1)),
            ((2, 3, 9, 33), 4, 3, Conv2dSpec::zeros(2, 0)),
        ];
        for family in SimdFamily::ALL {
            for (seed, &(xs, co, k, spec)) in layers.iter().enumerate() {
                let seed = 4 * seed as u64;
                let x64 = pseudo_random(xs, seed, DType::F64, &dev)?;
                let w64 = pseudo_random((co, xs.1, k, k), seed + 1, DType::F64, &dev)?;
                let g64 = pseudo_random(
                    Geometry::new(xs, w64.dims4()?, spec)?.y_shape(),
                    seed + 2,
                    DType::F64,
                    &dev,
                )?;
                let (rx, rw) = (Var::from_tensor(&x64)?, Var::from_tensor(&w64)?);
                let reference = value_and_grads(conv2d_reference, &rx, &rw, &g64, spec)?;
                let f32 = |t: &Tensor| t.to_dtype(DType::F32);
                let (x, w) = (
                    Var::from_tensor(&f32(&x64)?)?,
                    Var::from_tensor(&f32(&w64)?)?,
                );
                let (ran, got) = with_simd_family(family, || {
                    value_and_grads(conv2d, &x, &w, &f32(&g64)?, spec)
                });
                let got = got?;
                for (what, a, b) in [
                    ("forward", &got.0, &reference.0),
                    ("input gradient", &got.1, &reference.1),
                    ("weight gradient", &got.2, &reference.2),
                ] {
                    // f32 sums of ≤ 6·16 = 96 products (weight gradients: ≤ 768 texels) of
                    // values in [−1, 1]: rounding ≲ 5e-5; a wrong tap is off by O(0.1).
                    let err = max_abs_diff(&a.to_dtype(DType::F64)?, b)?;
                    assert!(err < 1e-4, "{ran:?} {spec:?} {xs:?} {what}: {err}");
                }
            }
        }
        Ok(())
    }

    #[test]
    fn conv_circular_padding_of_a_whole_period_wraps_exactly() -> Result<()> {
        // padding = H = W: every tap wraps; still the narrow+cat reference.
        let dev = Device::Cpu;
        let x = pseudo_random((1, 2, 3, 3), 1, DType::F64, &dev)?;
        let w = pseudo_random((2, 2, 3, 3), 2, DType::F64, &dev)?;
        let spec = Conv2dSpec::circular(1, 3);
        let y = conv2d(&x, &w, spec)?;
        assert_eq!(y.dims4()?, (1, 2, 7, 7));
        assert!(max_abs_diff(&y, &conv2d_reference(&x, &w, spec)?)? < 1e-12);
        Ok(())
    }

    #[test]
    fn conv_gradients_match_finite_differences() -> Result<()> {
        // Independent of candle's backward. L = Σ g ⊙ conv(x, w) is linear in x and w, so
        // central differences are exact up to rounding ≈ 1e-16·|L|/δ ≈ 1e-13 (δ = 1e-3).
        // The second case is one where candle 0.11.1's own conv2d backward fails (1×1 stride
        // 2 with an unread last row: "shape mismatch in add" in its conv_transpose2d path).
        let dev = Device::Cpu;
        let cases = [
            ((1, 2, 5, 6), (3, 2, 4, 4), Conv2dSpec::circular(2, 1)),
            ((2, 3, 6, 5), (2, 3, 1, 1), Conv2dSpec::zeros(2, 0)),
        ];
        for (seed, (xs, ws, spec)) in cases.into_iter().enumerate() {
            let seed = 3 * seed as u64;
            let x0 = pseudo_random(xs, seed, DType::F64, &dev)?;
            let w0 = pseudo_random(ws, seed + 1, DType::F64, &dev)?;
            let ys = Geometry::new(xs, ws, spec)?.y_shape();
            let g = pseudo_random(ys, seed + 2, DType::F64, &dev)?;
            let (x, w) = (Var::from_tensor(&x0)?, Var::from_tensor(&w0)?);
            let (_, dx, dw) = value_and_grads(conv2d, &x, &w, &g, spec)?;
            let loss = |x: &Tensor, w: &Tensor| -> Result<f64> {
                (conv2d(x, w, spec)? * &g)?.sum_all()?.to_scalar::<f64>()
            };
            let delta = 1e-3;
            for (t0, grad, is_x) in [(&x0, &dx, true), (&w0, &dw, false)] {
                let base = t0.flatten_all()?.to_vec1::<f64>()?;
                let analytic = grad.flatten_all()?.to_vec1::<f64>()?;
                for (i, a) in analytic.iter().enumerate() {
                    let shifted = |d: f64| -> Result<f64> {
                        let mut v = base.clone();
                        v[i] += d;
                        let t = Tensor::from_vec(v, t0.shape(), &dev)?;
                        if is_x { loss(&t, &w0) } else { loss(&x0, &t) }
                    };
                    let fd = (shifted(delta)? - shifted(-delta)?) / (2.0 * delta);
                    assert!(
                        (a - fd).abs() < 1e-9,
                        "{spec:?} element {i} (x: {is_x}): {a} vs {fd}"
                    );
                }
            }
        }
        Ok(())
    }

    #[test]
    fn conv_kernels_write_every_output_element() -> Result<()> {
        // Poison the output buffers with NaN, run each kernel on every batch split (1 thread,
        // gemm-parallel batch < threads, rayon over images), and require finite values equal
        // to the reference.
        let dev = Device::Cpu;
        for (seed, &(b, ci, h, w, co, k, s, p)) in CASES.iter().enumerate() {
            for mode in [PaddingMode::Zeros, PaddingMode::Circular] {
                let spec = Conv2dSpec {
                    stride: s,
                    padding: p,
                    mode,
                };
                let seed = 7 * seed as u64;
                let x = pseudo_random((b, ci, h, w), seed, DType::F64, &dev)?;
                let wt = pseudo_random((co, ci, k, k), seed + 1, DType::F64, &dev)?;
                let g = Geometry::new(x.dims4()?, wt.dims4()?, spec)?;
                let dy = pseudo_random(g.y_shape(), seed + 2, DType::F64, &dev)?;
                let (xv, wv, dyv) = (
                    x.flatten_all()?.to_vec1::<f64>()?,
                    wt.flatten_all()?.to_vec1::<f64>()?,
                    dy.flatten_all()?.to_vec1::<f64>()?,
                );
                let reference = [
                    conv2d_reference(&x, &wt, spec)?,
                    apply_input_grad(g, &dy, &wt)?,
                    apply_weight_grad(g, &x, &dy)?,
                ];
                for threads in [1, 2, 3, 5] {
                    let mut y = vec![f64::NAN; g.y_shape().elem_count()];
                    forward_into(&g, &xv, &wv, &mut y, threads);
                    let mut dx = vec![f64::NAN; g.x_shape().elem_count()];
                    input_grad_into(&g, &dyv, &wv, &mut dx, threads);
                    let mut dw = vec![f64::NAN; g.w_shape().elem_count()];
                    weight_grad_into(&g, &xv, &dyv, &mut dw, threads);
                    for (out, r) in [(y, &reference[0]), (dx, &reference[1]), (dw, &reference[2])] {
                        assert!(out.iter().all(|v| v.is_finite()), "{g:?} threads {threads}");
                        let out = Tensor::from_vec(out, r.shape(), &dev)?;
                        // Same sums, other split: rounding only (see the tests above).
                        assert!(max_abs_diff(&out, r)? < 1e-10, "{g:?} threads {threads}");
                    }
                }
            }
        }
        Ok(())
    }

    #[test]
    fn conv_band_split_does_not_change_the_result() -> Result<()> {
        // 64 channels × 9 taps × 36 columns × 8 B = 162 KiB per output row: a 512 KiB band
        // holds 3 rows, so 16 rows take 6 bands, the last one partial.
        let dev = Device::Cpu;
        let x = pseudo_random((1, 64, 16, 36), 1, DType::F64, &dev)?;
        let w = pseudo_random((2, 64, 3, 3), 2, DType::F64, &dev)?;
        let spec = Conv2dSpec::circular(1, 1);
        let g = Geometry::new(x.dims4()?, w.dims4()?, spec)?;
        assert_eq!(crate::im2col::band_rows(&g, 8), 3);
        let reference = conv2d_reference(&x, &w, spec)?;
        let y = conv2d(&x, &w, spec)?;
        // 576-term f64 dot products of O(1) values: rounding ≲ 1e-13.
        assert!(max_abs_diff(&y, &reference)? < 1e-10);
        // One image, six bands: with 2 or 3 threads the bands are the parallel tasks.
        let (xv, wv) = (x.flatten_all()?.to_vec1()?, w.flatten_all()?.to_vec1()?);
        for threads in [1, 2, 3] {
            let mut y = vec![f64::NAN; g.y_shape().elem_count()];
            forward_into(&g, &xv, &wv, &mut y, threads);
            let y = Tensor::from_vec(y, g.y_shape(), &dev)?;
            assert!(max_abs_diff(&y, &reference)? < 1e-10, "threads {threads}");
        }
        Ok(())
    }

    #[test]
    fn conv_rejects_inconsistent_arguments() -> Result<()> {
        let dev = Device::Cpu;
        let x = Tensor::zeros((1, 3, 4, 4), DType::F32, &dev)?;
        let err = |w: &Tensor, spec| conv2d(&x, w, spec).expect_err("invalid").to_string();
        let w = Tensor::zeros((2, 2, 3, 3), DType::F32, &dev)?;
        assert!(err(&w, Conv2dSpec::zeros(1, 1)).contains("channels"));
        let w = Tensor::zeros((2, 3, 3, 3), DType::F32, &dev)?;
        assert!(err(&w, Conv2dSpec::circular(1, 5)).contains("circular padding"));
        assert!(err(&w, Conv2dSpec::zeros(0, 1)).contains("stride"));
        let w = Tensor::zeros((2, 3, 7, 7), DType::F32, &dev)?;
        assert!(err(&w, Conv2dSpec::zeros(1, 1)).contains("larger"));
        let w64 = Tensor::zeros((2, 3, 3, 3), DType::F64, &dev)?;
        assert!(err(&w64, Conv2dSpec::zeros(1, 1)).contains("dtypes differ"));
        Ok(())
    }
}
