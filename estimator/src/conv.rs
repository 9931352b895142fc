//! Convolution layers with circular padding (the reference's `CircularConv2d`, what the
//! estimator uses on periodic materials) or zero padding (what networks on photos use, such as
//! the relief prior), one layer type for both ([`Conv2dLayer`]).
//!
//! PhotoMat's estimator (paper §4 "Implementation"; reference `training/networks.py`,
//! `CircularConv2d`) pads every convolution's input by wrapping around and then convolves
//! without padding. Here the parameters live in candle-nn's [`Conv2d`] (`padding = 0`); the
//! convolution is [`photomat_kernels::conv2d`] with circular padding, which reads the wrapped
//! texels inside its im2col instead of building a padded copy (the same values as
//! [`crate::circular_pad()`] followed by an unpadded conv). Forward + backward of E's layers
//! got 2.0–5.0× faster than with candle's `conv2d` and the polyphase backward
//! (`docs/benchmarks/conv-kernels.md`, "Estimator layers").
//!
//! Each layer keeps the size up to its stride ("same" convolution on the torus): a `k × k`
//! kernel with stride `s` is padded by `(k − s)/2` on every side, so (H, W) → (H/s, W/s).
//! Output texel `(i, j)` then reads input rows `s·i − (k − s)/2 …` and commutes with rolls by
//! multiples of `s`: `conv(roll(x, s·t)) = roll(conv(x), t)`.
//!
//! Initialisation follows the reference's `weights_init`: Xavier-normal weights
//! (σ = √(2 / ((C_in + C_out)·k²))) and biases drawn from N(0, 0.02²).

use candle_core::{Result, Tensor, bail};
use candle_nn::{Conv2d, Conv2dConfig, Init, Module, VarBuilder};

use photomat_kernels::{Conv2dSpec, PaddingMode, conv2d};

/// Standard deviation of the initial biases (the reference's `bias.data.normal_(0, 0.02)`).
const BIAS_INIT_STD: f64 = 0.02;

/// A `k × k` "same" convolution with stride `s`, padded circularly (a periodic image) or with
/// zeros.
#[derive(Debug, Clone)]
pub struct Conv2dLayer {
    conv: Conv2d,
    pad: usize,
    stride: usize,
    mode: PaddingMode,
}

/// The estimator's layer: a [`Conv2dLayer`] with circular padding.
pub type CircularConv2d = Conv2dLayer;

/// Builds a [`CircularConv2d`] with parameters `weight` (C_out, C_in, k, k) and `bias`
/// (C_out) under `vb`.
///
/// `kernel − stride` must be even and ≥ 0 so that the padding is symmetric and the layer maps
/// (H, W) to exactly (H/stride, W/stride).
pub fn circular_conv2d(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    stride: usize,
    vb: VarBuilder,
) -> Result<CircularConv2d> {
    conv2d_layer(
        in_channels,
        out_channels,
        kernel,
        stride,
        PaddingMode::Circular,
        vb,
    )
}

/// Builds a [`Conv2dLayer`] padded by `mode`, with parameters `weight` (C_out, C_in, k, k) and
/// `bias` (C_out) under `vb`; as [`circular_conv2d`] otherwise.
pub fn conv2d_layer(
    in_channels: usize,
    out_channels: usize,
    kernel: usize,
    stride: usize,
    mode: PaddingMode,
    vb: VarBuilder,
) -> Result<Conv2dLayer> {
    if stride == 0 || kernel < stride || !(kernel - stride).is_multiple_of(2) {
        bail!(
            "circular conv: kernel {kernel} with stride {stride} cannot keep the size \
             (need kernel ≥ stride ≥ 1 and kernel − stride even)"
        );
    }
    let fan = ((in_channels + out_channels) * kernel * kernel) as f64;
    let weight = vb.get_with_hints(
        (out_channels, in_channels, kernel, kernel),
        "weight",
        Init::Randn {
            mean: 0.0,
            stdev: (2.0 / fan).sqrt(),
        },
    )?;
    let bias = vb.get_with_hints(
        out_channels,
        "bias",
        Init::Randn {
            mean: 0.0,
            stdev: BIAS_INIT_STD,
        },
    )?;
    let cfg = Conv2dConfig {
        padding: 0,
        stride,
        ..Default::default()
    };
    Ok(Conv2dLayer {
        conv: Conv2d::new(weight, Some(bias), cfg),
        pad: (kernel - stride) / 2,
        stride,
        mode,
    })
}

impl Conv2dLayer {
    /// The wrapped candle-nn convolution (padding 0).
    pub fn conv(&self) -> &Conv2d {
        &self.conv
    }

