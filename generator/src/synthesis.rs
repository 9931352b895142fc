//! The synthesis network of G and the generator G itself (StyleGAN2 "skip" generator, Karras
//! et al. 2020 §4.1 and Fig. 7; StyleGAN2-ADA `SynthesisNetwork`, `SynthesisBlock`,
//! `SynthesisLayer`, `ToRGBLayer`), producing PhotoMat's neural material F (paper §3, §4).
//!
//! ```text
//! b4:   const (C₄,4,4) → conv1 ─────────────────────────────→ toFeature → F₄
//! b8:   ↑FIR → conv0 → conv1 ───────────────────────→ toFeature ⊕ ↑FIR(F₄) = F₈
//! …
//! bR:   ↑FIR → conv0 → conv1 ───────────────────────→ toFeature ⊕ ↑FIR(F_{R/2}) = F
//! ```
//!
//! - Each conv is a demodulated [`ModulatedConv2d`] 3×3, followed by per-pixel noise
//!   ([`crate::noise`]), a bias and `lrelu` ([`crate::activation`]).
//! - The up-sampling conv0 is StyleGAN2's transposed 3×3 conv followed by the `[1,3,3,1]` filter;
//!   both are linear shift-invariant operators on the zero-stuffed signal, so they commute:
//!   here the FIR upsampling ([`crate::fir::upsample2d`]) runs first and an ordinary 3×3
//!   conv follows: the same operator up to the alignment of the output grid (at most one
//!   texel) and the border handling, with no transposed conv, and it wraps around in
//!   tileable mode.
//! - toFeature layers (StyleGAN2's toRGB with `feature_channels` = 32 outputs) are 1×1
//!   modulated convs without demodulation, plus bias, no activation; their outputs are summed
//!   through FIR upsampling and the sum at the last block is F (no activation).
//! - Per-layer w: one per conv plus the last toFeature, the toFeature of a block sharing its w
//!   with the next block's conv0 (StyleGAN2); `num_ws = 2·log₂R − 2`.
//! - Channels at resolution r: [`GeneratorConfig::channels_at`].
//! - **Tileable** ([`GeneratorConfig::tileable`]): every conv pads circularly and every FIR
//!   upsampling wraps around, so each layer commutes with rolls and F is exactly periodic;
//!   rolling the constant input by t texels and every noise image accordingly rolls F by
//!   t·R/4 texels.
//!
//! Parameter names under the generator's `vb`: `mapping.*` ([`crate::mapping`]) and
//! `synthesis.b{r}.{const, conv0.*, conv1.*, tofeat.*}` with, per conv,
//! `affine.{weight,bias}`, `weight`, `noise_strength`, `bias`.

use candle_core::{Result, Tensor, bail};
use candle_nn::{Init, VarBuilder};

use crate::activation::{bias_lrelu, noise_bias_lrelu};
use crate::fir::upsample2d;
use crate::mapping::Mapping;
use crate::modulated_conv::{ModulatedConv2d, modulated_conv2d};
use crate::noise::{NoiseInjection, NoiseInput, noise_injection};
use crate::padding::Padding;
use crate::{BASE_RESOLUTION, GeneratorConfig};

/// Kernel of the synthesis convs.
const KERNEL: usize = 3;

/// One modulated conv + noise + bias + `lrelu`, optionally preceded by ×2 FIR upsampling.
#[derive(Debug, Clone)]
pub struct SynthesisLayer {
    conv: ModulatedConv2d,
    noise: NoiseInjection,
    bias: Tensor,
    up: bool,
    padding: Padding,
}

fn synthesis_layer(
    in_channels: usize,
    out_channels: usize,
    w_dim: usize,
    up: bool,
    padding: Padding,
    vb: VarBuilder,
) -> Result<SynthesisLayer> {
    let conv = modulated_conv2d(
        in_channels,
        out_channels,
        KERNEL,
        w_dim,
        true,
        padding,
        vb.clone(),
    )?;
    let noise = noise_injection(vb.clone())?;
    let bias = vb.get_with_hints(out_channels, "bias", Init::Const(0.0))?;
    Ok(SynthesisLayer {
        conv,
        noise,
        bias,
        up,
        padding,
    })
}

impl SynthesisLayer {
    /// # Shapes
    /// x (B, C_in, H, W), w (B, w_dim), noise (B, 1, H', W') → (B, C_out, H', W') with
    /// H' = 2H when upsampling, H otherwise.
    pub fn forward(&self, x: &Tensor, w: &Tensor, noise: Option<&Tensor>) -> Result<Tensor> {
        let x = if self.up {
            upsample2d(x, self.padding)?
        } else {
            x.clone()
        };
        let y = self.conv.forward(&x, w)?;
        match noise {
            Some(n) => noise_bias_lrelu(&y, &self.noise.scaled(&y, n)?, &self.bias),
            None => bias_lrelu(&y, &self.bias),
        }
    }
}

