//! The map estimator E: a tileable UNet from neural material features F to raw BRDF maps.
//!
//! Paper: PhotoMat (Zhou et al., SIGGRAPH 2023), §3 "Material map estimator" (what E is
//! trained for) and §4 "Implementation" (the architecture: a UNet with skip connections,
//! five down- and five up-sampling levels, channels
//! 32→32→64→128→256→256→256→128→64→32→n). Layer details follow the reference `MatUnet`
//! (`training/networks.py`, `layer_n = 5`, no batch norm) and `docs/neural-models.md`, "Map
//! estimator E":
//!
//! ```text
//! F (B,32,H,W)
//!  enc0: 4×4/2 conv 32→32,  3×3 conv 32→32      (H/2)   ──────────────┐ skip
//!  enc1: 4×4/2 conv 32→64,  3×3 conv 64→64      (H/4)   ────────────┐ │
//!  enc2: 4×4/2 conv 64→128, 3×3 conv 128→128    (H/8)   ──────────┐ │ │
//!  enc3: 4×4/2 conv 128→256, 3×3 conv 256→256   (H/16)  ────────┐ │ │ │
//!  enc4: 4×4/2 conv 256→256, 3×3 conv 256→256   (H/32)          │ │ │ │
//!  dec0: up ×2, cat enc3 (512), 3×3 →256, 3×3 →256  (H/16) ◀────┘ │ │ │
//!  dec1: up ×2, cat enc2 (384), 3×3 →128, 3×3 →128  (H/8)  ◀──────┘ │ │
//!  dec2: up ×2, cat enc1 (192), 3×3 →64,  3×3 →64   (H/4)  ◀────────┘ │
//!  dec3: up ×2, cat enc0 (96),  3×3 →32,  3×3 →32   (H/2)  ◀──────────┘
//!  head: up ×2, 3×3 conv 32→n                       (H)    → raw (B,n,H,W)
//! ```
//!
//! Every conv is followed by LeakyReLU (slope 0.01, PyTorch's default; [`crate::activation`])
//! except the head; every conv pads circularly ([`crate::conv`]); upsampling is periodic
//! bilinear ([`crate::upsample`]). The fifth up level has no skip: the reference concatenates
//! nothing at full resolution, its last level is upsample + output conv, which is the paper's
//! final "32→n" arrow. Weights start Xavier-normal, biases N(0, 0.02²), as the reference's
//! `weights_init`.
//!
//! # The tanh head and the plugin decode
//! The reference ends in `tanh` and maps to [0, 1] with `0.5·tanh(·) + 0.5`, then clamps
//! per map. photomat's plugins decode *unconstrained* values with [`ParamSpec::decode`], which
//! applies that same `(tanh x + 1)/2` itself (then the map's range and gamma). E therefore
//! outputs the **pre-tanh** values of the reference's head (`raw = out.conv(x)`, no
//! activation), and `brdf.decode(raw)` applies the tanh exactly once. A map with the linear
//! encoding and range [0, 1] thus decodes to exactly the reference's `net(F)·0.5 + 0.5`
//! (before the reference's per-map clamps); other encodings (gamma-2.2 albedos, unit
//! normals, other ranges) are the plugin's documented choice.
//!
//! # Tileability
//! With circular padding and periodic upsampling every layer commutes with rolls by multiples
//! of its stride, so E commutes with rolls by multiples of the total stride 2⁵ = 32:
//! `E(roll(F, 32·t)) = roll(E(F), 32·t)`; a periodic F gives periodic maps. Inputs must be
//! multiples of 32 texels on each side.
//!
//! # Speed
//! 5 674 632 parameters at n = 8. On the 2-core build machine (f32, dev profile with optimised
//! dependencies, no other load; `examples/estimator_timing.rs`), one 64² batch-4 pass takes
//! 138 ms forward and 387 ms backward; with candle's own conv2d backward and candle-nn's
//! LeakyReLU it took 125 ms and 1240 ms ([`crate::conv_grad`], [`crate::activation`]).
//! A 256² batch-1 pass: 471 ms forward, 934 ms backward.
//!
//! [`ParamSpec::decode`]: photomat_core::ParamSpec::decode

use candle_core::{Module, Result, Tensor, bail};
use candle_nn::VarBuilder;
use photomat_core::{DifferentiableBrdf, MaterialMaps};

