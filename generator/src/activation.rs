//! StyleGAN2's `lrelu` activation: LeakyReLU with slope 0.2 followed by a gain of √2.
//!
//! StyleGAN2 (Karras et al. 2020; `bias_act` in the StyleGAN2-ADA code) multiplies the
//! LeakyReLU output by √2 so that, with equalised learning rate, the signal variance is kept
//! from layer to layer (He initialisation for a leaky rectifier). `docs/neural-models.md`
//! ("Relightable generator G") prescribes it for the mapping network, the synthesis layers,
//! M and D.
//!
//! On the CPU this is photomat-kernels' fused LeakyReLU ([`photomat_kernels::leaky_relu_gain`],
//! and [`photomat_kernels::bias_leaky_relu_gain`] with the preceding bias add fused in,
//! StyleGAN2's `bias_act`): one pass forward and one backward, whose backward is itself a
//! custom op with a backward, so the R1 penalty's double backward through D and path-length
//! regularisation through G stay exact. Derivative: `g` for x > 0, `g·a` for x ≤ 0.
//!
//! Inside [`photomat_kernels::with_reference_ops`] (plain candle ops, the implementation
//! before the kernels were used) it is written as `g·(1 − a)·relu(x) + g·a·x` after a
//! `broadcast_add` of the bias: every op in it has exact first and second derivatives (`relu`'s
//! derivative is a constant mask); its derivative at exactly 0 is `g` (candle's `relu`
//! derivative there is 1) instead of `g·a`, a difference on a set of measure zero.

use candle_core::{Result, Tensor, bail};

/// Negative slope of StyleGAN2's `lrelu`.
pub const LRELU_SLOPE: f64 = 0.2;
/// Gain of StyleGAN2's `lrelu` (√2).
pub const LRELU_GAIN: f64 = std::f64::consts::SQRT_2;

/// `gain · LeakyReLU(x, slope)`.
///
/// # Shapes
/// Any shape, same shape out.
pub fn leaky_relu_gain(x: &Tensor, slope: f64, gain: f64) -> Result<Tensor> {
    if !(0.0..=1.0).contains(&slope) {
        bail!("leaky_relu_gain: slope {slope} is outside [0, 1]");
    }
    if !photomat_kernels::reference_ops() {
        return photomat_kernels::leaky_relu_gain(x, slope, gain);
    }
    let positive = x.relu()?.affine(gain * (1.0 - slope), 0.0)?;
    positive + x.affine(gain * slope, 0.0)?
}

/// StyleGAN2's `lrelu`: `√2 · LeakyReLU(x, 0.2)`.
///
/// # Shapes
/// Any shape, same shape out.
pub fn lrelu(x: &Tensor) -> Result<Tensor> {
    leaky_relu_gain(x, LRELU_SLOPE, LRELU_GAIN)
}

/// StyleGAN2's `bias_act` with `lrelu`: `√2 · LeakyReLU(x + bias, 0.2)`, the bias added along
/// dimension 1 (channels of an NCHW map, features of (N, C) rows).
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2, bias (C) → x's shape.
pub fn bias_lrelu(x: &Tensor, bias: &Tensor) -> Result<Tensor> {
    bias_leaky_relu_gain(x, bias, LRELU_SLOPE, LRELU_GAIN)
}

/// `gain · LeakyReLU(x + bias, slope)`, the bias added along dimension 1: one pass each way on
/// the CPU; a layer's output gain after [`bias_lrelu`] is this with `gain = √2 · layer gain`.
///
/// # Shapes
/// x (B, C, …) of rank ≥ 2, bias (C) → x's shape.
pub fn bias_leaky_relu_gain(x: &Tensor, bias: &Tensor, slope: f64, gain: f64) -> Result<Tensor> {
    if !photomat_kernels::reference_ops() {
        return photomat_kernels::bias_leaky_relu_gain(x, bias, slope, gain);
    }
    let mut shape = vec![1; x.rank()];
    shape[1] = bias.elem_count();
    leaky_relu_gain(&x.broadcast_add(&bias.reshape(shape)?)?, slope, gain)
}