/// 1×1 modulated conv without demodulation + bias: a block's contribution to F.
#[derive(Debug, Clone)]
pub struct ToFeatures {
    conv: ModulatedConv2d,
    bias: Tensor,
}

fn to_features(
    in_channels: usize,
    out_channels: usize,
    w_dim: usize,
    vb: VarBuilder,
) -> Result<ToFeatures> {
    let conv = modulated_conv2d(
        in_channels,
        out_channels,
        1,
        w_dim,
        false,
        Padding::Zeros,
        vb.clone(),
    )?;
    let bias = vb.get_with_hints(out_channels, "bias", Init::Const(0.0))?;
    Ok(ToFeatures { conv, bias })
}

impl ToFeatures {
    /// # Shapes
    /// x (B, C_in, H, W), w (B, w_dim) → (B, feature_channels, H, W).
    pub fn forward(&self, x: &Tensor, w: &Tensor) -> Result<Tensor> {
        self.conv
            .forward(x, w)?
            .broadcast_add(&self.bias.reshape((1, (), 1, 1))?)
    }
}

/// The synthesis block at one resolution.
#[derive(Debug, Clone)]
pub struct SynthesisBlock {
    resolution: usize,
    const_input: Option<Tensor>,
    conv0: Option<SynthesisLayer>,
    conv1: SynthesisLayer,
    to_features: ToFeatures,
}

impl SynthesisBlock {
    /// Convs in this block (1 at 4², 2 elsewhere).
    pub fn num_conv(&self) -> usize {
        1 + usize::from(self.conv0.is_some())
    }

    /// One block step: (features, F so far) → (features, F) at this block's resolution.
    ///
    /// # Shapes
    /// x (B, C_{r/2}, r/2, r/2) or None at 4², img (B, 32, r/2, r/2) or None at 4²,
    /// ws (B, num_conv + 1, w_dim) → ((B, C_r, r, r), (B, 32, r, r)).
    fn forward(
        &self,
        x: Option<&Tensor>,
        img: Option<&Tensor>,
        ws: &Tensor,
        noise: &[Option<Tensor>],
        padding: Padding,
    ) -> Result<(Tensor, Tensor)> {
        let (b, _n, _d) = ws.dims3()?;
        let w_at = |i: usize| ws.narrow(1, i, 1)?.squeeze(1);
        let mut x = match (&self.const_input, x) {
            (Some(c), _) => c.unsqueeze(0)?.repeat((b, 1, 1, 1))?,
            (None, Some(x)) => x.clone(),
            (None, None) => bail!("synthesis block {}: no input features", self.resolution),
        };
        let mut idx = 0;
        if let Some(conv0) = &self.conv0 {
            x = conv0.forward(&x, &w_at(idx)?, noise[idx].as_ref())?;
            idx += 1;
        }
        x = self.conv1.forward(&x, &w_at(idx)?, noise[idx].as_ref())?;
        idx += 1;
        let y = self.to_features.forward(&x, &w_at(idx)?)?;
        let img = match img {
            Some(img) => (upsample2d(img, padding)? + y)?,
            None => y,
        };
        Ok((x, img))
    }
}

/// The synthesis network: per-layer w → F.
#[derive(Debug, Clone)]
pub struct Synthesis {
    blocks: Vec<SynthesisBlock>,
    padding: Padding,
    num_ws: usize,
    latent_dim: usize,
}

impl Synthesis {
    /// Builds the synthesis network of `cfg` under `vb`.
    pub fn new(cfg: &GeneratorConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let padding = Padding::for_tileable(cfg.tileable);
        let w_dim = cfg.latent_dim;
        let mut blocks = Vec::with_capacity(cfg.num_blocks());
        let mut res = BASE_RESOLUTION;
        while res <= cfg.resolution {
            let vb = vb.pp(format!("b{res}"));
            let c = cfg.channels_at(res);
            let (const_input, conv0) = if res == BASE_RESOLUTION {
                let init = Init::Randn {
                    mean: 0.0,
                    stdev: 1.0,
                };
                (Some(vb.get_with_hints((c, res, res), "const", init)?), None)
            } else {
                let c_in = cfg.channels_at(res / 2);
                (
                    None,
                    Some(synthesis_layer(
                        c_in,
                        c,
                        w_dim,
                        true,
                        padding,
                        vb.pp("conv0"),
                    )?),
                )
            };
            blocks.push(SynthesisBlock {
                resolution: res,
                const_input,
                conv0,
                conv1: synthesis_layer(c, c, w_dim, false, padding, vb.pp("conv1"))?,
                to_features: to_features(c, cfg.feature_channels, w_dim, vb.pp("tofeat"))?,
            });
            res *= 2;
        }
        Ok(Self {
            blocks,
            padding,
            num_ws: cfg.num_ws(),
            latent_dim: cfg.latent_dim,
        })
    }

