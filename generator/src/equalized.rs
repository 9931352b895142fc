//! Equalised-learning-rate layers (Karras et al. 2018, ProGAN §4.1; StyleGAN2-ADA's
//! `FullyConnectedLayer` and `Conv2dLayer`).
//!
//! Weights are stored as N(0, 1/λ²) samples, λ being the layer's learning-rate multiplier,
//! and scaled at run time by `λ/√fan_in`: the effective weight starts as N(0, 1/fan_in) (He
//! initialisation) while Adam, whose steps are invariant to the parameter's scale, moves every
//! effective weight at the same relative speed, multiplied by λ. Biases are stored as their
//! initial value b₀ and scaled by λ (so the effective initial bias is λ·b₀, exactly as in
//! StyleGAN2-ADA: the mapping uses b₀ = 0, the affine style layers b₀ = 1 with λ = 1).
//!
//! Parameter names under the layer's `vb`: `weight`, `bias`.

use candle_core::{Result, Tensor, bail};
use candle_nn::{Init, VarBuilder};

use crate::activation::{bias_lrelu, lrelu};
use crate::padding::{Padding, pad2d};

/// Options of an [`EqualizedLinear`] layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinearConfig {
    /// Learning-rate multiplier λ. Default 1.
    pub lr_multiplier: f64,
    /// Stored initial bias b₀ (effective initial bias λ·b₀). Default 0.
    pub bias_init: f64,
    /// Whether the layer has a bias. Default true.
    pub bias: bool,
}

impl Default for LinearConfig {
    fn default() -> Self {
        Self {
            lr_multiplier: 1.0,
            bias_init: 0.0,
            bias: true,
        }
    }
}

/// Fully connected layer with equalised learning rate: `y = x·(λ/√in · W)ᵀ + λ·b`.
#[derive(Debug, Clone)]
pub struct EqualizedLinear {
    weight: Tensor,
    bias: Option<Tensor>,
    weight_gain: f64,
    bias_gain: f64,
}

/// Builds an [`EqualizedLinear`] with `weight` (out, in) and `bias` (out) under `vb`.
pub fn equalized_linear(
    in_features: usize,
    out_features: usize,
    cfg: LinearConfig,
    vb: VarBuilder,
) -> Result<EqualizedLinear> {
    if !(cfg.lr_multiplier.is_finite() && cfg.lr_multiplier > 0.0) {
        bail!(
            "learning-rate multiplier {} must be positive",
            cfg.lr_multiplier
        );
    }
    let weight = vb.get_with_hints(
        (out_features, in_features),
        "weight",
        Init::Randn {
            mean: 0.0,
            stdev: 1.0 / cfg.lr_multiplier,
        },
    )?;
    let bias = if cfg.bias {
        Some(vb.get_with_hints(out_features, "bias", Init::Const(cfg.bias_init))?)
    } else {
        None
    };
    Ok(EqualizedLinear {
        weight,
        bias,
        weight_gain: cfg.lr_multiplier / (in_features as f64).sqrt(),
        bias_gain: cfg.lr_multiplier,
    })
}

impl EqualizedLinear {
    /// # Shapes
    /// (N, in) → (N, out).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (_n, _in) = x.dims2()?;
        let w = self.weight.affine(self.weight_gain, 0.0)?;
        let y = x.matmul(&w.t()?)?;
        match &self.bias {
            Some(b) => y.broadcast_add(&b.affine(self.bias_gain, 0.0)?),
            None => Ok(y),
        }
    }

    /// `lrelu(forward(x))` with the bias add fused into the activation
    /// ([`crate::activation::bias_lrelu`]).
    ///
    /// # Shapes
    /// (N, in) → (N, out).
    pub fn forward_lrelu(&self, x: &Tensor) -> Result<Tensor> {
        let (_n, _in) = x.dims2()?;
        let y = x.matmul(&self.weight.affine(self.weight_gain, 0.0)?.t()?)?;
        match &self.bias {
            Some(b) => bias_lrelu(&y, &b.affine(self.bias_gain, 0.0)?),
            None => lrelu(&y),
        }
    }

    /// The layer as photomat-kernels' fused per-texel MLP takes it (stored weight and bias
    /// with their run-time gains); `None` for a layer without a bias.
    pub fn mlp_layer(&self) -> Option<photomat_kernels::MlpLayer<'_>> {
        Some(photomat_kernels::MlpLayer {
            weight: &self.weight,
            bias: self.bias.as_ref()?,
            weight_gain: self.weight_gain,
            bias_gain: self.bias_gain,
        })
    }

    /// Number of input features.
    pub fn in_features(&self) -> usize {
        self.weight.dims()[1]
    }

    /// Number of output features.
    pub fn out_features(&self) -> usize {
        self.weight.dims()[0]
    }
}

/// A k×k convolution with equalised learning rate (λ = 1): `weight` (out, in, k, k) ~ N(0, 1)
/// scaled by `1/√(in·k²)`, optional `bias` (out) initialised to 0. Padding and resampling are
/// done by the caller ([`crate::discriminator`]); [`EqualizedConv2d::forward`] pads by k/2.
#[derive(Debug, Clone)]
pub struct EqualizedConv2d {
    weight: Tensor,
    bias: Option<Tensor>,
    weight_gain: f64,
}

