//! LeakyReLU (optionally with a gain) as one fused element-wise pass forward and one backward,
//! differentiable to any order.
//!
//! `f(x) = g·x` for x > 0, `g·a·x` otherwise, with PyTorch's derivative `f'(x) = g` for x > 0
//! and `g·a` otherwise (so `g·a` at exactly 0). The estimator uses slope 0.01, gain 1 (paper
//! §4 "Implementation"; the reference's `nn.LeakyReLU()`); the StyleGAN2 networks slope 0.2,
//! gain √2 (`docs/neural-models.md`, "Relightable generator G"; `bias_act`'s `lrelu`).
//!
//! candle 0.11 element-wise ops allocate per call, and a composite LeakyReLU costs 2–5 ops
//! forward and ≈ 12 backward (`maximum`'s backward builds two masks, divides and accumulates;
//! `docs/candle-notes.md`, "Speed"). On the CPU this module runs one pass each way through candle
//! custom ops, split over rayon for tensors of more than 65,536 elements; other devices use the
//! equivalent `g·max(x, a·x)` composite.
//!
//! The backward is itself a custom op with a backward, so gradients through it can be
//! differentiated again (R1 through D, path length through G; `docs/neural-models.md`, "GAN
//! training"): the input gradient `dx = dy ⊙ f'(x)` is linear in `dy` with the same factor, and
//! `f'` is piecewise constant, so its derivative w.r.t. x is zero wherever it exists.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor, bail};
use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::bias::channel_sums;
use crate::storage::contiguous;

use crate::threads::ELEMENTWISE_CHUNK as CHUNK;

/// `out[i] = f(a[i], b[i])`, split over rayon tasks of [`CHUNK`] elements.
fn zip_map<T: candle_core::WithDType>(a: &[T], b: &[T], f: impl Fn(T, T) -> T + Sync) -> Vec<T> {
    // A shorter `b` would leave the tail of `out` unwritten.
    assert_eq!(a.len(), b.len(), "zip_map: operands of different lengths");
    // SAFETY: `run` writes every element of every chunk (the zip covers all of `a`, and `b` is
    // as long).
    let mut out = unsafe { output_buffer(a.len()) };
    let run = |(o, (a, b)): (&mut [T], (&[T], &[T]))| {
        for ((o, &a), &b) in o.iter_mut().zip(a).zip(b) {
            *o = f(a, b);
        }
    };
    if a.len() <= CHUNK {
        run((&mut out, (a, b)));
    } else {
        out.par_chunks_mut(CHUNK)
            .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
            .for_each(run);
    }
    out
}

/// LeakyReLU with negative slope `slope` ∈ [0, 1].
///
/// # Shapes
/// Any shape, f32 or f64 on the CPU (any float dtype elsewhere); same shape out.
pub fn leaky_relu(x: &Tensor, slope: f64) -> Result<Tensor> {
    leaky_relu_gain(x, slope, 1.0)
}

