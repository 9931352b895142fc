//! The epilogue of a StyleGAN2 synthesis layer as one fused element-wise op: per-pixel noise
//! (one image per sample, broadcast over the channels), per-channel bias and LeakyReLU with
//! gain (StyleGAN2-ADA `SynthesisLayer.forward`: `x + noise`, then `bias_act` with `lrelu`;
//! Karras et al. 2019 §3.2, 2020 §2),
//!
//! ```text
//! y[b, c, p] = gain · LeakyReLU(x[b, c, p] + noise[b, p] + bias[c], slope)
//! ```
//!
//! Composed from candle ops this is a broadcast addition (whose backward fills and adds two
//! full-size gradient buffers and sums one over the channels) before the fused bias +
//! LeakyReLU of [`crate::activation`]; here it is one pass forward and three backward:
//! `dz = dy ⊙ f'(z)` (the sign of z read from the output, gain > 0), `dx = dz`,
//! `dnoise = Σ_c dz`, `dbias = Σ_{b, p} dz`. The backward is built from ops with a backward
//! (the LeakyReLU gradient op, sums), so it can be differentiated again.
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices, and calls inside
//! [`crate::reference::with_reference_ops`], use the composition of candle ops.

use candle_core::{CpuStorage, CustomOp3, DType, Layout, Result, Shape, Tensor, WithDType, bail};
use rayon::prelude::*;

use crate::activation::{LeakyReluGrad, leaky_relu_gain};
use crate::alloc::output_buffer;
use crate::bias::channel_sums;
use crate::plane_ops::sum_over_channels;
use crate::storage::contiguous;

/// `gain · LeakyReLU(x + noise + bias, slope)`, noise broadcast over channels, bias over
/// batch and pixels; slope ∈ [0, 1], gain > 0.
///
/// # Shapes
/// x (B, C, H, W), noise (B, 1, H, W), bias (C) → (B, C, H, W).
pub fn noise_bias_leaky_relu_gain(
    x: &Tensor,
    noise: &Tensor,
    bias: &Tensor,
    slope: f64,
    gain: f64,
) -> Result<Tensor> {
    if !(0.0..=1.0).contains(&slope) {
        bail!("noise-bias-leaky-relu: slope {slope} is outside [0, 1]");
    }
    if !(gain.is_finite() && gain > 0.0) {
        bail!("noise-bias-leaky-relu: gain {gain} is not a positive number");
    }
    let (b, c, h, w) = x.dims4()?;
    if noise.dims4()? != (b, 1, h, w) || bias.dims() != [c] {
        bail!(
            "noise-bias-leaky-relu: noise {:?} and bias {:?} do not fit x {:?}",
            noise.dims(),
            bias.dims(),
            x.dims()
        );
    }
    let same = x.dtype() == noise.dtype() && x.dtype() == bias.dtype();
    let fused = [x, noise, bias].iter().all(|t| t.device().is_cpu())
        && same
        && matches!(x.dtype(), DType::F32 | DType::F64)
        && !crate::reference::reference_ops();
    if !fused {
        let z = x
            .broadcast_add(noise)?
            .broadcast_add(&bias.reshape((1, c, 1, 1))?)?;
        return leaky_relu_gain(&z, slope, gain);
    }
    x.contiguous()?.apply_op3(
        &noise.contiguous()?,
        &bias.contiguous()?,
        NoiseBiasLeakyRelu { slope, gain },
    )
}

/// (x, noise, bias) → `gain · LeakyReLU(x + noise + bias)`.
struct NoiseBiasLeakyRelu {
    slope: f64,
    gain: f64,
}

impl NoiseBiasLeakyRelu {
    /// Writes every element: plane (b, c) of `hw` texels reads noise plane b and bias c.
    fn run<T: WithDType>(&self, x: &[T], noise: &[T], bias: &[T], hw: usize) -> Vec<T> {
        let (p, n) = (T::from_f64(self.gain), T::from_f64(self.gain * self.slope));
        let zero = T::from_f64(0.0);
        let channels = bias.len();
        // SAFETY: `plane` writes every element of every plane.
        let mut out = unsafe { output_buffer(x.len()) };
        let plane = |(i, (o, x)): (usize, (&mut [T], &[T]))| {
            let (b, c) = (i / channels, i % channels);
            let nz = &noise[b * hw..(b + 1) * hw];
            let bc = bias[c];
            for ((o, &x), &nz) in o.iter_mut().zip(x).zip(nz) {
                let z = x + nz + bc;
                *o = if z > zero { p * z } else { n * z };
            }
        };
        if x.len() < crate::threads::ELEMENTWISE_CHUNK {
            out.chunks_mut(hw)
                .zip(x.chunks(hw))
                .enumerate()
                .for_each(plane);
        } else {
            out.par_chunks_mut(hw)
                .zip(x.par_chunks(hw))
                .enumerate()
                .for_each(plane);
        }
        out
    }
}

