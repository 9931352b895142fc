//! The estimator's training objective for one batch (PhotoMat §3 "Material map estimator";
//! `docs/neural-models.md`, "Training E"): E's decoded maps are rendered under the batch's flashes
//! and compared with the frozen M's relighting of the same neural material F:
//!
//! ```text
//! maps   = brdf.decode(E(F))
//! stage 1:  render(maps, l)        vs  M(F, ω_l)        L1 (texel-wise) + Gram at 1, ½, ¼
//! stage 2:  render(roll(maps), l)  vs  M(roll(F), ω_l)  L1 on 16×16 downsamples + Gram at 1
//! loss   = l1_weight·L1 + gram_weight·Gram                (0.1 and 1.0 in the reference)
//! ```
//!
//! Images: the analytic render is display-encoded ([`encode_display`], values in [0, 1]);
//! M's output lives in the networks' range `2·encoded − 1` (`docs/conventions.md`, "Image values").
//! L1 compares both in that [−1, 1] range, the Gram term in [0, 1] (the extractors' input). M's
//! image is clamped to [−1, 1]: the encoded render cannot leave [0, 1], so values beyond are
//! unreachable targets. F and M's image are constants (G and M are frozen): only E receives
//! gradients.

use candle_core::{DType, Tensor};
use photomat_core::render::to_network_range;
use photomat_core::{
    DifferentiableBrdf, FlashGeometry, MaterialMaps, Result, encode_display, render_radiance_with,
};
use photomat_generator::Relight;
use photomat_train::{roll_maps, roll_per_sample};

use super::config::{Stage, TrainConfig};
use super::draws::StepDraws;
use crate::Estimator;
use crate::loss::{FeatureExtractor, gram_loss, l1, l1_downsampled};

/// The terms of one batch's loss (scalars).
#[derive(Debug, Clone)]
pub struct LossTerms {
    /// The L1 term, unweighted.
    pub l1: Tensor,
    /// The Gram term, unweighted.
    pub gram: Tensor,
    /// `l1_weight·l1 + gram_weight·gram`: what is minimised.
    pub total: Tensor,
}

/// What the objective needs besides E: the BRDF, the frozen M, the Gram features, the weights.
pub struct Objective<'a> {
    pub brdf: &'a dyn DifferentiableBrdf,
    pub relight: &'a Relight,
    pub extractor: &'a dyn FeatureExtractor,
    pub config: &'a TrainConfig,
    /// World side of the R×R training materials: 1 (the unit square) for a fixed-size GAN,
    /// R × texel size for a spatial one.
    pub side: f64,
    /// Texel size the decoded maps record (a spatial GAN's; `None`: the unit square).
    pub texel_size: Option<f64>,
}

impl Objective<'_> {
    /// The loss of E on neural materials `features` under the batch's `draws` at `stage`.
    ///
    /// # Shapes
    /// features (B, C_F, R, R) with B = `draws.highlights.len()` → scalar terms.
    pub fn loss(
        &self,
        estimator: &Estimator,
        features: &Tensor,
        draws: &StepDraws,
        stage: Stage,
    ) -> Result<LossTerms> {
        let features = features.detach();
        let (_, _, r, _) = features.dims4()?;
        let maps = self
            .brdf
            .decode(&estimator.forward(&features)?)?
            .with_texel_size(self.texel_size);
        let (features, maps) = match stage {
            Stage::Aligned => (features, maps),
            Stage::Finetune => (
                roll_per_sample(&features, &draws.rolls)?,
                roll_maps(&maps, &draws.rolls)?,
            ),
        };
        let highlights = draws.highlights_on(self.texel_size.map(|_| self.side));
        let (target, render) = self.images(&features, &maps, &highlights, r)?;
        let l1 = match stage {
            Stage::Aligned => l1(&to_network_range(&render)?, &target)?,
            Stage::Finetune => l1_downsampled(
                &to_network_range(&render)?,
                &target,
                self.config.finetune_l1_size,
            )?,
        };
        let scales = match stage {
            Stage::Aligned => self.config.gram_scales,
            Stage::Finetune => 1,
        };
        let gram = gram_loss(self.extractor, &render, &target.affine(0.5, 0.5)?, scales)?;
        let total = ((&l1 * self.config.l1_weight)? + (&gram * self.config.gram_weight)?)?;
        Ok(LossTerms { l1, gram, total })
    }

    /// M's image of `features` (constant, clamped to [−1, 1]) and the display-encoded render
    /// of `maps` ([0, 1]) under `highlights` (world units on the square of side `self.side`).
    ///
    /// # Shapes
    /// features (B, C_F, R, R), maps (B, ·, R, R) → ((B, 3, R, R), (B, 3, R, R)).
    pub fn images(
        &self,
        features: &Tensor,
        maps: &MaterialMaps,
        highlights: &[photomat_core::Highlight],
        resolution: usize,
    ) -> Result<(Tensor, Tensor)> {
        let geometry = FlashGeometry::with_side(
            highlights,
            resolution,
            self.side,
            DType::F32,
            features.device(),
        )?;
        let target = self
            .relight
            .forward(features, &geometry.omega)?
            .detach()
            .clamp(-1f32, 1f32)?;
        let render = encode_display(&render_radiance_with(self.brdf, maps, &geometry)?)?;
        Ok((target, render))
    }
}
