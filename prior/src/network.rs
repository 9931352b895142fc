//! The relief prior's network: a UNet from a flash photo to material maps with one encoder and
//! **two decoders**, one for the colour maps (diffuse, specular, roughness) and one for the
//! relief (a height), after Deschaintre et al. 2018 ("Single-image SVBRDF capture with a
//! rendering-aware deep network", §4: a UNet with skip connections from photo to maps) and the
//! failure its successors report for a single decoder: the highlight and the flash's falloff
//! baked into the diffuse map while the normals stay flat. Separate decoders give the relief
//! features of its own at every scale (docs/neural-models.md, "Relief prior").
//!
//! ```text
//! input (B, 5, H, W): photo (3, linear, over its mean) ‖ offset from the flash (2)
//!  enc_k: 4×4/2 conv, 3×3 conv             k = 0 … L−1, widths encoder_channels
//!  per decoder (colour, relief):
//!  dec_k: up ×2, cat enc_{L−2−k}, 3×3, 3×3  widths decoder_channels
//!  head:  up ×2, 3×3 conv → colour raw (B, n_c, H, W) | height (B, 1, H, W)
//! ```
//!
//! Every conv but the heads is followed by LeakyReLU (slope 0.2), pads with zeros (a photo does
//! not wrap around) and upsampling repeats the border texel ([`upsample2x_clamped`]), so the
//! network is fully convolutional: it runs at any side that is a multiple of its total
//! stride `2^L` (trained on 256² crops, run at 512²–1024²). The colour head's outputs are the
//! model's raw (pre-decoding) values, decoded by its [`photomat_core::ParamSpec`]s; the relief
//! head's is a height in units of [`HEIGHT_UNIT`] world units.

use candle_core::{Result, Tensor, bail};
use candle_nn::VarBuilder;
use photomat_estimator::conv::{Conv2dLayer, conv2d_layer};
use photomat_estimator::upsample::upsample2x_clamped;
use photomat_kernels::PaddingMode;
use serde::{Deserialize, Serialize};

/// Kernel of the encoder's down-sampling convs (4×4, stride 2, as the estimator's).
const DOWN_KERNEL: usize = 4;
/// Kernel of every other conv.
const KERNEL: usize = 3;
/// Input channels: the photo's RGB and the texel's offset from the flash (x, y).
pub const INPUT_CHANNELS: usize = 5;
/// World units of a relief output of 1: the library's reliefs span 0.03–0.14 (median per
/// package) on the photo's square of side 2, so heights of order 1 are what the head outputs.
pub const HEIGHT_UNIT: f64 = 0.01;
/// Most encoder levels: 2¹⁰ texels per side is the largest photo a capture fits at.
const MAX_LEVELS: usize = 10;
/// Most channels of a conv.
pub const MAX_CHANNELS: usize = 1024;

/// Architecture of [`PriorNet`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorConfig {
    /// Widths of the encoder levels, each halving the side. Default `[24, 48, 96, 128, 160]`
    /// (total stride 32: a 256² crop reaches an 8² bottleneck whose texels each see the
    /// whole crop).
    pub encoder_channels: Vec<usize>,
    /// Widths of each decoder's levels with a skip, coarse to fine (one fewer than the
    /// encoder's). Default `[128, 96, 48, 24]`.
    pub decoder_channels: Vec<usize>,
    /// Raw colour channels: the model's maps other than the relief (`height(ggx)`: diffuse 3,
    /// specular 3, roughness 1 = 7).
    pub colour_channels: usize,
    /// Negative slope of the LeakyReLUs. Default 0.2.
    pub leaky_slope: f64,
}

impl PriorConfig {
    /// The default architecture for `colour_channels` raw colour channels.
    pub fn new(colour_channels: usize) -> Self {
        Self {
            encoder_channels: vec![24, 48, 96, 128, 160],
            decoder_channels: vec![128, 96, 48, 24],
            colour_channels,
            leaky_slope: 0.2,
        }
    }

