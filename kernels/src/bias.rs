//! A per-channel bias added to an NCHW map, as a candle custom op that is differentiable to
//! any order: the bias of a layer with no activation after it (StyleGAN2's `toRGB`-like
//! feature layer and the discriminator's linear convs, the estimator's output head).
//!
//! ```text
//! add_channel_bias(x, bias)[b, c, p] = x[b, c, p] + bias[c]
//! ```
//!
//! Composed from candle ops this is a broadcast addition, whose backward sums the gradient over
//! the batch and the texels in candle's strided reduction (one element at a time across the
//! non-contiguous dimensions, on one thread). Here the forward is one pass and the backward
//! passes the gradient through unchanged and sums each plane contiguously
//! ([`channel_sums`]), split over rayon for large maps.
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices and dtypes, and calls inside
//! [`crate::reference::with_reference_ops`], use the candle compositions.

use candle_core::{
    CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor, WithDType, bail,
};
use rayon::prelude::*;

use crate::plane_ops::{fast_path, leading_dims, map_planes, plane_len};
use crate::storage::contiguous;

use crate::threads::ELEMENTWISE_CHUNK as CHUNK;

/// `x + bias` with `bias` along dimension 1 (channels).
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2, bias (C) → x's shape.
pub fn add_channel_bias(x: &Tensor, bias: &Tensor) -> Result<Tensor> {
    let (_, c) = leading_dims(x, "add_channel_bias")?;
    if bias.dims() != [c] {
        bail!(
            "add_channel_bias: bias {:?} does not match {c} channels",
            bias.dims()
        );
    }
    if fast_path(x, bias) {
        x.contiguous()?
            .apply_op2(&bias.contiguous()?, AddChannelBias)
    } else {
        x.broadcast_add(&bias.reshape(channel_shape(x))?)
    }
}

/// `Σ_{b, p} x[b, c, p]` for each channel c: the gradient of a per-channel bias.
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2 → (C).
pub fn channel_sums(x: &Tensor) -> Result<Tensor> {
    let (_, c) = leading_dims(x, "channel_sums")?;
    if fast_path(x, x) {
        x.contiguous()?.apply_op1(ChannelSums)
    } else {
        x.transpose(0, 1)?.reshape((c, ()))?.sum(1)
    }
}

/// (1, C, 1, …, 1) of x's rank.
fn channel_shape(x: &Tensor) -> Vec<usize> {
    let mut shape = vec![1; x.rank()];
    shape[1] = x.dims()[1];
    shape
}

/// (batch, channels, elements per plane) of a (B, C, …) layout.
fn planes(l: &Layout) -> (usize, usize, usize) {
    let dims = l.shape().dims();
    (dims[0], dims[1], plane_len(l))
}

/// `Σ v[i]` with eight independent partial sums, so that the loop vectorises (the compiler
/// may not reorder one serial chain of float additions itself).
fn sum<T: WithDType>(v: &[T]) -> T {
    let zero = T::from_f64(0.0);
    let mut acc = [zero; 8];
    let chunks = v.chunks_exact(8);
    let tail = chunks.remainder().iter().fold(zero, |s, &x| s + x);
    for x in chunks {
        for k in 0..8 {
            acc[k] += x[k];
        }
    }
    acc.iter().fold(tail, |s, &a| s + a)
}

/// (x, bias) → `x + bias` per channel (module docs).
struct AddChannelBias;

impl AddChannelBias {
    fn run<T: WithDType>(x: &[T], bias: &[T], plane: usize) -> Vec<T> {
        map_planes(x, plane, |i| bias[i % bias.len()], |x, b| x + b)
    }
}

impl CustomOp2 for AddChannelBias {
    fn name(&self) -> &'static str {
        "add-channel-bias"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        b: &CpuStorage,
        lb: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (name, (_, c, plane)) = (self.name(), planes(lx));
        if lb.shape().dims() != [c] {
            bail!("{name}: bias {:?} does not fit {c} channels", lb.shape());
        }
        let out = match (x, b) {
            (CpuStorage::F32(x), CpuStorage::F32(b)) => CpuStorage::F32(Self::run(
                contiguous(x, lx, name)?,
                contiguous(b, lb, name)?,
                plane,
            )),
            (CpuStorage::F64(x), CpuStorage::F64(b)) => CpuStorage::F64(Self::run(
                contiguous(x, lx, name)?,
                contiguous(b, lb, name)?,
                plane,
            )),
            _ => bail!("{name}: operands must both be f32 or both f64"),
        };
        Ok((out, lx.shape().clone()))
    }

    fn bwd(
        &self,
        _x: &Tensor,
        _bias: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((Some(grad.clone()), Some(channel_sums(grad)?)))
    }
}