    /// Circular padding applied on every side before the convolution.
    pub fn pad(&self) -> usize {
        self.pad
    }
}

impl Conv2dLayer {
    /// The convolution without its bias.
    ///
    /// # Shapes
    /// (B, C_in, H, W) → (B, C_out, H/s, W/s); H and W must be multiples of the stride s.
    fn convolve(&self, x: &Tensor) -> Result<Tensor> {
        let (_b, _c, h, w) = x.dims4()?;
        if h % self.stride != 0 || w % self.stride != 0 {
            bail!(
                "conv layer with stride {}: input {h}×{w} is not a multiple of the stride",
                self.stride
            );
        }
        let spec = Conv2dSpec {
            stride: self.stride,
            padding: self.pad,
            mode: self.mode,
        };
        conv2d(x, self.conv.weight(), spec)
    }

    /// `LeakyReLU(conv(x) + bias, slope)`, the bias and the activation as one fused pass each
    /// way ([`photomat_kernels::bias_leaky_relu_gain`]): the same value as
    /// `leaky_relu(&self.forward(x)?, slope)` without the broadcast addition, whose backward
    /// sums the gradient over the batch and the texels in a slow strided reduction.
    ///
    /// # Shapes
    /// As [`Module::forward`].
    pub fn forward_leaky_relu(&self, x: &Tensor, slope: f64) -> Result<Tensor> {
        let y = self.convolve(x)?;
        match self.conv.bias() {
            Some(bias) => photomat_kernels::bias_leaky_relu_gain(&y, bias, slope, 1.0),
            None => photomat_kernels::leaky_relu(&y, slope),
        }
    }
}

impl Module for Conv2dLayer {
    /// # Shapes
    /// (B, C_in, H, W) → (B, C_out, H/s, W/s); H and W must be multiples of the stride s.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let y = self.convolve(x)?;
        match self.conv.bias() {
            Some(bias) => photomat_kernels::add_channel_bias(&y, bias),
            None => Ok(y),
        }
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    use super::*;
    use crate::test_util::{max_abs_diff, pseudo_random};

    /// A layer with fresh random weights (f64 so that comparisons are tight).
    fn layer(c_in: usize, c_out: usize, k: usize, s: usize) -> Result<CircularConv2d> {
        let vm = VarMap::new();
        circular_conv2d(
            c_in,
            c_out,
            k,
            s,
            VarBuilder::from_varmap(&vm, DType::F64, &Device::Cpu),
        )
    }

    /// Reference: convolve the 3 × 3 tiling of `x` without padding and crop the window that
    /// corresponds to the centre tile. Independent of `circular_pad`.
    fn tiled_reference(layer: &CircularConv2d, x: &Tensor) -> Result<Tensor> {
        let (_, _, h, w) = x.dims4()?;
        let row = Tensor::cat(&[x, x, x], 3)?;
        let tiled = Tensor::cat(&[&row, &row, &row], 2)?;
        let p = layer.pad();
        let s = layer.conv().config().stride;
        let window = tiled
            .narrow(2, h - p, h + 2 * p)?
            .narrow(3, w - p, w + 2 * p)?;
        let y = window.conv2d(layer.conv().weight(), 0, s, 1, 1)?;
        let bias = layer.conv().bias().expect("layer has a bias");
        y.broadcast_add(&bias.reshape((1, (), 1, 1))?)
    }

    #[test]
    fn circular_conv_equals_conv_of_the_tiled_input() -> Result<()> {
        for (k, s) in [(3, 1), (4, 2)] {
            let conv = layer(3, 5, k, s)?;
            let x = pseudo_random((2, 3, 8, 12), 1, DType::F64, &Device::Cpu)?;
            let y = conv.forward(&x)?;
            assert_eq!(y.dims4()?, (2, 5, 8 / s, 12 / s));
            // Same products summed in the same order on identical windows: rounding-level
            // differences at most (f64, ≤ 48-term dot products).
            assert!(max_abs_diff(&y, &tiled_reference(&conv, &x)?)? < 1e-12);
        }
        Ok(())
    }

    #[test]
    fn circular_conv_commutes_with_roll_by_stride_multiples() -> Result<()> {
        let conv = layer(2, 4, 4, 2)?;
        let x = pseudo_random((1, 2, 8, 8), 2, DType::F64, &Device::Cpu)?;
        let a = conv.forward(&x.roll(4, 2)?.roll(-2, 3)?)?;
        let b = conv.forward(&x)?.roll(2, 2)?.roll(-1, 3)?;
        assert!(max_abs_diff(&a, &b)? < 1e-12);
        Ok(())
    }

