//! Per-texel channel dot products and per-texel scaling of NCHW maps, as candle custom ops that
//! are differentiable to any order: the two halves of the 3-vector algebra of
//! [`crate::vecops`] (n·l, n·h, normalisation) that the differentiable renderer evaluates at
//! every texel of every step of a fit.
//!
//! ```text
//! channel_dot(a, b)[b, 0, p] = Σ_c a[b, c, p] · b[b, c, p]
//! scale_texels(v, s)[b, c, p] = v[b, c, p] · s[b, 0, p]
//! ```
//!
//! Composed from candle ops the first is a product and a sum over the channel axis, which
//! candle reduces one element at a time across the strided dimension; the backward of the
//! second (a broadcast product) runs the same reduction. Here each is one contiguous pass over
//! the channel planes, and each is the other's adjoint:
//!
//! ```text
//! channel_dot:  (da, db) = (scale_texels(b, g), scale_texels(a, g))
//! scale_texels: (dv, ds) = (scale_texels(g, s), channel_dot(g, v))
//! ```
//!
//! CPU tensors of dtype f32 and f64 of the same shape take this path; other devices, dtypes
//! and broadcasting shapes use the candle compositions.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Tensor, WithDType, bail};

use crate::Result;

/// `Σ_c a[b, c, p] · b[b, c, p]` per texel.
///
/// # Shapes
/// a, b (B, C, H, W), or shapes candle broadcasts to one → (B, 1, H, W).
pub fn channel_dot(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    if a.dims() == b.dims() && a.rank() == 4 && fast_path(a, b) {
        Ok(a.contiguous()?.apply_op2(&b.contiguous()?, ChannelDot)?)
    } else {
        Ok(a.broadcast_mul(b)?.sum_keepdim(1)?)
    }
}

/// `v[b, c, p] · s[b, 0, p]`: every channel of a texel scaled by the texel's scalar.
///
/// # Shapes
/// v (B, C, H, W), s (B, 1, H, W), or shapes candle broadcasts to one → v's shape.
pub fn scale_texels(v: &Tensor, s: &Tensor) -> Result<Tensor> {
    let fits = match (v.dims(), s.dims()) {
        ([b, _, h, w], [sb, 1, sh, sw]) => (b, h, w) == (sb, sh, sw),
        _ => false,
    };
    if fits && fast_path(v, s) {
        Ok(v.contiguous()?.apply_op2(&s.contiguous()?, ScaleTexels)?)
    } else {
        Ok(v.broadcast_mul(s)?)
    }
}

/// Whether both operands take the fused CPU kernels.
fn fast_path(a: &Tensor, b: &Tensor) -> bool {
    a.device().is_cpu()
        && b.device().is_cpu()
        && a.dtype() == b.dtype()
        && matches!(a.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
}

/// The contiguous slice a layout describes.
fn slice<'a, T>(v: &'a [T], l: &Layout, op: &str) -> candle_core::Result<&'a [T]> {
    match l.contiguous_offsets() {
        Some((start, end)) => Ok(&v[start..end]),
        None => bail!("{op}: expected a contiguous tensor"),
    }
}

/// (B, C, H·W) of a rank-4 layout.
fn dims(l: &Layout) -> (usize, usize, usize) {
    let d = l.shape().dims();
    (d[0], d[1], d[2] * d[3])
}

/// (a, b) → `Σ_c a ⊙ b` per texel (module docs).
struct ChannelDot;

impl ChannelDot {
    fn run<T: WithDType>(a: &[T], b: &[T], (n, c, p): (usize, usize, usize)) -> Vec<T> {
        let mut out = vec![T::from_f64(0.0); n * p];
        for (i, o) in out.chunks_mut(p.max(1)).enumerate().take(n) {
            for ch in 0..c {
                let at = (i * c + ch) * p;
                for ((o, &x), &y) in o.iter_mut().zip(&a[at..at + p]).zip(&b[at..at + p]) {
                    *o += x * y;
                }
            }
        }
        out
    }
}

impl CustomOp2 for ChannelDot {
    fn name(&self) -> &'static str {
        "channel-dot"
    }

    fn cpu_fwd(
        &self,
        a: &CpuStorage,
        la: &Layout,
        b: &CpuStorage,
        lb: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (name, d) = (self.name(), dims(la));
        let out = match (a, b) {
            (CpuStorage::F32(a), CpuStorage::F32(b)) => {
                CpuStorage::F32(Self::run(slice(a, la, name)?, slice(b, lb, name)?, d))
            }
            (CpuStorage::F64(a), CpuStorage::F64(b)) => {
                CpuStorage::F64(Self::run(slice(a, la, name)?, slice(b, lb, name)?, d))
            }
            _ => bail!(
                "{name}: operands must both be f32 or both f64, got {:?}",
                a.dtype()
            ),
        };
        let s = la.shape().dims();
        Ok((out, Shape::from((s[0], 1, s[2], s[3]))))
    }

    fn bwd(
        &self,
        a: &Tensor,
        b: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let wrap = candle_core::Error::wrap;
        Ok((
            Some(scale_texels(b, grad).map_err(wrap)?),
            Some(scale_texels(a, grad).map_err(wrap)?),
        ))
    }
}

