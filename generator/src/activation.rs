//! StyleGAN2's `lrelu` activation: LeakyReLU with slope 0.2 followed by a gain of √2.
//!
//! StyleGAN2 (Karras et al. 2020; `bias_act` in the StyleGAN2-ADA code) multiplies the
//! LeakyReLU output by √2 so that, with equalised learning rate, the signal variance is kept
//! from layer to layer (He initialisation for a leaky rectifier). DESIGN §4 prescribes it for
//! the mapping network, the synthesis layers, M and D.
//!
//! Written as `g·(1 − a)·relu(x) + g·a·x`: with this form DESIGN §6 measured a per-texel MLP
//! ≈ 2× faster than with candle's `leaky_relu` on the CPU, and every op in it has exact first and second derivatives
//! (`relu`'s derivative is a constant mask), which the R1 penalty's double backward through D
//! requires. Derivative: `g` for x > 0, `g·a` for x < 0; at exactly 0 candle's `relu`
//! derivative is 1 (`x ≥ 0`), so the derivative there is `g`.
//!
//! photomat-kernels' fused LeakyReLU is not used: its backward is a `no_bwd` custom op, so a
//! gradient through it cannot be differentiated again, which the R1 penalty (through D) and
//! path-length regularisation (through G) need. It could serve G's and M's plain
//! (non-regularised) passes once a trainer selects the op per pass.

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
}