    /// Factor the input side must be a multiple of: 2^(encoder levels).
    pub fn total_stride(&self) -> usize {
        1 << self.encoder_channels.len()
    }

    /// Checks the configuration, naming the field.
    pub fn validate(&self) -> Result<()> {
        let (enc, dec) = (&self.encoder_channels, &self.decoder_channels);
        if enc.is_empty() || enc.len() > MAX_LEVELS {
            bail!(
                "prior config: {} encoder levels (give 1 … {MAX_LEVELS})",
                enc.len()
            );
        }
        if dec.len() + 1 != enc.len() {
            bail!(
                "prior config: {} encoder levels need {} decoder levels, got {}",
                enc.len(),
                enc.len() - 1,
                dec.len()
            );
        }
        if let Some(c) = enc
            .iter()
            .chain(dec)
            .chain([&self.colour_channels])
            .find(|&&c| c == 0 || c > MAX_CHANNELS)
        {
            bail!("prior config: a channel count of {c} is outside 1 … {MAX_CHANNELS}");
        }
        if !(0.0..=1.0).contains(&self.leaky_slope) {
            bail!(
                "prior config: leaky_slope {} is outside [0, 1]",
                self.leaky_slope
            );
        }
        Ok(())
    }

    /// Trainable scalars of the network.
    pub fn num_parameters(&self) -> usize {
        let conv = |c_in: usize, c_out: usize, k: usize| c_out * c_in * k * k + c_out;
        let enc = &self.encoder_channels;
        let mut total = 0;
        let mut c = INPUT_CHANNELS;
        for &e in enc {
            total += conv(c, e, DOWN_KERNEL) + conv(e, e, KERNEL);
            c = e;
        }
        for out in [self.colour_channels, 1] {
            let mut c = *enc.last().unwrap_or(&0);
            for (i, &d) in self.decoder_channels.iter().enumerate() {
                total += conv(c + enc[enc.len() - 2 - i], d, KERNEL) + conv(d, d, KERNEL);
                c = d;
            }
            total += conv(c, out, KERNEL);
        }
        total
    }
}

/// A zero-padded "same" convolution of the prior.
fn layer(
    c_in: usize,
    c_out: usize,
    kernel: usize,
    stride: usize,
    vb: VarBuilder,
) -> Result<Conv2dLayer> {
    conv2d_layer(c_in, c_out, kernel, stride, PaddingMode::Zeros, vb)
}

/// One decoder: its levels and its head.
#[derive(Debug, Clone)]
struct Decoder {
    levels: Vec<(Conv2dLayer, Conv2dLayer)>,
    head: Conv2dLayer,
}

impl Decoder {
    fn new(config: &PriorConfig, out: usize, vb: VarBuilder) -> Result<Self> {
        let enc = &config.encoder_channels;
        let mut c = *enc.last().unwrap_or(&1);
        let mut levels = Vec::new();
        for (i, &d) in config.decoder_channels.iter().enumerate() {
            let skip = enc[enc.len() - 2 - i];
            let level = vb.pp(format!("level{i}"));
            levels.push((
                layer(c + skip, d, KERNEL, 1, level.pp("conv1"))?,
                layer(d, d, KERNEL, 1, level.pp("conv2"))?,
            ));
            c = d;
        }
        Ok(Self {
            levels,
            head: layer(c, out, KERNEL, 1, vb.pp("head"))?,
        })
    }

    /// The decoder over the encoder's outputs `skips` (finest first, the bottleneck last).
    fn forward(&self, skips: &[Tensor], slope: f64) -> Result<Tensor> {
        let mut x = skips[skips.len() - 1].clone();
        for (i, (conv1, conv2)) in self.levels.iter().enumerate() {
            let skip = &skips[skips.len() - 2 - i];
            x = Tensor::cat(&[&upsample2x_clamped(&x)?, skip], 1)?;
            x = conv1.forward_leaky_relu(&x, slope)?;
            x = conv2.forward_leaky_relu(&x, slope)?;
        }
        candle_core::Module::forward(&self.head, &upsample2x_clamped(&x)?)
    }
}