use crate::conv::{CircularConv2d, circular_conv2d};
use crate::upsample::upsample2x_periodic;

/// Kernel of the encoder's down-sampling convs (4×4, stride 2: the reference's encoder).
const DOWN_KERNEL: usize = 4;
/// Kernel of every other conv (3×3, stride 1).
const KERNEL: usize = 3;
/// Most encoder levels accepted: 2¹⁶ = 65536 texels per side is beyond any material size,
/// and the bound keeps `total_stride` far from overflow.
const MAX_LEVELS: usize = 16;
/// Most channels of any conv (the paper's widest level has 512; ×8).
pub const MAX_CHANNELS: usize = 4096;
/// Most trainable scalars (the paper's E has about 30 M; 200 M is 0.8 GB of f32 weights).
pub const MAX_PARAMETERS: usize = 200_000_000;

/// Architecture of [`Estimator`]. The defaults are the paper's configuration for
/// `height(ggx)` (n = 8).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorConfig {
    /// Channels of the neural material F (the generator's 32 toRGB features). Default 32.
    pub in_channels: usize,
    /// Output channels of the encoder levels, one level per entry, each halving the
    /// resolution. Default `[32, 64, 128, 256, 256]` (5 levels, total stride 32).
    pub encoder_channels: Vec<usize>,
    /// Output channels of the decoder levels that concatenate a skip, from coarse to fine;
    /// exactly one fewer than the encoder levels (the last up level is the head). Default
    /// `[256, 128, 64, 32]`.
    pub decoder_channels: Vec<usize>,
    /// Raw output channels n: the BRDF plugin's [`DifferentiableBrdf::channels`]. Default 8
    /// (`height(ggx)`: diffuse 3, specular 3, roughness 1, height 1).
    pub out_channels: usize,
    /// Negative slope of every LeakyReLU, in [0, 1]. Default 0.01 (the reference uses
    /// PyTorch's default `nn.LeakyReLU()`).
    pub leaky_slope: f64,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            in_channels: 32,
            encoder_channels: vec![32, 64, 128, 256, 256],
            decoder_channels: vec![256, 128, 64, 32],
            out_channels: 8,
            leaky_slope: 0.01,
        }
    }
}

impl EstimatorConfig {
    /// The default architecture with the output width of `brdf` (n = `brdf.channels()`).
    pub fn for_brdf(brdf: &dyn DifferentiableBrdf) -> Self {
        Self {
            out_channels: brdf.channels(),
            ..Self::default()
        }
    }

    /// The same architecture with every encoder and decoder width multiplied by `width`
    /// (rounded, at least 1); input and output widths unchanged. `width` 0.25 gives a model
    /// with about 1/16 of the parameters for CPU training.
    pub fn with_width(&self, width: f64) -> Result<Self> {
        if !(width.is_finite() && width > 0.0) {
            bail!("estimator width multiplier {width} must be positive and finite");
        }
        let scale = |c: &usize| ((*c as f64 * width).round() as usize).max(1);
        Ok(Self {
            encoder_channels: self.encoder_channels.iter().map(scale).collect(),
            decoder_channels: self.decoder_channels.iter().map(scale).collect(),
            ..self.clone()
        })
    }

    /// Factor by which the input side must be divisible: 2^(encoder levels).
    pub fn total_stride(&self) -> usize {
        1 << self.encoder_channels.len()
    }

    /// Number of trainable scalars (weights + biases), from the layer list.
    pub fn num_parameters(&self) -> usize {
        self.layers()
            .iter()
            .map(|&(c_in, c_out, k)| c_out * c_in * k * k + c_out)
            .sum()
    }

    /// Every conv as (C_in, C_out, kernel), in forward order.
    fn layers(&self) -> Vec<(usize, usize, usize)> {
        let enc = &self.encoder_channels;
        let mut layers = Vec::new();
        let mut c = self.in_channels;
        for &e in enc {
            layers.push((c, e, DOWN_KERNEL));
            layers.push((e, e, KERNEL));
            c = e;
        }
        for (i, &d) in self.decoder_channels.iter().enumerate() {
            let skip = enc[enc.len() - 2 - i];
            layers.push((c + skip, d, KERNEL));
            layers.push((d, d, KERNEL));
            c = d;
        }
        layers.push((c, self.out_channels, KERNEL));
        layers
    }

