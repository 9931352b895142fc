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
//! - **Spatial** ([`GeneratorConfig::spatial`], [`crate::spatial`]): the constant is replaced
//!   by a field of local latents (one per base cell) mapped per cell to the base channels;
//!   with the tileable padding G is then fully convolutional: a field of n×n cells makes F of
//!   side n·R/4 ([`Synthesis::forward_field`]), every noise image scaled alike
//!   ([`Synthesis::noise_shapes_at`]).
//!
//! - **Periodic waves** ([`crate::spatial::SpatialConfig::waves`], [`crate::waves`]): a
//!   spatial G may add plane waves, whose wave vectors follow w, to every block's input.
//!
//! Parameter names under the generator's `vb`: `mapping.*` ([`crate::mapping`]) and
//! `synthesis.b{r}.{const, conv0.*, conv1.*, tofeat.*}` (a spatial G has
//! `synthesis.b4.input.fc{i}.*` instead of `b4.const`, and with waves `synthesis.waves.*`)
//! with, per conv,
//! `affine.{weight,bias}`, `weight`, `noise_strength`, `bias`.

use candle_core::{Result, Tensor, bail};
use candle_nn::{Init, VarBuilder};

use crate::activation::{bias_lrelu, noise_bias_lrelu};
use crate::fir::upsample2d;
use crate::mapping::Mapping;
use crate::modulated_conv::{ModulatedConv2d, modulated_conv2d};
use crate::noise::{NoiseInjection, NoiseInput, noise_injection};
use crate::padding::Padding;
use crate::spatial::{LocalInput, local_input};
use crate::waves::{PeriodicWaves, periodic_waves};
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
        photomat_kernels::add_channel_bias(&self.conv.forward(x, w)?, &self.bias)
    }
}

