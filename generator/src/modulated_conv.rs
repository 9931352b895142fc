//! StyleGAN2's modulated convolution with weight demodulation (Karras et al. 2020, §2.2,
//! eqs. 1–3; StyleGAN2-ADA `modulated_conv2d` with `fused_modconv = False`).
//!
//! A per-sample style `s = A(w)` (an [`EqualizedLinear`] affine layer, bias initialised to 1)
//! scales the input channels of a shared weight W, and demodulation rescales each output
//! channel to unit expected variance:
//!
//! ```text
//! w'_{o,i,k} = s_i · W_{o,i,k}                 (modulation, eq. 1)
//! d_o       = 1 / √(Σ_{i,k} (w'_{o,i,k})² + ε)  (demodulation, eq. 3)
//! y         = d_o · conv(x, w')
//! ```
//!
//! Implemented without per-sample (grouped) weights, StyleGAN2's non-fused path:
//! `y = d ⊙ conv(x ⊙ s, W)`, the same value since modulation is a per-input-channel scale. The
//! demodulation coefficients are one matmul, `d = rsqrt((s ⊙ s) · (Σ_k W²)ᵀ + ε)`. With a
//! weight shared by the batch, modulation, convolution and demodulation are one op,
//! photomat-kernels' [`modulated_conv2d`](photomat_kernels::modulated_conv2d): the styles
//! scale the input once, im2col + gemm convolves it with the padding (zeros or circular) done
//! inside the op, the coefficients scale the output rows, and the backward takes seven passes
//! over the map where candle's broadcast products took about seventeen. Inside
//! [`photomat_kernels::with_reference_ops`] the plain-candle formulation (broadcast products,
//! explicit padding, candle's `conv2d`) computes the same values.
//!
//! ε = 1e-8 as in StyleGAN2 (eq. 3): it only matters when a sample's styles of a layer are all
//! ≈ 0, where it keeps `d` finite (≤ 10⁴) instead of dividing by zero; with unit-variance
//! weights and styles ≈ 1 the sum is ≈ C_in·k², ≥ 1 for every layer here, so ε changes d by
//! less than 1e-8 relative in normal operation.
//!
//! The toFeature layers use the same operation without demodulation, their styles scaled by
//! `1/√(C_in·k²)` (StyleGAN2's `ToRGBLayer` weight gain). Parameter names under the layer's
//! `vb`: `affine.weight` (C_in, w_dim), `affine.bias` (C_in), `weight` (C_out, C_in, k, k).

use candle_core::{D, Result, Tensor, bail};
use candle_nn::{Init, VarBuilder};

use crate::equalized::{EqualizedLinear, LinearConfig, equalized_linear};
use crate::padding::{Padding, pad2d};

/// Demodulation ε (StyleGAN2 eq. 3; justified in the module docs).
pub const DEMOD_EPS: f64 = 1e-8;

/// A modulated k×k convolution (k odd), stride 1, "same" padding.
#[derive(Debug, Clone)]
pub struct ModulatedConv2d {
    affine: EqualizedLinear,
    weight: Tensor,
    demodulate: bool,
    style_gain: f64,
    padding: Padding,
}

/// Builds a [`ModulatedConv2d`] from `w_dim`-dimensional styles. With `demodulate` false the
/// styles are scaled by `1/√(C_in·k²)` (toFeature layers).
pub fn modulated_conv2d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    w_dim: usize,
    demodulate: bool,
    padding: Padding,
    vb: VarBuilder,
) -> Result<ModulatedConv2d> {
    if kernel % 2 != 1 {
        bail!("modulated conv: kernel {kernel} must be odd to keep the size");
    }
    let affine = equalized_linear(
        w_dim,
        in_channels,
        LinearConfig {
            bias_init: 1.0,
            ..Default::default()
        },
        vb.pp("affine"),
    )?;
    let weight = vb.get_with_hints(
        (out_channels, in_channels, kernel, kernel),
        "weight",
        Init::Randn {
            mean: 0.0,
            stdev: 1.0,
        },
    )?;
    let style_gain = if demodulate {
        1.0
    } else {
        1.0 / ((in_channels * kernel * kernel) as f64).sqrt()
    };
    Ok(ModulatedConv2d {
        affine,
        weight,
        demodulate,
        style_gain,
        padding,
    })
}