    /// Number of per-layer w vectors consumed ([`GeneratorConfig::num_ws`]).
    pub fn num_ws(&self) -> usize {
        self.num_ws
    }

    /// Shapes of the noise images, one per conv, in the order [`NoiseInput::Given`] expects:
    /// (B, 1, 4, 4), then two (B, 1, r, r) per block r = 8 … R.
    pub fn noise_shapes(&self, batch: usize) -> Vec<(usize, usize, usize, usize)> {
        self.blocks
            .iter()
            .flat_map(|blk| {
                std::iter::repeat_n((batch, 1, blk.resolution, blk.resolution), blk.num_conv())
            })
            .collect()
    }

    /// Per-layer w → F.
    ///
    /// # Shapes
    /// ws (B, num_ws, w_dim) → (B, feature_channels, R, R).
    pub fn forward(&self, ws: &Tensor, noise: &NoiseInput) -> Result<Tensor> {
        let (b, n, d) = ws.dims3()?;
        if n != self.num_ws || d != self.latent_dim {
            bail!(
                "synthesis: ws of shape {:?}, expected ({b}, {}, {})",
                ws.dims(),
                self.num_ws,
                self.latent_dim
            );
        }
        let shapes = self.noise_shapes(b);
        let noises: Vec<Option<Tensor>> = match noise {
            NoiseInput::Zero => vec![None; shapes.len()],
            NoiseInput::Random => shapes
                .iter()
                .map(|&s| {
                    Tensor::randn(0f32, 1., s, ws.device())?
                        .to_dtype(ws.dtype())
                        .map(Some)
                })
                .collect::<Result<_>>()?,
            NoiseInput::Given(images) => {
                if images.len() != shapes.len() {
                    bail!(
                        "synthesis: {} noise images given, {} needed",
                        images.len(),
                        shapes.len()
                    );
                }
                for (img, s) in images.iter().zip(&shapes) {
                    if img.dims4()? != *s {
                        bail!("synthesis: noise image {:?}, expected {s:?}", img.dims());
                    }
                }
                images.iter().cloned().map(Some).collect()
            }
        };
        let (mut x, mut img): (Option<Tensor>, Option<Tensor>) = (None, None);
        let (mut w_idx, mut noise_idx) = (0, 0);
        for block in &self.blocks {
            let nc = block.num_conv();
            let block_ws = ws.narrow(1, w_idx, nc + 1)?;
            let (nx, nimg) = block.forward(
                x.as_ref(),
                img.as_ref(),
                &block_ws,
                &noises[noise_idx..noise_idx + nc],
                self.padding,
            )?;
            x = Some(nx);
            img = Some(nimg);
            w_idx += nc;
            noise_idx += nc;
        }
        match img {
            Some(img) => Ok(img),
            None => bail!("synthesis network has no blocks"),
        }
    }
}

/// The feature generator G: mapping + synthesis, z → F.
#[derive(Debug, Clone)]
pub struct Generator {
    mapping: Mapping,
    synthesis: Synthesis,
}

impl Generator {
    /// Builds G of `cfg` with parameters `mapping.*` and `synthesis.*` under `vb`.
    pub fn new(cfg: &GeneratorConfig, vb: VarBuilder) -> Result<Self> {
        Ok(Self {
            mapping: Mapping::new(cfg, vb.pp("mapping"))?,
            synthesis: Synthesis::new(cfg, vb.pp("synthesis"))?,
        })
    }

    /// The mapping network.
    pub fn mapping(&self) -> &Mapping {
        &self.mapping
    }

    /// The synthesis network.
    pub fn synthesis(&self) -> &Synthesis {
        &self.synthesis
    }

    /// z → per-layer w with truncation ψ.
    ///
    /// # Shapes
    /// (B, latent_dim) → (B, num_ws, latent_dim).
    pub fn ws(&self, z: &Tensor, psi: f64) -> Result<Tensor> {
        self.mapping.ws(z, psi, self.synthesis.num_ws())
    }

    /// z → F with truncation ψ (1 = none).
    ///
    /// # Shapes
    /// (B, latent_dim) → (B, feature_channels, R, R).
    pub fn forward(&self, z: &Tensor, psi: f64, noise: &NoiseInput) -> Result<Tensor> {
        self.synthesis.forward(&self.ws(z, psi)?, noise)
    }
}