/// A synthesis layer's epilogue: `√2 · LeakyReLU(x + noise + bias, 0.2)` with one noise image
/// per sample (already scaled by the layer's strength) broadcast over the channels, one pass
/// each way on the CPU ([`photomat_kernels::noise_bias_leaky_relu_gain`]); inside
/// [`photomat_kernels::with_reference_ops`] a `broadcast_add` followed by [`bias_lrelu`].
///
/// # Shapes
/// x (B, C, H, W), noise (B, 1, H, W), bias (C) → (B, C, H, W).
pub fn noise_bias_lrelu(x: &Tensor, noise: &Tensor, bias: &Tensor) -> Result<Tensor> {
    if !photomat_kernels::reference_ops() {
        return photomat_kernels::noise_bias_leaky_relu_gain(
            x,
            noise,
            bias,
            LRELU_SLOPE,
            LRELU_GAIN,
        );
    }
    bias_lrelu(&x.broadcast_add(noise)?, bias)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;

    #[test]
    fn lrelu_values_and_gradient() -> Result<()> {
        let x = Var::new(&[-2.0f64, -0.5, 0.5, 3.0], &Device::Cpu)?;
        let y = lrelu(x.as_tensor())?;
        let s = LRELU_GAIN;
        let expected = [-0.4 * s, -0.1 * s, 0.5 * s, 3.0 * s];
        for (a, b) in y.to_vec1::<f64>()?.iter().zip(expected) {
            // Two roundings of O(1) values in f64.
            assert!((a - b).abs() < 1e-14, "{a} vs {b}");
        }
        let grads = y.sum_all()?.backward()?;
        // Derivative 0.2·√2 for x < 0, √2 for x > 0 (fused kernel path).
        let g = grads
            .get(x.as_tensor())
            .expect("gradient")
            .to_vec1::<f64>()?;
        for (a, b) in g.iter().zip([0.2 * s, 0.2 * s, s, s]) {
            assert!((a - b).abs() < 1e-14, "{a} vs {b}");
        }
        assert!(leaky_relu_gain(x.as_tensor(), -0.1, 1.0).is_err());
        Ok(())
    }

    #[test]
    fn bias_lrelu_equals_bias_then_lrelu_on_both_paths() -> Result<()> {
        // (N, C) rows and an NCHW map, bias along dimension 1; values and both gradients.
        let dev = Device::Cpu;
        for shape in [vec![5, 3], vec![2, 3, 4, 5]] {
            let n: usize = shape.iter().product();
            let vals: Vec<f64> = (0..n).map(|i| ((i * 7) % 11) as f64 * 0.3 - 1.45).collect();
            let x = Var::from_tensor(&Tensor::from_vec(vals, shape.as_slice(), &dev)?)?;
            let b = Var::new(&[0.27f64, -0.52, 0.13], &dev)?;
            let weights = Tensor::from_vec(
                (0..n).map(|i| (i % 5) as f64 - 2.0).collect::<Vec<_>>(),
                shape.as_slice(),
                &dev,
            )?;
            let run = || -> Result<Vec<Vec<f64>>> {
                let y = bias_lrelu(x.as_tensor(), b.as_tensor())?;
                let g = (&y * &weights)?.sum_all()?.backward()?;
                let get = |v: &Var| g.get(v.as_tensor()).expect("gradient").flatten_all();
                Ok(vec![
                    y.flatten_all()?.to_vec1()?,
                    get(&x)?.to_vec1()?,
                    get(&b)?.to_vec1()?,
                ])
            };
            let fused = run()?;
            let plain = photomat_kernels::with_reference_ops(run)?;
            // x ∈ 0.3ℤ − 1.45 and these biases keep every pre-activation ≥ 0.02 away from 0,
            // where the two paths differ in derivative (module docs).
            for (f, p) in fused.iter().flatten().zip(plain.iter().flatten()) {
                assert!((f - p).abs() < 1e-12, "{shape:?}: {f} vs {p}");
            }
        }
        Ok(())
    }
}