/// `gain · LeakyReLU(x, slope)`, slope ∈ [0, 1], gain finite.
///
/// # Shapes
/// Any shape, f32 or f64 on the CPU (any float dtype elsewhere); same shape out.
pub fn leaky_relu_gain(x: &Tensor, slope: f64, gain: f64) -> Result<Tensor> {
    if !(0.0..=1.0).contains(&slope) {
        bail!("leaky_relu: slope {slope} is outside [0, 1]");
    }
    if !gain.is_finite() {
        bail!("leaky_relu: gain {gain} is not finite");
    }
    let fused = x.device().is_cpu()
        && matches!(x.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
        && !crate::reference::reference_ops();
    if fused {
        x.contiguous()?.apply_op1(LeakyRelu { slope, gain })
    } else {
        // max(x, a·x) equals LeakyReLU for 0 ≤ a ≤ 1 (ties at 0 split the gradient).
        x.maximum(&x.affine(slope, 0.0)?)?.affine(gain, 0.0)
    }
}

/// `gain · LeakyReLU(x + bias, slope)` with `bias` added along dimension 1 (channels):
/// StyleGAN2's `bias_act` with `lrelu`, one pass forward and one backward (plus the bias
/// gradient's sum). slope ∈ [0, 1], gain > 0 (the backward reads the sign of the input from
/// the output, which needs a positive gain).
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2, bias (C) → x's shape.
pub fn bias_leaky_relu_gain(x: &Tensor, bias: &Tensor, slope: f64, gain: f64) -> Result<Tensor> {
    if !(0.0..=1.0).contains(&slope) {
        bail!("bias_leaky_relu: slope {slope} is outside [0, 1]");
    }
    if !(gain.is_finite() && gain > 0.0) {
        bail!("bias_leaky_relu: gain {gain} is not a positive number");
    }
    let c = x.dim(1)?;
    if bias.dims() != [c] {
        bail!(
            "bias_leaky_relu: bias {:?} does not match {c} channels",
            bias.dims()
        );
    }
    let fused = x.device().is_cpu()
        && bias.device().is_cpu()
        && x.dtype() == bias.dtype()
        && matches!(x.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
        && !crate::reference::reference_ops();
    if fused {
        x.contiguous()?
            .apply_op2(&bias.contiguous()?, BiasLeakyRelu { slope, gain })
    } else {
        let mut shape = vec![1; x.rank()];
        shape[1] = c;
        leaky_relu_gain(&x.broadcast_add(&bias.reshape(shape)?)?, slope, gain)
    }
}

/// (x, bias) → `gain · LeakyReLU(x + bias)`, bias along dimension 1.
struct BiasLeakyRelu {
    slope: f64,
    gain: f64,
}

impl BiasLeakyRelu {
    /// `out[i] = f(x[i] + bias[channel of i])` over rows of `inner` elements, row r in
    /// channel `r % channels`.
    fn run<T: candle_core::WithDType>(&self, x: &[T], bias: &[T], inner: usize) -> Vec<T> {
        let (p, n) = (T::from_f64(self.gain), T::from_f64(self.gain * self.slope));
        let zero = T::from_f64(0.0);
        let channels = bias.len();
        // SAFETY: `row` writes every element of every row.
        let mut out = unsafe { output_buffer(x.len()) };
        let row = |(r, (o, x)): (usize, (&mut [T], &[T]))| {
            let b = bias[r % channels];
            for (o, &x) in o.iter_mut().zip(x) {
                let z = x + b;
                *o = if z > zero { p * z } else { n * z };
            }
        };
        if x.len() <= CHUNK {
            out.chunks_mut(inner)
                .zip(x.chunks(inner))
                .enumerate()
                .for_each(row);
        } else {
            out.par_chunks_mut(inner)
                .zip(x.par_chunks(inner))
                .enumerate()
                .for_each(row);
        }
        out
    }
}

impl CustomOp2 for BiasLeakyRelu {
    fn name(&self) -> &'static str {
        "bias-leaky-relu"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        bias: &CpuStorage,
        l_bias: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let dims = lx.shape().dims();
        if dims.len() < 2 || l_bias.shape().dims() != [dims[1]] {
            bail!(
                "bias-leaky-relu: bias {:?} does not fit x {dims:?}",
                l_bias.shape()
            );
        }
        let inner: usize = dims[2..].iter().product();
        let out = match (x, bias) {
            (CpuStorage::F32(x), CpuStorage::F32(bias)) => {
                let (x, bias) = (
                    contiguous(x, lx, self.name())?,
                    contiguous(bias, l_bias, self.name())?,
                );
                CpuStorage::F32(self.run(x, bias, inner.max(1)))
            }
            (CpuStorage::F64(x), CpuStorage::F64(bias)) => {
                let (x, bias) = (
                    contiguous(x, lx, self.name())?,
                    contiguous(bias, l_bias, self.name())?,
                );
                CpuStorage::F64(self.run(x, bias, inner.max(1)))
            }
            (x, bias) => bail!(
                "bias-leaky-relu: unsupported dtypes {:?}, {:?}",
                x.dtype(),
                bias.dtype()
            ),
        };
        Ok((out, lx.shape().clone()))
    }

    /// `dz = grad ⊙ f'(z)` with the sign of z read from the output (gain > 0), then
    /// `dx = dz` and `dbias = Σ dz` over every dimension but 1. Built from ops with their own
    /// backward, so it can be differentiated again.
    fn bwd(
        &self,
        _x: &Tensor,
        _bias: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let op = LeakyReluGrad {
            slope: self.slope,
            gain: self.gain,
        };
        // The mask is constant (zero derivative): detached, so that a second backward does
        // not wait for a gradient of y that no op provides.
        let dz = op.apply(grad, &y.detach())?;
        // Each plane summed contiguously, split over rayon ([`channel_sums`]).
        let dbias = channel_sums(&dz)?;
        Ok((Some(dz), Some(dbias)))
    }
}

struct LeakyRelu {
    slope: f64,
    gain: f64,
}

impl CustomOp1 for LeakyRelu {
    fn name(&self) -> &'static str {
        "leaky-relu"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let out = match s {
            CpuStorage::F32(v) => {
                let (p, n) = (self.gain as f32, (self.gain * self.slope) as f32);
                let v = contiguous(v, l, self.name())?;
                CpuStorage::F32(
                    v.iter()
                        .map(|&x| if x > 0.0 { p * x } else { n * x })
                        .collect(),
                )
            }
            CpuStorage::F64(v) => {
                let (p, n) = (self.gain, self.gain * self.slope);
                let v = contiguous(v, l, self.name())?;
                CpuStorage::F64(
                    v.iter()
                        .map(|&x| if x > 0.0 { p * x } else { n * x })
                        .collect(),
                )
            }
            other => bail!("leaky-relu: unsupported dtype {:?}", other.dtype()),
        };
        Ok((out, l.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let op = LeakyReluGrad {
            slope: self.slope,
            gain: self.gain,
        };
        // The mask's input is a constant for the gradient (zero derivative a.e.).
        Ok(Some(op.apply(grad, &x.detach())?))
    }
}

/// `grad · f'(x)`: (grad, x) → `g·grad` where x > 0, `g·slope·grad` elsewhere.
#[derive(Clone, Copy)]
pub(crate) struct LeakyReluGrad {
    pub(crate) slope: f64,
    pub(crate) gain: f64,
}

impl LeakyReluGrad {
    pub(crate) fn apply(self, grad: &Tensor, x: &Tensor) -> Result<Tensor> {
        grad.contiguous()?.apply_op2(&x.contiguous()?, self)
    }
}

impl CustomOp2 for LeakyReluGrad {
    fn name(&self) -> &'static str {
        "leaky-relu-grad"
    }

    fn cpu_fwd(
        &self,
        g: &CpuStorage,
        lg: &Layout,
        x: &CpuStorage,
        lx: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        if lg.shape() != lx.shape() {
            bail!(
                "leaky-relu-grad: gradient {:?} and input {:?} differ",
                lg.shape(),
                lx.shape()
            );
        }
        let out = match (g, x) {
            (CpuStorage::F32(g), CpuStorage::F32(x)) => {
                let (p, n) = (self.gain as f32, (self.gain * self.slope) as f32);
                let (g, x) = (
                    contiguous(g, lg, self.name())?,
                    contiguous(x, lx, self.name())?,
                );
                CpuStorage::F32(zip_map(g, x, |g, x| if x > 0.0 { p * g } else { n * g }))
            }
            (CpuStorage::F64(g), CpuStorage::F64(x)) => {
                let (p, n) = (self.gain, self.gain * self.slope);
                let (g, x) = (
                    contiguous(g, lg, self.name())?,
                    contiguous(x, lx, self.name())?,
                );
                CpuStorage::F64(zip_map(g, x, |g, x| if x > 0.0 { p * g } else { n * g }))
            }
            (g, x) => bail!(
                "leaky-relu-grad: unsupported dtypes {:?}, {:?}",
                g.dtype(),
                x.dtype()
            ),
        };
        Ok((out, lg.shape().clone()))
    }

    /// Linear in `grad` with the same factor; `f'` is piecewise constant, so no gradient
    /// flows to `x` (zero wherever the derivative exists).
    fn bwd(
        &self,
        _grad: &Tensor,
        x: &Tensor,
        _res: &Tensor,
        outer: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((Some(self.apply(outer, x)?), None))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    #[test]
    fn leaky_relu_matches_candle_nn_forward() -> Result<()> {
        for dtype in [DType::F32, DType::F64] {
            let x = pseudo_random((2, 3, 4, 5), 1, dtype, &Device::Cpu)?;
            let expected = candle_nn::ops::leaky_relu(&x, 0.01)?;
            assert_eq!(max_abs_diff(&leaky_relu(&x, 0.01)?, &expected)?, 0.0);
            // Non-contiguous input (a transposed view) gives the transposed result.
            let xt = x.transpose(2, 3)?;
            assert_eq!(
                max_abs_diff(&leaky_relu(&xt, 0.01)?, &expected.transpose(2, 3)?)?,
                0.0
            );
        }
        Ok(())
    }

    #[test]
    fn leaky_relu_gradient_is_one_or_the_slope() -> Result<()> {
        // L = Σ g ⊙ f(x)  ⇒  ∂L/∂x = g where x > 0, a·g elsewhere (PyTorch's convention,
        // including a at exactly 0).
        let a = 0.2;
        let mut values = pseudo_random((1, 2, 3, 4), 2, DType::F64, &Device::Cpu)?
            .flatten_all()?
            .to_vec1::<f64>()?;
        values[5] = 0.0;
        let x = Var::from_tensor(&Tensor::from_vec(
            values.clone(),
            (1, 2, 3, 4),
            &Device::Cpu,
        )?)?;
        let g = pseudo_random((1, 2, 3, 4), 3, DType::F64, &Device::Cpu)?;
        let store = (leaky_relu(x.as_tensor(), a)? * &g)?
            .sum_all()?
            .backward()?;
        let got = store
            .get(x.as_tensor())
            .expect("gradient")
            .flatten_all()?
            .to_vec1::<f64>()?;
        let g = g.flatten_all()?.to_vec1::<f64>()?;
        for ((got, g), x) in got.iter().zip(&g).zip(&values) {
            let expected = if *x > 0.0 { *g } else { a * g };
            assert_eq!(*got, expected, "x = {x}");
        }
        Ok(())
    }

    #[test]
    fn leaky_relu_composite_path_agrees() -> Result<()> {
        // f16 is not fused on the CPU and takes the max(x, a·x) path; a slope of ½ and inputs
        // k/8 keep every value exact in f16.
        let x = Tensor::new(&[-1.0f32, -0.375, 0.0, 0.25, 2.0], &Device::Cpu)?;
        let y = leaky_relu(&x.to_dtype(DType::F16)?, 0.5)?.to_dtype(DType::F32)?;
        assert_eq!(y.to_vec1::<f32>()?, [-0.5, -0.1875, 0.0, 0.25, 2.0]);
        assert_eq!(
            leaky_relu(&x, 0.5)?.to_vec1::<f32>()?,
            [-0.5, -0.1875, 0.0, 0.25, 2.0]
        );
        Ok(())
    }

    #[test]
    fn leaky_relu_rejects_slopes_outside_unit_interval() {
        let x = Tensor::zeros(4, DType::F32, &Device::Cpu).expect("tensor");
        assert!(leaky_relu(&x, 1.5).is_err());
        assert!(leaky_relu(&x, -0.1).is_err());
    }

    #[test]
    fn leaky_relu_gain_matches_the_stylegan2_composite() -> Result<()> {
        // g·(1 − a)·relu(x) + g·a·x (StyleGAN2's lrelu as candle ops). Values agree to f64
        // rounding; gradients are g or g·a exactly, away from x = 0 where candle's relu
        // derivative differs by convention (pseudo-random inputs are never exactly 0).
        let (a, gain) = (0.2, std::f64::consts::SQRT_2);
        let x = Var::from_tensor(&pseudo_random((2, 3, 5, 7), 4, DType::F64, &Device::Cpu)?)?;
        let g = pseudo_random((2, 3, 5, 7), 5, DType::F64, &Device::Cpu)?;
        let fused = leaky_relu_gain(x.as_tensor(), a, gain)?;
        let t = x.as_tensor();
        let composite = (t.relu()?.affine(gain * (1.0 - a), 0.0)? + t.affine(gain * a, 0.0)?)?;
        assert!(max_abs_diff(&fused, &composite)? < 1e-15);
        let gf = (fused * &g)?.sum_all()?.backward()?;
        let gc = (composite * &g)?.sum_all()?.backward()?;
        let (gf, gc) = (gf.get(t).expect("gradient"), gc.get(t).expect("gradient"));
        assert!(max_abs_diff(gf, gc)? < 1e-15);
        Ok(())
    }

    #[test]
    fn leaky_relu_gradient_op_is_linear_in_the_gradient() -> Result<()> {
        // Its backward w.r.t. the incoming gradient must be the same mask (second order).
        let a = 0.2;
        let x = pseudo_random((3, 4), 6, DType::F64, &Device::Cpu)?;
        let dy = Var::from_tensor(&pseudo_random((3, 4), 7, DType::F64, &Device::Cpu)?)?;
        let outer = pseudo_random((3, 4), 8, DType::F64, &Device::Cpu)?;
        let op = LeakyReluGrad {
            slope: a,
            gain: 2.0,
        };
        let dx = op.apply(dy.as_tensor(), &x)?;
        let store = (dx * &outer)?.sum_all()?.backward()?;
        let got = store.get(dy.as_tensor()).expect("gradient");
        let mask = x.gt(0.0)?.where_cond(
            &Tensor::full(2.0, (3, 4), &Device::Cpu)?,
            &Tensor::full(2.0 * a, (3, 4), &Device::Cpu)?,
        )?;
        assert_eq!(max_abs_diff(got, &(outer * mask)?)?, 0.0);
        Ok(())
    }

    #[test]
    fn leaky_relu_rejects_a_non_finite_gain() {
        let x = Tensor::zeros(4, DType::F32, &Device::Cpu).expect("tensor");
        assert!(leaky_relu_gain(&x, 0.2, f64::NAN).is_err());
    }

    #[test]
    fn leaky_relu_parallel_path_matches_the_sequential_one() -> Result<()> {
        // 3·CHUNK + 5 elements: several rayon tasks and a ragged last one; each element is
        // computed by the same expression, so results are bit-identical.
        let n = 3 * CHUNK + 5;
        let x = pseudo_random(n, 9, DType::F32, &Device::Cpu)?;
        let v = x.to_vec1::<f32>()?;
        let y = leaky_relu_gain(&x, 0.2, 2.0)?.to_vec1::<f32>()?;
        let (p, q) = (2.0f32, (2.0 * 0.2) as f32);
        for (y, x) in y.iter().zip(&v) {
            assert_eq!(*y, if *x > 0.0 { p * x } else { q * x });
        }
        // Backward through the same split: ∂Σ(y ⊙ g)/∂x = g·(2 or 0.4).
        let xv = Var::from_tensor(&x)?;
        let g = pseudo_random(n, 10, DType::F32, &Device::Cpu)?;
        let store = (leaky_relu_gain(xv.as_tensor(), 0.2, 2.0)? * &g)?
            .sum_all()?
            .backward()?;
        let dx = store
            .get(xv.as_tensor())
            .expect("gradient")
            .to_vec1::<f32>()?;
        for ((d, g), x) in dx.iter().zip(g.to_vec1::<f32>()?).zip(&v) {
            assert_eq!(*d, if *x > 0.0 { p * g } else { q * g });
        }
        Ok(())
    }

    #[test]
    fn bias_leaky_relu_matches_add_then_activation() -> Result<()> {
        // Against broadcast_add + leaky_relu_gain, values and gradients for x and the bias,
        // NCHW and (N, C) rows (the per-texel MLP), including the rayon path (> CHUNK).
        // f64; the bias gradient sums ≤ 2·40·40 products in another order: ≲ 1e-12.
        let (a, gain) = (0.2, std::f64::consts::SQRT_2);
        for (seed, shape) in [vec![2, 3, 4, 5], vec![7, 4], vec![2, 3, 120, 200]]
            .into_iter()
            .enumerate()
        {
            let seed = 3 * seed as u64;
            let c = shape[1];
            let x = Var::from_tensor(&pseudo_random(
                shape.clone(),
                seed,
                DType::F64,
                &Device::Cpu,
            )?)?;
            let b = Var::from_tensor(&pseudo_random(c, seed + 1, DType::F64, &Device::Cpu)?)?;
            let g = pseudo_random(shape.clone(), seed + 2, DType::F64, &Device::Cpu)?;
            let fused = bias_leaky_relu_gain(x.as_tensor(), b.as_tensor(), a, gain)?;
            let mut bshape = vec![1; shape.len()];
            bshape[1] = c;
            let reference = leaky_relu_gain(
                &x.as_tensor()
                    .broadcast_add(&b.as_tensor().reshape(bshape)?)?,
                a,
                gain,
            )?;
            assert!(max_abs_diff(&fused, &reference)? < 1e-15, "{shape:?}");
            let gf = (fused * &g)?.sum_all()?.backward()?;
            let gr = (reference * &g)?.sum_all()?.backward()?;
            for v in [x.as_tensor(), b.as_tensor()] {
                let (p, q) = (gf.get(v).expect("gradient"), gr.get(v).expect("gradient"));
                assert!(max_abs_diff(p, q)? < 1e-10, "{shape:?}");
            }
        }
        Ok(())
    }

    #[test]
    fn bias_leaky_relu_rejects_bad_arguments() -> Result<()> {
        let x = Tensor::zeros((2, 3, 4), DType::F32, &Device::Cpu)?;
        let b = Tensor::zeros(3, DType::F32, &Device::Cpu)?;
        assert!(
            bias_leaky_relu_gain(&x, &b, 0.2, 0.0).is_err(),
            "gain must be > 0"
        );
        assert!(bias_leaky_relu_gain(&x, &b, 1.2, 1.0).is_err());
        let wrong = Tensor::zeros(4, DType::F32, &Device::Cpu)?;
        assert!(bias_leaky_relu_gain(&x, &wrong, 0.2, 1.0).is_err());
        Ok(())
    }
}