impl ModulatedConv2d {
    /// Per-sample styles `s = A(w) · gain`.
    ///
    /// # Shapes
    /// (B, w_dim) → (B, C_in).
    pub fn styles(&self, w: &Tensor) -> Result<Tensor> {
        self.affine.forward(w)?.affine(self.style_gain, 0.0)
    }

    /// Demodulation coefficients `d = rsqrt((s ⊙ s) · (Σ_k W²)ᵀ + ε)`.
    ///
    /// # Shapes
    /// styles (B, C_in) → (B, C_out).
    pub fn demodulation(&self, styles: &Tensor) -> Result<Tensor> {
        let (c_out, c_in, _, _) = self.weight.dims4()?;
        let w2 = self
            .weight
            .sqr()?
            .reshape((c_out, c_in, ()))?
            .sum(D::Minus1)?;
        let energy = styles.sqr()?.matmul(&w2.t()?)?;
        (energy + DEMOD_EPS)?.sqrt()?.recip()
    }

    /// # Shapes
    /// x (B, C_in, H, W), w (B, w_dim) → (B, C_out, H, W).
    pub fn forward(&self, x: &Tensor, w: &Tensor) -> Result<Tensor> {
        let (b, c_in, _h, _w) = x.dims4()?;
        let (bw, _) = w.dims2()?;
        if bw != b {
            bail!("modulated conv: {bw} styles for a batch of {b}");
        }
        let styles = self.styles(w)?;
        let k = self.weight.dims()[2];
        if photomat_kernels::reference_ops() {
            // The plain-candle formulation: broadcast products, explicit padding, candle's
            // conv2d.
            let x = x.broadcast_mul(&styles.reshape((b, c_in, 1, 1))?)?;
            let y = pad2d(&x, k / 2, self.padding)?.conv2d(&self.weight, 0, 1, 1, 1)?;
            return if self.demodulate {
                let d = self.demodulation(&styles)?;
                y.broadcast_mul(&d.reshape((b, (), 1, 1))?)
            } else {
                Ok(y)
            };
        }
        let scales = if self.demodulate {
            Tensor::cat(&[&styles, &self.demodulation(&styles)?], 1)?
        } else {
            styles
        };
        let spec = photomat_kernels::Conv2dSpec {
            stride: 1,
            padding: k / 2,
            mode: self.padding.into(),
        };
        photomat_kernels::modulated_conv2d(x, &self.weight, &scales, self.demodulate, spec)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    use super::*;
    use crate::seeded_uniform;

    #[test]
    fn modulated_conv_equals_per_sample_weights() -> Result<()> {
        // Reference: build w' = s·W per sample, demodulate it explicitly and convolve each
        // sample alone (StyleGAN2's fused/grouped formulation).
        let dev = Device::Cpu;
        let vm = VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F64, &dev);
        let conv = modulated_conv2d(3, 4, 3, 8, true, Padding::Zeros, vb)?;
        let x = seeded_uniform((2, 3, 5, 6), 1, DType::F64, &dev)?;
        let w = seeded_uniform((2, 8), 2, DType::F64, &dev)?;
        let y = conv.forward(&x, &w)?;
        let styles = conv.styles(&w)?;
        for bi in 0..2 {
            let s = styles.get(bi)?.reshape((1, 3, 1, 1))?;
            let wp = conv.weight.broadcast_mul(&s)?;
            let d = (wp.sqr()?.sum_keepdim((1, 2, 3))? + DEMOD_EPS)?
                .sqrt()?
                .recip()?;
            let wp = wp.broadcast_mul(&d)?;
            let expected = x.get(bi)?.unsqueeze(0)?.conv2d(&wp, 1, 1, 1, 1)?;
            let got = y.get(bi)?.unsqueeze(0)?;
            let diff = (got - expected)?.abs()?.max_all()?.to_scalar::<f64>()?;
            // f64 sums of 27 products in another order.
            assert!(diff < 1e-12, "sample {bi}: {diff}");
        }
        Ok(())
    }
}
