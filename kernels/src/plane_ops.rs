//! Per-plane scaling and per-plane dot products of NCHW maps, as candle custom ops that are
//! differentiable to any order: the element-wise halves of StyleGAN2's modulated convolution
//! (Karras et al. 2020, §2.2: styles scale the input planes, demodulation the output planes)
//! and of their gradients.
//!
//! ```text
//! scale_planes(x, s)[b, c, p] = x[b, c, p] · s[b, c]
//! plane_dot(a, b)[b, c]       = Σ_p a[b, c, p] · b[b, c, p]
//! sum_over_channels(x)[b, 0, p] = Σ_c x[b, c, p]
//! ```
//!
//! Composed from candle ops the first is a broadcast multiplication, whose backward runs a
//! product and a broadcast sum over the batch's planes (a slow strided reduction); the second
//! is a product, a temporary map and a sum. Here each is one pass, and each is the other's
//! adjoint: with `⟨g, scale_planes(x, s)⟩ = ⟨scale_planes(g, s), x⟩ = ⟨plane_dot(g, x), s⟩`,
//!
//! ```text
//! scale_planes: (dx, ds) = (scale_planes(g, s), plane_dot(g, x))
//! plane_dot:    (da, db) = (scale_planes(b, g), scale_planes(a, g))
//! ```
//!
//! so gradients of gradients (path-length regularisation through G; `docs/neural-models.md`,
//! "GAN training") stay on these ops. The third, the gradient of one plane broadcast over the
//! channels (a synthesis layer's noise image, `crate::noise_act`), is candle's strided
//! reduction over dimension 1 when composed; here it adds whole planes, and its backward is
//! the broadcast back (a candle view, differentiable).
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices and dtypes, and calls inside
//! [`crate::reference::with_reference_ops`], use the candle compositions above.

use candle_core::{
    CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor, WithDType, bail,
};
use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::storage::contiguous;

use crate::threads::ELEMENTWISE_CHUNK as CHUNK;

/// `x[b, c, …] · s[b, c]`.
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2, s (B, C) → x's shape.
pub fn scale_planes(x: &Tensor, s: &Tensor) -> Result<Tensor> {
    let (b, c) = leading_dims(x, "scale_planes")?;
    if s.dims() != [b, c] {
        bail!(
            "scale_planes: scales {:?} do not match the map's (B, C) = ({b}, {c})",
            s.dims()
        );
    }
    if fast_path(x, s) {
        x.contiguous()?.apply_op2(&s.contiguous()?, ScalePlanes)
    } else {
        x.broadcast_mul(&s.reshape(plane_broadcast_shape(x))?)
    }
}

/// `Σ_p a[b, c, p] · b[b, c, p]` over each plane.
///
/// # Shapes
/// a, b (B, C, …) of the same shape, rank ≥ 2 → (B, C).
pub fn plane_dot(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let (batch, c) = leading_dims(a, "plane_dot")?;
    if a.dims() != b.dims() {
        bail!(
            "plane_dot: operands of shapes {:?} and {:?}",
            a.dims(),
            b.dims()
        );
    }
    if fast_path(a, b) {
        a.contiguous()?.apply_op2(&b.contiguous()?, PlaneDot)
    } else {
        (a * b)?.reshape((batch, c, ()))?.sum(2)
    }
}

/// `Σ_c x[b, c, …]`: the planes of each sample added together.
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2 → (B, 1, …).
pub fn sum_over_channels(x: &Tensor) -> Result<Tensor> {
    leading_dims(x, "sum_over_channels")?;
    if fast_path(x, x) {
        x.contiguous()?.apply_op1(SumOverChannels)
    } else {
        x.sum_keepdim(1)
    }
}

/// (B, C) of a tensor of rank ≥ 2, or an error naming `op`.
pub(crate) fn leading_dims(x: &Tensor, op: &str) -> Result<(usize, usize)> {
    match x.dims() {
        [b, c, ..] => Ok((*b, *c)),
        dims => bail!("{op}: expected a map of rank ≥ 2, got {dims:?}"),
    }
}

/// (B, C, 1, …, 1) of x's rank: the shape that broadcasts a (B, C) tensor over x's planes.
fn plane_broadcast_shape(x: &Tensor) -> Vec<usize> {
    let mut shape = vec![1; x.rank()];
    shape[..2].copy_from_slice(&x.dims()[..2]);
    shape
}