    /// Reject configurations the network cannot be built from, naming the offending field.
    pub fn validate(&self) -> Result<()> {
        let (enc, dec) = (&self.encoder_channels, &self.decoder_channels);
        if enc.is_empty() {
            bail!("estimator config: encoder_channels is empty (the paper uses 5 levels)");
        }
        if enc.len() > MAX_LEVELS {
            bail!(
                "estimator config: {} encoder levels would need inputs of 2^{} texels per side \
                 (at most {MAX_LEVELS} levels)",
                enc.len(),
                enc.len()
            );
        }
        if dec.len() + 1 != enc.len() {
            bail!(
                "estimator config: {} encoder levels need {} decoder levels with a skip \
                 (the last up level is the head), got {}",
                enc.len(),
                enc.len() - 1,
                dec.len()
            );
        }
        let widths = [self.in_channels, self.out_channels];
        if widths.iter().chain(enc).chain(dec).any(|&c| c == 0) {
            bail!("estimator config: every channel count must be ≥ 1, got {self:?}");
        }
        // Checked before any weight is allocated: a corrupt estimator.json must be an error,
        // not an allocation that aborts the process.
        if let Some(c) = widths
            .iter()
            .chain(enc)
            .chain(dec)
            .find(|&&c| c > MAX_CHANNELS)
        {
            bail!("estimator config: a channel count of {c} exceeds the limit of {MAX_CHANNELS}");
        }
        let parameters = self.num_parameters();
        if parameters > MAX_PARAMETERS {
            bail!("estimator config: {parameters} parameters exceed the limit of {MAX_PARAMETERS}");
        }
        if !(0.0..=1.0).contains(&self.leaky_slope) {
            bail!(
                "estimator config: leaky_slope {} is outside [0, 1]",
                self.leaky_slope
            );
        }
        Ok(())
    }
}

/// Encoder level: 4×4 stride-2 conv, LeakyReLU, 3×3 conv, LeakyReLU.
#[derive(Debug, Clone)]
struct EncoderLevel {
    down: CircularConv2d,
    conv: CircularConv2d,
}

impl EncoderLevel {
    fn new(c_in: usize, c_out: usize, vb: VarBuilder) -> Result<Self> {
        Ok(Self {
            down: circular_conv2d(c_in, c_out, DOWN_KERNEL, 2, vb.pp("down"))?,
            conv: circular_conv2d(c_out, c_out, KERNEL, 1, vb.pp("conv"))?,
        })
    }

    /// (B, C_in, H, W) → (B, C_out, H/2, W/2).
    fn forward(&self, x: &Tensor, slope: f64) -> Result<Tensor> {
        let x = self.down.forward_leaky_relu(x, slope)?;
        self.conv.forward_leaky_relu(&x, slope)
    }
}

/// Decoder level: ×2 periodic bilinear upsample, concat skip, two (3×3 conv, LeakyReLU).
#[derive(Debug, Clone)]
struct DecoderLevel {
    conv1: CircularConv2d,
    conv2: CircularConv2d,
}

impl DecoderLevel {
    fn new(c_in: usize, c_skip: usize, c_out: usize, vb: VarBuilder) -> Result<Self> {
        Ok(Self {
            conv1: circular_conv2d(c_in + c_skip, c_out, KERNEL, 1, vb.pp("conv1"))?,
            conv2: circular_conv2d(c_out, c_out, KERNEL, 1, vb.pp("conv2"))?,
        })
    }

    /// x (B, C_in, H, W), skip (B, C_skip, 2H, 2W) → (B, C_out, 2H, 2W). The upsampled input
    /// comes first in the concatenation, as in the reference.
    fn forward(&self, x: &Tensor, skip: &Tensor, slope: f64) -> Result<Tensor> {
        let x = Tensor::cat(&[&upsample2x_periodic(x)?, skip], 1)?;
        let x = self.conv1.forward_leaky_relu(&x, slope)?;
        self.conv2.forward_leaky_relu(&x, slope)
    }
}