/// (v, s) → `v ⊙ s` with s broadcast over the channels (module docs).
struct ScaleTexels;

impl ScaleTexels {
    fn run<T: WithDType>(v: &[T], s: &[T], (n, c, p): (usize, usize, usize)) -> Vec<T> {
        let mut out = Vec::with_capacity(n * c * p);
        for i in 0..n {
            let si = &s[i * p..(i + 1) * p];
            for ch in 0..c {
                let at = (i * c + ch) * p;
                out.extend(v[at..at + p].iter().zip(si).map(|(&x, &y)| x * y));
            }
        }
        out
    }
}

impl CustomOp2 for ScaleTexels {
    fn name(&self) -> &'static str {
        "scale-texels"
    }

    fn cpu_fwd(
        &self,
        v: &CpuStorage,
        lv: &Layout,
        s: &CpuStorage,
        ls: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (name, d) = (self.name(), dims(lv));
        let out = match (v, s) {
            (CpuStorage::F32(v), CpuStorage::F32(s)) => {
                CpuStorage::F32(Self::run(slice(v, lv, name)?, slice(s, ls, name)?, d))
            }
            (CpuStorage::F64(v), CpuStorage::F64(s)) => {
                CpuStorage::F64(Self::run(slice(v, lv, name)?, slice(s, ls, name)?, d))
            }
            _ => bail!(
                "{name}: operands must both be f32 or both f64, got {:?}",
                v.dtype()
            ),
        };
        Ok((out, lv.shape().clone()))
    }

    fn bwd(
        &self,
        v: &Tensor,
        s: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let wrap = candle_core::Error::wrap;
        Ok((
            Some(scale_texels(grad, s).map_err(wrap)?),
            Some(channel_dot(grad, v).map_err(wrap)?),
        ))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::op_derivatives::bilinear_derivatives as derivatives;
    use crate::rng::pseudo_random;

    fn max_abs_diff(a: &Tensor, b: &Tensor) -> Result<f64> {
        Ok((a - b)?.abs()?.max_all()?.to_scalar::<f64>()?)
    }

    #[test]
    fn texel_ops_match_their_candle_compositions() -> Result<()> {
        let dev = Device::Cpu;
        for (i, (b, c, h, w)) in [(2, 3, 5, 7), (1, 4, 3, 2)].into_iter().enumerate() {
            let seed = 60 * i as u64;
            let x = Var::from_tensor(&pseudo_random((b, c, h, w), seed, DType::F64, &dev)?)?;
            let y = Var::from_tensor(&pseudo_random((b, c, h, w), seed + 1, DType::F64, &dev)?)?;
            let s = Var::from_tensor(&pseudo_random((b, 1, h, w), seed + 2, DType::F64, &dev)?)?;
            let g1 = pseudo_random((b, 1, h, w), seed + 3, DType::F64, &dev)?;
            let gc = pseudo_random((b, c, h, w), seed + 4, DType::F64, &dev)?;
            let hc = pseudo_random((b, c, h, w), seed + 5, DType::F64, &dev)?;

            let fast = derivatives(channel_dot, &x, &y, &g1, &hc)?;
            let reference = derivatives(
                |a, b| Ok(a.broadcast_mul(b)?.sum_keepdim(1)?),
                &x,
                &y,
                &g1,
                &hc,
            )?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                assert_eq!(a.dims(), r.dims());
                // f64 sums of ≤ 4 O(1) products in another order.
                assert!(
                    max_abs_diff(a, r)? < 1e-12,
                    "channel_dot case {i}, output {j}"
                );
            }

            let fast = derivatives(scale_texels, &x, &s, &gc, &hc)?;
            let reference = derivatives(|v, s| Ok(v.broadcast_mul(s)?), &x, &s, &gc, &hc)?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                assert_eq!(a.dims(), r.dims());
                assert!(
                    max_abs_diff(a, r)? < 1e-12,
                    "scale_texels case {i}, output {j}"
                );
            }
        }
        Ok(())
    }

    #[test]
    fn broadcasting_operands_take_the_candle_composition() -> Result<()> {
        // A constant direction (1, 3, 1, 1) against a map: the same values as the broadcast.
        let dev = Device::Cpu;
        let v = pseudo_random((2, 3, 4, 5), 1, DType::F32, &dev)?;
        let l = Tensor::new(&[0.0f32, 0.6, 0.8], &dev)?.reshape((1, 3, 1, 1))?;
        let d = channel_dot(&v, &l)?;
        assert_eq!(d.dims(), [2, 1, 4, 5]);
        let expected = (v.narrow(1, 1, 1)? * 0.6)? + (v.narrow(1, 2, 1)? * 0.8)?;
        assert!(max_abs_diff(&d.to_dtype(DType::F64)?, &expected?.to_dtype(DType::F64)?)? < 1e-6);
        Ok(())
    }
}
