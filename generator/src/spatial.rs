//! The spatial input of a fully convolutional G: a field of local latents in place of
//! StyleGAN2's learned 4×4 constant.
//!
//! Following the spatial texture GANs (Jetchev, Bergmann, Vollgraf 2016, "Texture Synthesis
//! with Spatial Generative Adversarial Networks"; Bergmann, Jetchev, Vollgraf 2017, PSGAN:
//! local, global and periodic latents; Henzler et al. 2021, "Generative Modelling of BRDF
//! Textures from Flash Images"), the first synthesis block starts from a field of i.i.d.
//! N(0, I) vectors, one per base cell, instead of a learned 4×4 constant. Each vector is mapped
//! to the base channels by [`SpatialConfig::layers`] 1×1 equalised-learning-rate convolutions
//! ([`crate::equalized`]; `lrelu` between them, the last one linear so the base features keep
//! the constant's role of a zero-mean, unit-scale input). The global z → w ([`crate::mapping`])
//! still modulates every layer and so keeps the material's identity; the local field only
//! decides *where* its structures are.
//!
//! Every later layer is a circularly padded conv or wrap-around FIR upsampling (the generator
//! must be tileable, [`crate::GeneratorConfig::validate`]), so G is translation-equivariant:
//! shifting the field by k cells, and every noise image by the same distance, shifts F by
//! k·[`cell_size`](crate::GeneratorConfig::cell_size) texels; a field of n×n cells gives F of
//! n·cell texels, periodic at that side (tileable at any size); a field tiled 2×2 gives F tiled
//! 2×2. PSGAN's periodic channels are optional ([`SpatialConfig::waves`], [`crate::waves`]):
//! the wrap-around padding already makes every sample periodic at its own size, and the waves
//! serve the other role, lattices that repeat across many cells (tiles, weave;
//! docs/neural-models.md, "Regular lattices"). With waves, the shift and tiling properties
//! above hold for the lattice up to its whole periods (it is anchored at the sample's corner).
//!
//! Parameter names under the base block's `vb` (`synthesis.b4`): `input.fc{i}.{weight,bias}`.

use candle_core::{Result, Tensor, bail};
use candle_nn::VarBuilder;
use serde::{Deserialize, Serialize};

use crate::activation::{bias_lrelu, lrelu};
use crate::equalized::{EqualizedConv2d, equalized_conv2d};
use crate::padding::Padding;

/// Options of the spatial input ([`crate::GeneratorConfig::spatial`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpatialConfig {
    /// Channels of a local latent (one N(0, I) vector per base cell). Default 32.
    pub local_dim: usize,
    /// 1×1 layers from a local latent to the base channels (`lrelu` between them, the last
    /// one linear). Default 2.
    pub layers: usize,
    /// World units per texel of F: the texel of the photos the patches were cut from (2/S for
    /// S×S prepared photos, the flash at height 1; docs/conventions.md, "Training patches").
    /// A sample of N texels covers a square of side N · texel_size. Set from the training data
    /// when a run starts (`RunPlan::bind_data`); `None` in a model folder written before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texel_size: Option<f64>,
    /// Periodic channels: plane waves whose wave vectors follow the material's w, added at
    /// every block ([`crate::waves`]). 0 (the default, and every model folder written before
    /// they existed): none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub waves: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl Default for SpatialConfig {
    fn default() -> Self {
        Self {
            local_dim: 32,
            layers: 2,
            texel_size: None,
            waves: 0,
        }
    }
}

impl SpatialConfig {
    /// Checks every field; the error names it.
    pub fn validate(&self) -> Result<()> {
        use crate::limits::{MAX_LOCAL_DIM, MAX_LOCAL_LAYERS, MAX_WAVES};
        if !(1..=MAX_LOCAL_DIM).contains(&self.local_dim) {
            bail!(
                "spatial.local_dim {} must be in 1 … {MAX_LOCAL_DIM}",
                self.local_dim
            );
        }
        if !(1..=MAX_LOCAL_LAYERS).contains(&self.layers) {
            bail!(
                "spatial.layers {} must be in 1 … {MAX_LOCAL_LAYERS}",
                self.layers
            );
        }
        if self.waves > MAX_WAVES {
            bail!("spatial.waves {} must be at most {MAX_WAVES}", self.waves);
        }
        if let Some(t) = self.texel_size
            && !(t.is_finite() && t > 0.0)
        {
            bail!("spatial.texel_size must be a positive number of world units, got {t}");
        }
        Ok(())
    }
}

/// The local-latent field → base features of the first synthesis block.
#[derive(Debug, Clone)]
pub struct LocalInput {
    layers: Vec<EqualizedConv2d>,
    local_dim: usize,
}

/// Builds the [`LocalInput`] of `cfg` to `channels` base channels under `vb` (`fc{i}`).
pub fn local_input(cfg: &SpatialConfig, channels: usize, vb: VarBuilder) -> Result<LocalInput> {
    cfg.validate()?;
    let layers = (0..cfg.layers)
        .map(|i| {
            let c_in = if i == 0 { cfg.local_dim } else { channels };
            equalized_conv2d(c_in, channels, 1, true, vb.pp(format!("fc{i}")))
        })
        .collect::<Result<_>>()?;
    Ok(LocalInput {
        layers,
        local_dim: cfg.local_dim,
    })
}

impl LocalInput {
    /// Channels of a local latent.
    pub fn local_dim(&self) -> usize {
        self.local_dim
    }

    /// Per-cell map of the local latents to base features.
    ///
    /// # Shapes
    /// field (B, local_dim, n, n) → (B, C₄, n, n).
    pub fn forward(&self, field: &Tensor) -> Result<Tensor> {
        let (_b, c, _h, _w) = field.dims4()?;
        if c != self.local_dim {
            bail!(
                "local latent field of shape {:?}: expected {} channels",
                field.dims(),
                self.local_dim
            );
        }
        let last = self.layers.len() - 1;
        let mut x = field.clone();
        for (i, layer) in self.layers.iter().enumerate() {
            // A 1×1 conv reads no neighbour: the padding mode is irrelevant.
            let y = layer.conv(&x, 1, 0, Padding::Zeros)?;
            x = match (i == last, layer.bias()) {
                (true, _) => layer.add_bias(&y)?,
                (false, Some(b)) => bias_lrelu(&y, b)?,
                (false, None) => lrelu(&y)?,
            };
        }
        Ok(x)
    }
}