/// The map estimator E (see the module docs for the architecture).
///
/// Parameters, as named under the [`VarBuilder`]: `enc{i}.down.{weight,bias}` and `enc{i}.conv.*` (the reference's `block{i}.model.0` and
/// `.model.2`, i < 5), `dec{j}.conv1.*` and `dec{j}.conv2.*` (reference `block{5+j}.model.0`
/// and `.model.2`), `head.*` (reference `out`). Weights are (C_out, C_in, k, k), biases (C_out).
#[derive(Debug, Clone)]
pub struct Estimator {
    cfg: EstimatorConfig,
    encoder: Vec<EncoderLevel>,
    decoder: Vec<DecoderLevel>,
    head: CircularConv2d,
}

impl Estimator {
    /// Builds E from `cfg` (validated first), creating or loading its parameters through `vb`.
    pub fn new(cfg: EstimatorConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let enc = &cfg.encoder_channels;
        let mut encoder = Vec::with_capacity(enc.len());
        let mut c = cfg.in_channels;
        for (i, &e) in enc.iter().enumerate() {
            encoder.push(EncoderLevel::new(c, e, vb.pp(format!("enc{i}")))?);
            c = e;
        }
        let mut decoder = Vec::with_capacity(cfg.decoder_channels.len());
        for (j, &d) in cfg.decoder_channels.iter().enumerate() {
            let skip = enc[enc.len() - 2 - j];
            decoder.push(DecoderLevel::new(c, skip, d, vb.pp(format!("dec{j}")))?);
            c = d;
        }
        let head = circular_conv2d(c, cfg.out_channels, KERNEL, 1, vb.pp("head"))?;
        Ok(Self {
            cfg,
            encoder,
            decoder,
            head,
        })
    }

    /// E for a BRDF plugin: the default architecture with n = `brdf.channels()`.
    pub fn for_brdf(brdf: &dyn DifferentiableBrdf, vb: VarBuilder) -> Result<Self> {
        Self::new(EstimatorConfig::for_brdf(brdf), vb)
    }

    /// The architecture E was built with.
    pub fn config(&self) -> &EstimatorConfig {
        &self.cfg
    }

    /// Raw, unconstrained (pre-tanh) parameter maps, to be decoded by the plugin.
    ///
    /// # Shapes
    /// (B, in_channels, H, W) → (B, out_channels, H, W); H and W multiples of
    /// [`EstimatorConfig::total_stride`] (32 by default).
    pub fn forward(&self, features: &Tensor) -> Result<Tensor> {
        let (_b, c, h, w) = features.dims4()?;
        if c != self.cfg.in_channels {
            bail!(
                "estimator: expected {} feature channels, got {c} (input shape {:?})",
                self.cfg.in_channels,
                features.dims()
            );
        }
        let stride = self.cfg.total_stride();
        if h == 0 || w == 0 || h % stride != 0 || w % stride != 0 {
            bail!(
                "estimator: the feature map is {h}×{w} texels, but its height and width must be \
                 positive multiples of {stride} ({} stride-2 levels)",
                self.encoder.len()
            );
        }
        let slope = self.cfg.leaky_slope;
        let mut skips = Vec::with_capacity(self.encoder.len());
        let mut x = features.clone();
        for level in &self.encoder {
            x = level.forward(&x, slope)?;
            skips.push(x.clone());
        }
        // The coarsest level is the bottleneck, not a skip: decoder level j takes encoder
        // level L − 2 − j.
        for (level, skip) in self.decoder.iter().zip(skips.iter().rev().skip(1)) {
            x = level.forward(&x, skip, slope)?;
        }
        self.head.forward(&upsample2x_periodic(&x)?)
    }

    /// Parameter maps of `brdf` for each material: `brdf.decode(forward(features))`.
    ///
    /// # Shapes
    /// features (B, in_channels, H, W) → one (B, channels, H, W) map per `ParamSpec`.
    pub fn estimate(
        &self,
        features: &Tensor,
        brdf: &dyn DifferentiableBrdf,
    ) -> photomat_core::Result<MaterialMaps> {
        if brdf.channels() != self.cfg.out_channels {
            return Err(photomat_core::Error::Invalid(format!(
                "the estimator outputs {} channels but model '{}' takes {}; build it with \
                 Estimator::for_brdf",
                self.cfg.out_channels,
                brdf.name(),
                brdf.channels()
            )));
        }
        brdf.decode(&self.forward(features)?)
    }
}

impl Module for Estimator {
    fn forward(&self, xs: &Tensor) -> Result<Tensor> {
        Estimator::forward(self, xs)
    }
}