/// The prior network (module docs).
#[derive(Debug, Clone)]
pub struct PriorNet {
    config: PriorConfig,
    encoder: Vec<(Conv2dLayer, Conv2dLayer)>,
    colour: Decoder,
    relief: Decoder,
}

/// What the network outputs for a batch.
#[derive(Debug, Clone)]
pub struct PriorOutput {
    /// Raw colour channels (B, n_c, H, W), decoded by the model's specs.
    pub colour: Tensor,
    /// Heights in world units (B, 1, H, W).
    pub height: Tensor,
}

impl PriorNet {
    /// The network of `config` with parameters under `vb` (`encoder.*`, `colour.*`,
    /// `relief.*`).
    pub fn new(config: &PriorConfig, vb: VarBuilder) -> Result<Self> {
        config.validate()?;
        let mut encoder = Vec::new();
        let mut c = INPUT_CHANNELS;
        for (k, &e) in config.encoder_channels.iter().enumerate() {
            let level = vb.pp(format!("encoder.level{k}"));
            encoder.push((
                layer(c, e, DOWN_KERNEL, 2, level.pp("down"))?,
                layer(e, e, KERNEL, 1, level.pp("conv"))?,
            ));
            c = e;
        }
        Ok(Self {
            colour: Decoder::new(config, config.colour_channels, vb.pp("colour"))?,
            relief: Decoder::new(config, 1, vb.pp("relief"))?,
            encoder,
            config: config.clone(),
        })
    }

    pub fn config(&self) -> &PriorConfig {
        &self.config
    }

    /// The maps' raw outputs for input `x` (B, 5, H, W), H and W multiples of the total
    /// stride.
    pub fn forward(&self, x: &Tensor) -> Result<PriorOutput> {
        let (_, c, h, w) = x.dims4()?;
        let stride = self.config.total_stride();
        if c != INPUT_CHANNELS || !h.is_multiple_of(stride) || !w.is_multiple_of(stride) {
            bail!(
                "the prior reads ({INPUT_CHANNELS}, H, W) inputs with H and W multiples of \
                 {stride}, got ({c}, {h}, {w})"
            );
        }
        let slope = self.config.leaky_slope;
        let mut skips = Vec::with_capacity(self.encoder.len());
        let mut y = x.clone();
        for (down, conv) in &self.encoder {
            y = down.forward_leaky_relu(&y, slope)?;
            y = conv.forward_leaky_relu(&y, slope)?;
            skips.push(y.clone());
        }
        Ok(PriorOutput {
            colour: self.colour.forward(&skips, slope)?,
            height: (self.relief.forward(&skips, slope)? * HEIGHT_UNIT)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    use super::*;

    #[test]
    fn prior_outputs_have_the_input_size_at_several_sizes_and_the_counted_parameters() {
        let config = PriorConfig {
            encoder_channels: vec![4, 6, 8],
            decoder_channels: vec![6, 4],
            colour_channels: 7,
            leaky_slope: 0.2,
        };
        let vars = VarMap::new();
        let vb = VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu);
        let net = PriorNet::new(&config, vb).unwrap();
        let counted: usize = vars.all_vars().iter().map(|v| v.elem_count()).sum();
        assert_eq!(counted, config.num_parameters());
        for (h, w) in [(16, 16), (32, 24), (64, 64)] {
            let x = Tensor::zeros((2, INPUT_CHANNELS, h, w), DType::F32, &Device::Cpu).unwrap();
            let out = net.forward(&x).unwrap();
            assert_eq!(out.colour.dims4().unwrap(), (2, 7, h, w));
            assert_eq!(out.height.dims4().unwrap(), (2, 1, h, w));
        }
        let odd = Tensor::zeros((1, INPUT_CHANNELS, 20, 16), DType::F32, &Device::Cpu).unwrap();
        assert!(net.forward(&odd).is_err());
    }
}