    #[test]
    fn circular_conv_keeps_periodic_input_periodic_where_zero_padding_does_not() -> Result<()> {
        // A 2 × 2 tiling of one 4 × 4 tile is periodic with period 4. Circular padding keeps
        // the output periodic; the same weights with zero padding see a black border and
        // break the period (the control that makes this test meaningful).
        let conv = layer(2, 3, 3, 1)?;
        let tile = pseudo_random((1, 2, 4, 4), 3, DType::F64, &Device::Cpu)?;
        let row = Tensor::cat(&[&tile, &tile], 3)?;
        let x = Tensor::cat(&[&row, &row], 2)?;
        let period_error = |y: &Tensor| -> Result<f64> {
            Ok(max_abs_diff(y, &y.roll(4, 2)?)?.max(max_abs_diff(y, &y.roll(4, 3)?)?))
        };
        assert!(period_error(&conv.forward(&x)?)? < 1e-12);
        let zero_padded = Conv2d::new(
            conv.conv().weight().clone(),
            conv.conv().bias().cloned(),
            Conv2dConfig {
                padding: 1,
                ..Default::default()
            },
        );
        // Border texels lose ≥ 3 of 9 taps of O(1) inputs with O(0.1) weights.
        assert!(period_error(&zero_padded.forward(&x)?)? > 1e-3);
        Ok(())
    }

    #[test]
    fn circular_conv_gradients_match_circular_pad_then_candle_conv() -> Result<()> {
        // The layer's gradients (photomat-kernels' backward) against candle's backward of
        // the documented composition circular_pad + unpadded conv2d. f64 sums of ≤ 2·3·16·32
        // O(1) products in another order: rounding ≲ 1e-13.
        use candle_core::Var;
        for (k, s) in [(3, 1), (4, 2)] {
            let conv = layer(3, 5, k, s)?;
            let x = Var::from_tensor(&pseudo_random((2, 3, 8, 12), 4, DType::F64, &Device::Cpu)?)?;
            let w = conv.conv().weight();
            let g = pseudo_random((2, 5, 8 / s, 12 / s), 5, DType::F64, &Device::Cpu)?;
            let ours = (conv.forward(x.as_tensor())? * &g)?.sum_all()?.backward()?;
            let padded = crate::circular_pad(x.as_tensor(), conv.pad())?;
            let reference = (padded.conv2d(w, 0, s, 1, 1)? * &g)?
                .sum_all()?
                .backward()?;
            for t in [x.as_tensor(), w] {
                let (a, b) = (
                    ours.get(t).expect("gradient"),
                    reference.get(t).expect("gradient"),
                );
                assert!(max_abs_diff(a, b)? < 1e-10, "k{k} s{s}");
            }
        }
        Ok(())
    }

    #[test]
    fn fused_leaky_relu_forward_equals_the_layer_then_the_activation() -> Result<()> {
        let vm = VarMap::new();
        let conv = circular_conv2d(
            3,
            4,
            3,
            1,
            VarBuilder::from_varmap(&vm, DType::F64, &Device::Cpu),
        )?;
        let x = pseudo_random((2, 3, 6, 8), 7, DType::F64, &Device::Cpu)?;
        let g = pseudo_random((2, 4, 6, 8), 8, DType::F64, &Device::Cpu)?;
        let fused = conv.forward_leaky_relu(&x, 0.01)?;
        let separate = crate::leaky_relu(&conv.forward(&x)?, 0.01)?;
        // The same sums in the same order, the bias added once: rounding-level differences.
        assert!(max_abs_diff(&fused, &separate)? < 1e-12);
        let a = (fused * &g)?.sum_all()?.backward()?;
        let b = (separate * &g)?.sum_all()?.backward()?;
        let bias = conv.conv().bias().expect("layer has a bias");
        for t in [conv.conv().weight(), bias] {
            let (a, b) = (a.get(t).expect("gradient"), b.get(t).expect("gradient"));
            // f64 sums of ≤ 96 products of O(1) values in another order.
            assert!(max_abs_diff(a, b)? < 1e-10);
        }
        Ok(())
    }

    #[test]
    fn circular_conv_rejects_sizes_it_cannot_keep() -> Result<()> {
        let vm = VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu);
        assert!(circular_conv2d(1, 1, 4, 1, vb.pp("a")).is_err()); // k − s = 3: odd
        let conv = circular_conv2d(1, 1, 4, 2, vb.pp("b"))?;
        let err = conv
            .forward(&Tensor::zeros((1, 1, 6, 5), DType::F32, &Device::Cpu)?)
            .expect_err("5 is odd")
            .to_string();
        assert!(err.contains("not a multiple of the stride"), "{err}");
        Ok(())
    }
}