impl CustomOp3 for NoiseBiasLeakyRelu {
    fn name(&self) -> &'static str {
        "noise-bias-leaky-relu"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        noise: &CpuStorage,
        ln: &Layout,
        bias: &CpuStorage,
        lb: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let name = self.name();
        let [b, c, h, w] = lx.shape().dims() else {
            bail!("{name}: expected an NCHW input, got {:?}", lx.shape());
        };
        if ln.shape().dims() != [*b, 1, *h, *w] || lb.shape().dims() != [*c] {
            bail!(
                "{name}: noise {:?} or bias {:?} do not fit",
                ln.shape(),
                lb.shape()
            );
        }
        let hw = (h * w).max(1);
        let out = match (x, noise, bias) {
            (CpuStorage::F32(x), CpuStorage::F32(nz), CpuStorage::F32(bi)) => {
                let (x, nz, bi) = (
                    contiguous(x, lx, name)?,
                    contiguous(nz, ln, name)?,
                    contiguous(bi, lb, name)?,
                );
                CpuStorage::F32(self.run(x, nz, bi, hw))
            }
            (CpuStorage::F64(x), CpuStorage::F64(nz), CpuStorage::F64(bi)) => {
                let (x, nz, bi) = (
                    contiguous(x, lx, name)?,
                    contiguous(nz, ln, name)?,
                    contiguous(bi, lb, name)?,
                );
                CpuStorage::F64(self.run(x, nz, bi, hw))
            }
            _ => bail!("{name}: operands must all be f32 or all f64"),
        };
        Ok((out, lx.shape().clone()))
    }

    fn bwd(
        &self,
        _x: &Tensor,
        _noise: &Tensor,
        _bias: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let op = LeakyReluGrad {
            slope: self.slope,
            gain: self.gain,
        };
        // The mask is constant (zero derivative a.e.): detached, as in `activation`.
        let dz = op.apply(grad, &y.detach())?;
        let dnoise = sum_over_channels(&dz)?;
        let dbias = channel_sums(&dz)?;
        Ok((Some(dz), Some(dnoise), Some(dbias)))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    #[test]
    fn fused_epilogue_matches_the_candle_composition_and_its_gradients() -> Result<()> {
        let dev = Device::Cpu;
        let (a, g) = (0.2, std::f64::consts::SQRT_2);
        // Small, odd and batch-1 maps, and one above the rayon split.
        for (i, (b, c, h, w)) in [(2, 3, 5, 4), (1, 2, 3, 7), (2, 8, 64, 64)]
            .into_iter()
            .enumerate()
        {
            let seed = 4 * i as u64;
            let x = Var::from_tensor(&pseudo_random((b, c, h, w), seed, DType::F64, &dev)?)?;
            let nz = Var::from_tensor(&pseudo_random((b, 1, h, w), seed + 1, DType::F64, &dev)?)?;
            let bias = Var::from_tensor(&pseudo_random(c, seed + 2, DType::F64, &dev)?)?;
            let weights = pseudo_random((b, c, h, w), seed + 3, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = noise_bias_leaky_relu_gain(
                    x.as_tensor(),
                    nz.as_tensor(),
                    bias.as_tensor(),
                    a,
                    g,
                )?;
                let store = (&y * &weights)?.sum_all()?.backward()?;
                let mut out = vec![y];
                for v in [&x, &nz, &bias] {
                    out.push(store.get(v.as_tensor()).cloned().expect("a gradient"));
                }
                Ok(out)
            };
            let fused = run()?;
            let reference = crate::reference::with_reference_ops(run)?;
            for (j, (f, r)) in fused.iter().zip(&reference).enumerate() {
                assert_eq!(f.dims(), r.dims());
                // Sums of ≤ 2·64² O(1) terms in another order (f64); pseudo-random inputs
                // never put a pre-activation exactly at 0, where the derivatives differ.
                assert!(max_abs_diff(f, r)? < 1e-10, "case {i}, output {j}");
            }
        }
        Ok(())
    }

    #[test]
    fn fused_epilogue_rejects_bad_arguments() -> Result<()> {
        let dev = Device::Cpu;
        let x = Tensor::zeros((2, 3, 4, 4), DType::F32, &dev)?;
        let nz = Tensor::zeros((2, 1, 4, 4), DType::F32, &dev)?;
        let bias = Tensor::zeros(3, DType::F32, &dev)?;
        assert!(noise_bias_leaky_relu_gain(&x, &nz, &bias, 0.2, 1.0).is_ok());
        assert!(noise_bias_leaky_relu_gain(&x, &x, &bias, 0.2, 1.0).is_err());
        assert!(noise_bias_leaky_relu_gain(&x, &nz, &nz, 0.2, 1.0).is_err());
        assert!(noise_bias_leaky_relu_gain(&x, &nz, &bias, 1.5, 1.0).is_err());
        assert!(noise_bias_leaky_relu_gain(&x, &nz, &bias, 0.2, -1.0).is_err());
        Ok(())
    }
}