/// Builds an [`EqualizedConv2d`] under `vb`.
pub fn equalized_conv2d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    bias: bool,
    vb: VarBuilder,
) -> Result<EqualizedConv2d> {
    let weight = vb.get_with_hints(
        (out_channels, in_channels, kernel, kernel),
        "weight",
        Init::Randn {
            mean: 0.0,
            stdev: 1.0,
        },
    )?;
    let bias = if bias {
        Some(vb.get_with_hints(out_channels, "bias", Init::Const(0.0))?)
    } else {
        None
    };
    Ok(EqualizedConv2d {
        weight,
        bias,
        weight_gain: 1.0 / ((in_channels * kernel * kernel) as f64).sqrt(),
    })
}

impl EqualizedConv2d {
    /// Kernel side k.
    pub fn kernel(&self) -> usize {
        self.weight.dims()[2]
    }

    /// Convolution with `padding` texels of the given mode on every side, without bias:
    /// photomat-kernels' im2col + gemm [`conv2d`](photomat_kernels::conv2d), differentiable
    /// to any order (R1 through D), or explicit padding and candle's `conv2d` inside
    /// [`photomat_kernels::with_reference_ops`].
    ///
    /// # Shapes
    /// (B, in, H, W) → (B, out, (H + 2·padding − k)/stride + 1, likewise W).
    pub fn conv(&self, x: &Tensor, stride: usize, padding: usize, mode: Padding) -> Result<Tensor> {
        self.conv_times(x, stride, padding, mode, 1.0)
    }

    /// [`Self::conv`] times `gain`, folded into the (small) weight tensor rather than applied
    /// to the (large) output: a linear layer's output gain for the price of none.
    ///
    /// # Shapes
    /// As [`Self::conv`].
    pub fn conv_times(
        &self,
        x: &Tensor,
        stride: usize,
        padding: usize,
        mode: Padding,
        gain: f64,
    ) -> Result<Tensor> {
        let (_b, _c, _h, _w) = x.dims4()?;
        let w = self.weight.affine(self.weight_gain * gain, 0.0)?;
        if photomat_kernels::reference_ops() {
            return pad2d(x, padding, mode)?.conv2d(&w, 0, stride, 1, 1);
        }
        let spec = photomat_kernels::Conv2dSpec {
            stride,
            padding,
            mode: mode.into(),
        };
        photomat_kernels::conv2d(x, &w, spec)
    }

    /// The weight as the layer applies it (stored weight × its run-time gain).
    ///
    /// # Shapes
    /// → (out, in, k, k).
    pub fn effective_weight(&self) -> Result<Tensor> {
        self.weight.affine(self.weight_gain, 0.0)
    }

    /// The bias (`None` for a layer without one), shape (out).
    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    /// Adds the bias (if any) per channel.
    ///
    /// # Shapes
    /// (B, out, H, W) → (B, out, H, W).
    pub fn add_bias(&self, y: &Tensor) -> Result<Tensor> {
        match &self.bias {
            Some(b) => photomat_kernels::add_channel_bias(y, b),
            None => Ok(y.clone()),
        }
    }

    /// Stride-1 "same" convolution with padding k/2 of the given mode, plus bias.
    ///
    /// # Shapes
    /// (B, in, H, W) → (B, out, H, W) for odd k.
    pub fn forward(&self, x: &Tensor, mode: Padding) -> Result<Tensor> {
        let y = self.conv(x, 1, self.kernel() / 2, mode)?;
        self.add_bias(&y)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    use super::*;

    #[test]
    fn equalized_linear_scales_weights_and_bias() -> Result<()> {
        let vm = VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F64, &Device::Cpu);
        let cfg = LinearConfig {
            lr_multiplier: 0.01,
            bias_init: 2.0,
            bias: true,
        };
        let layer = equalized_linear(4, 3, cfg, vb.pp("fc"))?;
        // Stored weights ~ N(0, 1/λ²): std ≈ 100 (12 samples, loosely checked).
        let stored = vm.data().lock().expect("lock")["fc.weight"]
            .as_tensor()
            .clone();
        let std = stored.sqr()?.mean_all()?.to_scalar::<f64>()?.sqrt();
        assert!(std > 20.0 && std < 400.0, "stored std {std}");
        // y = x (λ/√4 W)ᵀ + λ b₀: with x = e₀, column 0 of the effective weight plus 0.02.
        let x = Tensor::new(&[[1.0f64, 0., 0., 0.]], &Device::Cpu)?;
        let y = layer.forward(&x)?.squeeze(0)?.to_vec1::<f64>()?;
        let col0 = stored.narrow(1, 0, 1)?.squeeze(1)?.to_vec1::<f64>()?;
        for (a, w) in y.iter().zip(col0) {
            let expected = w * 0.01 / 2.0 + 0.02;
            assert!((a - expected).abs() < 1e-12, "{a} vs {expected}");
        }
        Ok(())
    }
}