/// x → `Σ_{b, p} x` per channel (module docs).
struct ChannelSums;

impl ChannelSums {
    fn run<T: WithDType>(x: &[T], (b, c, plane): (usize, usize, usize)) -> Vec<T> {
        let zero = T::from_f64(0.0);
        if plane == 0 {
            return vec![zero; c];
        }
        let per_plane: Vec<T> = if x.len() <= CHUNK {
            x.chunks(plane).map(sum).collect()
        } else {
            x.par_chunks(plane).map(sum).collect()
        };
        (0..c)
            .map(|ch| (0..b).fold(zero, |s, i| s + per_plane[i * c + ch]))
            .collect()
    }
}

impl CustomOp1 for ChannelSums {
    fn name(&self) -> &'static str {
        "channel-sums"
    }

    fn cpu_fwd(&self, x: &CpuStorage, lx: &Layout) -> Result<(CpuStorage, Shape)> {
        let (name, dims) = (self.name(), planes(lx));
        let out = match x {
            CpuStorage::F32(x) => CpuStorage::F32(Self::run(contiguous(x, lx, name)?, dims)),
            CpuStorage::F64(x) => CpuStorage::F64(Self::run(contiguous(x, lx, name)?, dims)),
            _ => bail!("{name}: expected f32 or f64"),
        };
        Ok((out, Shape::from(dims.1)))
    }

    fn bwd(&self, x: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        // Each input element adds once to its channel's sum: the gradient broadcast back.
        Ok(Some(
            grad.reshape(channel_shape(x))?.broadcast_as(x.shape())?,
        ))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::reference::with_reference_ops;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    #[test]
    fn bias_and_its_gradients_match_the_broadcast_addition() -> Result<()> {
        let dev = Device::Cpu;
        // Small odd planes, rank 2 (a plane of one element), and a map large enough for the
        // rayon split (2·8·64·64 > CHUNK).
        let shapes: [&[usize]; 3] = [&[2, 3, 5, 7], &[4, 6], &[2, 8, 64, 64]];
        for (i, shape) in shapes.into_iter().enumerate() {
            let seed = 50 * i as u64;
            let x = Var::from_tensor(&pseudo_random(shape, seed, DType::F64, &dev)?)?;
            let bias = Var::from_tensor(&pseudo_random(shape[1], seed + 1, DType::F64, &dev)?)?;
            let g = pseudo_random(shape, seed + 2, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = add_channel_bias(x.as_tensor(), bias.as_tensor())?;
                let grads = (&y * &g)?.sum_all()?.backward()?;
                Ok(vec![
                    y,
                    grads.get(x.as_tensor()).expect("dx").clone(),
                    grads.get(bias.as_tensor()).expect("dbias").clone(),
                ])
            };
            let fast = run()?;
            let reference = with_reference_ops(run)?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                assert_eq!(a.dims(), r.dims());
                // f64 sums of ≤ 8192 O(1) values in another order.
                assert!(max_abs_diff(a, r)? < 1e-10, "case {i}, output {j}");
            }
        }
        Ok(())
    }

    #[test]
    fn channel_sums_are_the_closed_form_on_constant_planes() -> Result<()> {
        // Channel c holds c + 1 everywhere on 2 samples of 5×7: its sum is 70·(c + 1), exact in
        // f32.
        let dev = Device::Cpu;
        let x = Tensor::arange(1f32, 4.0, &dev)?
            .reshape((1, 3, 1, 1))?
            .broadcast_as((2, 3, 5, 7))?;
        let sums = channel_sums(&x)?.to_vec1::<f32>()?;
        assert_eq!(sums, [70.0, 140.0, 210.0]);
        Ok(())
    }

    #[test]
    fn bias_of_the_wrong_length_is_refused() -> Result<()> {
        let x = Tensor::zeros((2, 3, 4, 4), DType::F32, &Device::Cpu)?;
        let err =
            add_channel_bias(&x, &Tensor::zeros(4, DType::F32, &Device::Cpu)?).expect_err("4 ≠ 3");
        assert!(err.to_string().contains("3 channels"), "{err}");
        Ok(())
    }
}