/// Whether both operands take the fused CPU kernels (CPU, one float dtype, outside
/// [`crate::reference::with_reference_ops`]).
pub(crate) fn fast_path(a: &Tensor, b: &Tensor) -> bool {
    a.device().is_cpu()
        && b.device().is_cpu()
        && a.dtype() == b.dtype()
        && matches!(a.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
        && !crate::reference::reference_ops()
}

/// Multiplies each plane of `planes` (consecutive runs of `plane` elements) by its scale
/// `scale(index of the plane)`, in place, split over rayon for large maps.
pub(crate) fn scale_planes_in_place<T: WithDType>(
    planes: &mut [T],
    plane: usize,
    scale: impl Fn(usize) -> T + Sync,
) {
    if plane == 0 {
        return;
    }
    let f = |(i, p): (usize, &mut [T])| {
        let s = scale(i);
        p.iter_mut().for_each(|v| *v *= s);
    };
    if planes.len() <= CHUNK {
        planes.chunks_mut(plane).enumerate().for_each(f);
    } else {
        planes.par_chunks_mut(plane).enumerate().for_each(f);
    }
}

/// `out[i·plane + j] = f(x[i·plane + j], value(i))`: an element-wise op whose second operand
/// is constant over each plane (consecutive runs of `plane` elements), in one pass, split over
/// rayon for large maps.
pub(crate) fn map_planes<T: WithDType>(
    x: &[T],
    plane: usize,
    value: impl Fn(usize) -> T + Sync,
    f: impl Fn(T, T) -> T + Sync,
) -> Vec<T> {
    if plane == 0 {
        return Vec::new();
    }
    // SAFETY: `g` writes every element of every plane, and the planes cover `out`.
    let mut out = unsafe { output_buffer(x.len()) };
    let g = |(i, (o, x)): (usize, (&mut [T], &[T]))| {
        let v = value(i);
        for (o, &x) in o.iter_mut().zip(x) {
            *o = f(x, v);
        }
    };
    if x.len() <= CHUNK {
        out.chunks_mut(plane)
            .zip(x.chunks(plane))
            .enumerate()
            .for_each(g);
    } else {
        out.par_chunks_mut(plane)
            .zip(x.par_chunks(plane))
            .enumerate()
            .for_each(g);
    }
    out
}

/// `Σ a[i] · b[i]` with eight independent partial sums, so that the loop vectorises without
/// reassociating one serial chain (the compiler may not reorder float additions itself).
fn dot<T: WithDType>(a: &[T], b: &[T]) -> T {
    let zero = T::from_f64(0.0);
    let mut acc = [zero; 8];
    let (a8, b8) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: T = a8
        .remainder()
        .iter()
        .zip(b8.remainder())
        .fold(zero, |s, (&x, &y)| s + x * y);
    for (x, y) in a8.zip(b8) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    acc.iter().fold(tail, |s, &v| s + v)
}

/// Elements per plane of a (B, C, …) layout (1 for rank 2).
pub(crate) fn plane_len(l: &Layout) -> usize {
    l.shape().dims()[2..].iter().product()
}

/// (x, s) → `x ⊙ s` per plane (module docs).
struct ScalePlanes;

impl ScalePlanes {
    fn run<T: WithDType>(x: &[T], s: &[T], plane: usize) -> Vec<T> {
        map_planes(x, plane, |i| s[i], |x, s| x * s)
    }
}

impl CustomOp2 for ScalePlanes {
    fn name(&self) -> &'static str {
        "scale-planes"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        s: &CpuStorage,
        ls: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (name, plane) = (self.name(), plane_len(lx));
        let out = match (x, s) {
            (CpuStorage::F32(x), CpuStorage::F32(s)) => CpuStorage::F32(Self::run(
                contiguous(x, lx, name)?,
                contiguous(s, ls, name)?,
                plane,
            )),
            (CpuStorage::F64(x), CpuStorage::F64(s)) => CpuStorage::F64(Self::run(
                contiguous(x, lx, name)?,
                contiguous(s, ls, name)?,
                plane,
            )),
            _ => bail!("{name}: operands must both be f32 or both f64"),
        };
        Ok((out, lx.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        s: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((Some(scale_planes(grad, s)?), Some(plane_dot(grad, x)?)))
    }
}

/// (a, b) → `Σ_p a ⊙ b` per plane (module docs).
struct PlaneDot;

impl PlaneDot {
    fn run<T: WithDType>(a: &[T], b: &[T], plane: usize, planes: usize) -> Vec<T> {
        if plane == 0 {
            return vec![T::from_f64(0.0); planes];
        }
        let f = |(p, q): (&[T], &[T])| dot(p, q);
        if a.len() <= CHUNK {
            a.chunks(plane).zip(b.chunks(plane)).map(f).collect()
        } else {
            a.par_chunks(plane)
                .zip(b.par_chunks(plane))
                .map(f)
                .collect()
        }
    }
}

impl CustomOp2 for PlaneDot {
    fn name(&self) -> &'static str {
        "plane-dot"
    }

    fn cpu_fwd(
        &self,
        a: &CpuStorage,
        la: &Layout,
        b: &CpuStorage,
        lb: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (name, plane) = (self.name(), plane_len(la));
        let dims = la.shape().dims();
        let planes = dims[0] * dims[1];
        let out = match (a, b) {
            (CpuStorage::F32(a), CpuStorage::F32(b)) => CpuStorage::F32(Self::run(
                contiguous(a, la, name)?,
                contiguous(b, lb, name)?,
                plane,
                planes,
            )),
            (CpuStorage::F64(a), CpuStorage::F64(b)) => CpuStorage::F64(Self::run(
                contiguous(a, la, name)?,
                contiguous(b, lb, name)?,
                plane,
                planes,
            )),
            _ => bail!("{name}: operands must both be f32 or both f64"),
        };
        Ok((out, Shape::from((dims[0], dims[1]))))
    }

    fn bwd(
        &self,
        a: &Tensor,
        b: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((Some(scale_planes(b, grad)?), Some(scale_planes(a, grad)?)))
    }
}

/// x → `Σ_c x` per sample (module docs).
struct SumOverChannels;

impl SumOverChannels {
    /// Each sample's `channels` planes of `plane` elements added, in channel order; samples,
    /// and chunks of a long plane, split over rayon for large maps.
    fn run<T: WithDType>(x: &[T], channels: usize, plane: usize) -> Vec<T> {
        // SAFETY: `add` writes every element of each output chunk before adding into it.
        let mut out = unsafe { output_buffer(x.len() / channels.max(1)) };
        if plane == 0 || channels == 0 {
            out.fill(T::from_f64(0.0));
            return out;
        }
        // Output elements start..start + o.len() of sample `b`.
        let add = |b: usize, start: usize, o: &mut [T]| {
            let len = o.len();
            let at = |c: usize| &x[(b * channels + c) * plane + start..][..len];
            o.copy_from_slice(at(0));
            for c in 1..channels {
                for (d, &v) in o.iter_mut().zip(at(c)) {
                    *d += v;
                }
            }
        };
        if x.len() <= CHUNK {
            out.chunks_mut(plane)
                .enumerate()
                .for_each(|(b, o)| add(b, 0, o));
        } else {
            // Chunks of about CHUNK / C outputs, so that each task reads about CHUNK inputs.
            let piece = (CHUNK / channels).clamp(1, plane);
            out.par_chunks_mut(plane).enumerate().for_each(|(b, o)| {
                o.par_chunks_mut(piece)
                    .enumerate()
                    .for_each(|(k, o)| add(b, k * piece, o))
            });
        }
        out
    }
}

impl CustomOp1 for SumOverChannels {
    fn name(&self) -> &'static str {
        "sum-over-channels"
    }

    fn cpu_fwd(&self, x: &CpuStorage, lx: &Layout) -> Result<(CpuStorage, Shape)> {
        let (name, plane) = (self.name(), plane_len(lx));
        let mut dims = lx.shape().dims().to_vec();
        let channels = dims[1];
        dims[1] = 1;
        let out = match x {
            CpuStorage::F32(x) => {
                CpuStorage::F32(Self::run(contiguous(x, lx, name)?, channels, plane))
            }
            CpuStorage::F64(x) => {
                CpuStorage::F64(Self::run(contiguous(x, lx, name)?, channels, plane))
            }
            _ => bail!("{name}: expected f32 or f64"),
        };
        Ok((out, Shape::from(dims)))
    }

    fn bwd(&self, x: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad.broadcast_as(x.shape())?))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::reference::with_reference_ops;
    use crate::testing::max_abs_diff;
    use photomat_core::op_derivatives::bilinear_derivatives;
    use photomat_core::rng::pseudo_random;

    /// The op's derivatives as a candle result (photomat-core's error type converted).
    fn derivatives(
        op: fn(&Tensor, &Tensor) -> Result<Tensor>,
        u: &Var,
        v: &Var,
        g: &Tensor,
        h: &Tensor,
    ) -> Result<Vec<Tensor>> {
        bilinear_derivatives(|a, b| Ok(op(a, b)?), u, v, g, h).map_err(candle_core::Error::wrap)
    }

    #[test]
    fn plane_ops_and_their_backward_ops_match_their_candle_compositions() -> Result<()> {
        let dev = Device::Cpu;
        // Small odd planes, a map large enough for the rayon split (2·8·64·64 > CHUNK), a
        // plane shorter than the eight partial sums.
        for (i, (b, c, h, w)) in [(2, 3, 5, 7), (2, 8, 64, 64), (3, 2, 1, 5)]
            .into_iter()
            .enumerate()
        {
            let seed = 20 * i as u64;
            let x = Var::from_tensor(&pseudo_random((b, c, h, w), seed, DType::F64, &dev)?)?;
            let s = Var::from_tensor(&pseudo_random((b, c), seed + 1, DType::F64, &dev)?)?;
            let g = pseudo_random((b, c, h, w), seed + 2, DType::F64, &dev)?;
            let h4 = pseudo_random((b, c, h, w), seed + 3, DType::F64, &dev)?;
            let fast = derivatives(scale_planes, &x, &s, &g, &h4)?;
            let reference = with_reference_ops(|| derivatives(scale_planes, &x, &s, &g, &h4))?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                // f64 sums of ≤ 4096 O(1) products in another order.
                assert!(
                    max_abs_diff(a, r)? < 1e-10,
                    "scale_planes case {i}, output {j}"
                );
            }

            let y = Var::from_tensor(&pseudo_random((b, c, h, w), seed + 4, DType::F64, &dev)?)?;
            let gd = pseudo_random((b, c), seed + 5, DType::F64, &dev)?;
            let fast = derivatives(plane_dot, &x, &y, &gd, &h4)?;
            let reference = with_reference_ops(|| derivatives(plane_dot, &x, &y, &gd, &h4))?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                assert!(
                    max_abs_diff(a, r)? < 1e-10,
                    "plane_dot case {i}, output {j}"
                );
            }
        }
        Ok(())
    }

    #[test]
    fn sum_over_channels_matches_candle_and_its_gradient_is_the_broadcast() -> Result<()> {
        let dev = Device::Cpu;
        // Small odd planes, one channel, and a map above the rayon split with planes cut into
        // pieces (2·8·64·64 > CHUNK, piece = CHUNK / 8 < 4096).
        for (i, dims) in [(2, 3, 5, 7), (3, 1, 4, 4), (2, 8, 64, 64)]
            .into_iter()
            .enumerate()
        {
            let x = Var::from_tensor(&pseudo_random(dims, 30 + i as u64, DType::F64, &dev)?)?;
            let sum = sum_over_channels(x.as_tensor())?;
            let reference = x.as_tensor().sum_keepdim(1)?;
            assert_eq!(sum.dims(), reference.dims());
            // f64 sums of ≤ 8 O(1) terms in the same order: equal up to rounding.
            assert!(max_abs_diff(&sum, &reference)? < 1e-12, "case {i}");
            // L = Σ g ⊙ sum ⇒ dL/dx[b, c, p] = g[b, 0, p] for every channel c.
            let g = pseudo_random(sum.dims(), 40 + i as u64, DType::F64, &dev)?;
            let grads = (&sum * &g)?.sum_all()?.backward()?;
            let dx = grads.get(x.as_tensor()).expect("a gradient");
            let expected = g.broadcast_as(dims)?;
            assert!(max_abs_diff(dx, &expected)? == 0.0, "case {i}");
        }
        Ok(())
    }

    #[test]
    fn plane_dot_is_the_closed_form_on_constant_planes() -> Result<()> {
        // a = 2, b = 3 on 5×7 planes: every plane's dot is 2·3·35 = 210, exactly in f32.
        let dev = Device::Cpu;
        let a = Tensor::full(2f32, (2, 3, 5, 7), &dev)?;
        let b = Tensor::full(3f32, (2, 3, 5, 7), &dev)?;
        let d = plane_dot(&a, &b)?;
        assert_eq!(d.dims(), [2, 3]);
        assert!(
            d.flatten_all()?
                .to_vec1::<f32>()?
                .iter()
                .all(|&v| v == 210.0)
        );
        Ok(())
    }

    #[test]
    fn plane_ops_reject_mismatched_shapes() -> Result<()> {
        let dev = Device::Cpu;
        let x = Tensor::zeros((2, 3, 4, 4), DType::F32, &dev)?;
        let err = scale_planes(&x, &Tensor::zeros((2, 4), DType::F32, &dev)?).expect_err("C");
        assert!(err.to_string().contains("(2, 3)"), "{err}");
        let err = plane_dot(&x, &Tensor::zeros((2, 3, 4, 5), DType::F32, &dev)?).expect_err("P");
        assert!(err.to_string().contains("shapes"), "{err}");
        Ok(())
    }
}
