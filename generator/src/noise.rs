//! Per-pixel noise inputs of the synthesis layers (StyleGAN, Karras et al. 2019 §3.2; StyleGAN2
//! `SynthesisLayer`): a single-channel N(0, 1) image per sample, broadcast over the feature
//! channels and scaled by one learned scalar per layer, initialised to 0 (so a fresh generator
//! ignores its noise until training gives it a strength).
//!
//! Parameter name under the layer's `vb`: `noise_strength` (shape (1)).

use candle_core::{Result, Tensor, bail};
use candle_nn::{Init, VarBuilder};

/// Where the synthesis layers take their noise images from.
#[derive(Debug, Clone, Copy)]
pub enum NoiseInput<'a> {
    /// Fresh N(0, 1) noise per call (training; candle's unseeded generator).
    Random,
    /// No noise (deterministic output, e.g. for evaluation).
    Zero,
    /// One (B, 1, r, r) image per noise layer, in the order of
    /// [`crate::Synthesis::noise_shapes`] (deterministic, seeded runs, and tests that roll
    /// the noise).
    Given(&'a [Tensor]),
}

/// Adds `strength · noise` to a feature map.
#[derive(Debug, Clone)]
pub struct NoiseInjection {
    strength: Tensor,
}

/// Builds a [`NoiseInjection`] with its `noise_strength` (1) initialised to 0.
pub fn noise_injection(vb: VarBuilder) -> Result<NoiseInjection> {
    let strength = vb.get_with_hints(1, "noise_strength", Init::Const(0.0))?;
    Ok(NoiseInjection { strength })
}

impl NoiseInjection {
    /// `x + strength · noise`, with `noise` None meaning no noise.
    ///
    /// # Shapes
    /// x (B, C, H, W), noise (B, 1, H, W) → (B, C, H, W).
    pub fn forward(&self, x: &Tensor, noise: Option<&Tensor>) -> Result<Tensor> {
        let (_b, _c, _h, _w) = x.dims4()?;
        let Some(noise) = noise else {
            return Ok(x.clone());
        };
        x.broadcast_add(&self.scaled(x, noise)?)
    }

    /// `strength · noise`, the term [`NoiseInjection::forward`] adds, for fused epilogues
    /// ([`crate::activation::noise_bias_lrelu`]); `features` gives the expected shape.
    ///
    /// # Shapes
    /// features (B, C, H, W), noise (B, 1, H, W) → (B, 1, H, W).
    pub fn scaled(&self, features: &Tensor, noise: &Tensor) -> Result<Tensor> {
        let (b, _c, h, w) = features.dims4()?;
        if noise.dims4()? != (b, 1, h, w) {
            bail!(
                "noise image of shape {:?} does not fit features {:?} (expected ({b}, 1, {h}, {w}))",
                noise.dims(),
                features.dims()
            );
        }
        noise.broadcast_mul(&self.strength.reshape((1, 1, 1, 1))?)
    }

    /// The learned strength, shape (1).
    pub fn strength(&self) -> &Tensor {
        &self.strength
    }
}