/// The synthesis block at one resolution.
#[derive(Debug, Clone)]
pub struct SynthesisBlock {
    resolution: usize,
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
    /// x (B, C_{r/2}, s/2, s/2), or the base features (B, C₄, s, s) at 4²; img (B, 32, s/2,
    /// s/2) or None at 4²; ws (B, num_conv + 1, w_dim) → ((B, C_r, s, s), (B, 32, s, s)),
    /// where s = r for the fixed-size G and s = r·N/R for a spatial G making side N.
    fn forward(
        &self,
        x: &Tensor,
        img: Option<&Tensor>,
        ws: &Tensor,
        noise: &[Option<Tensor>],
        padding: Padding,
    ) -> Result<(Tensor, Tensor)> {
        let w_at = |i: usize| ws.narrow(1, i, 1)?.squeeze(1);
        let mut x = x.clone();
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

/// What the first (4²) block starts from.
#[derive(Debug, Clone)]
pub enum BaseInput {
    /// StyleGAN2's learned constant (C₄, 4, 4) (`b4.const`): the fixed-size G.
    Constant(Tensor),
    /// A field of local latents mapped per cell ([`crate::spatial`], `b4.input.*`): the
    /// spatial G.
    Local(LocalInput),
}

/// The synthesis network: per-layer w → F.
#[derive(Debug, Clone)]
pub struct Synthesis {
    base: BaseInput,
    blocks: Vec<SynthesisBlock>,
    /// A spatial G's periodic channels, added to every block's input ([`crate::waves`]).
    waves: Option<PeriodicWaves>,
    padding: Padding,
    num_ws: usize,
    latent_dim: usize,
    /// The architecture (for the possible output sizes).
    config: GeneratorConfig,
}

impl Synthesis {
    /// Builds the synthesis network of `cfg` under `vb`.
    pub fn new(cfg: &GeneratorConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let padding = Padding::for_tileable(cfg.tileable);
        let w_dim = cfg.latent_dim;
        let c4 = cfg.channels_at(BASE_RESOLUTION);
        let vb4 = vb.pp(format!("b{BASE_RESOLUTION}"));
        let base = match &cfg.spatial {
            None => {
                let init = Init::Randn {
                    mean: 0.0,
                    stdev: 1.0,
                };
                let shape = (c4, BASE_RESOLUTION, BASE_RESOLUTION);
                BaseInput::Constant(vb4.get_with_hints(shape, "const", init)?)
            }
            Some(spatial) => BaseInput::Local(local_input(spatial, c4, vb4.pp("input"))?),
        };
        let mut blocks = Vec::with_capacity(cfg.num_blocks());
        let mut res = BASE_RESOLUTION;
        while res <= cfg.resolution {
            let vb = vb.pp(format!("b{res}"));
            let c = cfg.channels_at(res);
            let conv0 = if res == BASE_RESOLUTION {
                None
            } else {
                let c_in = cfg.channels_at(res / 2);
                Some(synthesis_layer(
                    c_in,
                    c,
                    w_dim,
                    true,
                    padding,
                    vb.pp("conv0"),
                )?)
            };
            blocks.push(SynthesisBlock {
                resolution: res,
                conv0,
                conv1: synthesis_layer(c, c, w_dim, false, padding, vb.pp("conv1"))?,
                to_features: to_features(c, cfg.feature_channels, w_dim, vb.pp("tofeat"))?,
            });
            res *= 2;
        }
        let waves = match &cfg.spatial {
            Some(spatial) if spatial.waves > 0 => {
                let inputs: Vec<(usize, usize)> = blocks
                    .iter()
                    .map(|blk| {
                        let r = blk.resolution;
                        (r, cfg.channels_at((r / 2).max(BASE_RESOLUTION)))
                    })
                    .collect();
                Some(periodic_waves(
                    spatial.waves,
                    w_dim,
                    cfg.cell_size(),
                    &inputs,
                    vb.pp("waves"),
                )?)
            }
            _ => None,
        };
        Ok(Self {
            base,
            blocks,
            waves,
            padding,
            num_ws: cfg.num_ws(),
            latent_dim: cfg.latent_dim,
            config: cfg.clone(),
        })
    }

    /// Number of per-layer w vectors consumed ([`GeneratorConfig::num_ws`]).
    pub fn num_ws(&self) -> usize {
        self.num_ws
    }

    /// What the first block starts from.
    pub fn base_input(&self) -> &BaseInput {
        &self.base
    }

    /// A spatial G's periodic channels, if it has any.
    pub fn periodic_waves(&self) -> Option<&PeriodicWaves> {
        self.waves.as_ref()
    }

    /// Whether this is a spatial G (a local latent field instead of the constant).
    pub fn is_spatial(&self) -> bool {
        matches!(self.base, BaseInput::Local(_))
    }

    /// Shapes of the noise images, one per conv, in the order [`NoiseInput::Given`] expects:
    /// (B, 1, 4, 4), then two (B, 1, r, r) per block r = 8 … R.
    pub fn noise_shapes(&self, batch: usize) -> Vec<(usize, usize, usize, usize)> {
        self.noise_shapes_for_cells(batch, BASE_RESOLUTION)
    }

    /// Shapes of the noise images for an F of side `size` (a spatial G: any multiple of the
    /// cell size; the fixed-size G: R only): (B, 1, n, n), then two (B, 1, n·r/4, n·r/4) per
    /// block r = 8 … R, with n = size / cell size base cells per side.
    pub fn noise_shapes_at(
        &self,
        batch: usize,
        size: usize,
    ) -> Result<Vec<(usize, usize, usize, usize)>> {
        Ok(self.noise_shapes_for_cells(batch, self.config.cells_for(size)?))
    }

    fn noise_shapes_for_cells(
        &self,
        batch: usize,
        cells: usize,
    ) -> Vec<(usize, usize, usize, usize)> {
        self.blocks
            .iter()
            .flat_map(|blk| {
                let side = cells * blk.resolution / BASE_RESOLUTION;
                std::iter::repeat_n((batch, 1, side, side), blk.num_conv())
            })
            .collect()
    }

    /// Shape of the local latent field of a spatial G making F of side `size`:
    /// (B, local_dim, n, n) with n = size / cell size. Errors for the fixed-size G and for
    /// sides that are not a multiple of the cell size.
    pub fn field_shape(&self, batch: usize, size: usize) -> Result<(usize, usize, usize, usize)> {
        match &self.base {
            BaseInput::Local(input) => {
                let n = self.config.cells_for(size)?;
                Ok((batch, input.local_dim(), n, n))
            }
            BaseInput::Constant(_) => bail!(
                "this generator starts from its learned constant and takes no local latent field"
            ),
        }
    }

    /// Per-layer w → F, for the fixed-size G (its learned constant as input).
    ///
    /// # Shapes
    /// ws (B, num_ws, w_dim) → (B, feature_channels, R, R).
    pub fn forward(&self, ws: &Tensor, noise: &NoiseInput) -> Result<Tensor> {
        let b = self.check_ws(ws)?;
        let x = match &self.base {
            BaseInput::Constant(c) => c.unsqueeze(0)?.repeat((b, 1, 1, 1))?,
            BaseInput::Local(_) => bail!(
                "a spatial generator starts from a local latent field: use \
                 Synthesis::forward_field"
            ),
        };
        self.run(&x, ws, noise)
    }

    /// Local latent field + per-layer w → F, for a spatial G: a field of n×n cells makes F of
    /// side n · cell size.
    ///
    /// # Shapes
    /// field (B, local_dim, n, n), ws (B, num_ws, w_dim) → (B, feature_channels, N, N) with
    /// N = n · [`GeneratorConfig::cell_size`].
    pub fn forward_field(&self, field: &Tensor, ws: &Tensor, noise: &NoiseInput) -> Result<Tensor> {
        let b = self.check_ws(ws)?;
        let BaseInput::Local(input) = &self.base else {
            bail!("a fixed-size generator takes no local latent field: use Synthesis::forward");
        };
        let (fb, _c, h, w) = field.dims4()?;
        if fb != b || h != w || h == 0 {
            bail!(
                "local latent field of shape {:?} for ws of batch {b}: expected ({b}, {}, n, n)",
                field.dims(),
                input.local_dim()
            );
        }
        self.run(&input.forward(field)?, ws, noise)
    }

    fn check_ws(&self, ws: &Tensor) -> Result<usize> {
        let (b, n, d) = ws.dims3()?;
        if n != self.num_ws || d != self.latent_dim {
            bail!(
                "synthesis: ws of shape {:?}, expected ({b}, {}, {})",
                ws.dims(),
                self.num_ws,
                self.latent_dim
            );
        }
        Ok(b)
    }

    /// The blocks from base features x (B, C₄, n, n).
    fn run(&self, x: &Tensor, ws: &Tensor, noise: &NoiseInput) -> Result<Tensor> {
        let (b, _c, cells, _) = x.dims4()?;
        let shapes = self.noise_shapes_for_cells(b, cells);
        let noises: Vec<Option<Tensor>> = match noise {
            // A generator without noise inputs ignores whatever noise it is given.
            _ if !self.config.noise_inputs => vec![None; shapes.len()],
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
        // The waves with their whole cycles per side of the sample, from the first layer's w.
        let waves = match &self.waves {
            Some(waves) => {
                let k = waves.wave_vectors(&ws.narrow(1, 0, 1)?.squeeze(1)?)?;
                let side = cells * self.config.cell_size();
                Some((waves, PeriodicWaves::cycles_per_side(&k, side)?))
            }
            None => None,
        };
        let mut x = x.clone();
        let mut img: Option<Tensor> = None;
        let (mut w_idx, mut noise_idx) = (0, 0);
        for (i, block) in self.blocks.iter().enumerate() {
            if let Some((waves, cycles)) = &waves {
                x = waves.add_to_block_input(i, &x, cycles)?;
            }
            let nc = block.num_conv();
            let block_ws = ws.narrow(1, w_idx, nc + 1)?;
            let (nx, nimg) = block.forward(
                &x,
                img.as_ref(),
                &block_ws,
                &noises[noise_idx..noise_idx + nc],
                self.padding,
            )?;
            x = nx;
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

    /// z → F with truncation ψ (1 = none), for the fixed-size G.
    ///
    /// # Shapes
    /// (B, latent_dim) → (B, feature_channels, R, R).
    pub fn forward(&self, z: &Tensor, psi: f64, noise: &NoiseInput) -> Result<Tensor> {
        self.synthesis.forward(&self.ws(z, psi)?, noise)
    }

    /// z and a local latent field → F with truncation ψ, for a spatial G
    /// ([`Synthesis::forward_field`]).
    ///
    /// # Shapes
    /// z (B, latent_dim), field (B, local_dim, n, n) → (B, feature_channels, N, N),
    /// N = n · cell size.
    pub fn forward_field(
        &self,
        z: &Tensor,
        field: &Tensor,
        psi: f64,
        noise: &NoiseInput,
    ) -> Result<Tensor> {
        self.synthesis
            .forward_field(field, &self.ws(z, psi)?, noise)
    }
}
