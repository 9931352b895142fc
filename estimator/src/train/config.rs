//! Hyper-parameters of the estimator's training (PhotoMat §3 "Material map estimator" and §4;
//! the reference's values in `docs/neural-models.md`, "Training E"): two stages, Adam, loss
//! weights, the feature extractor of the Gram term and the run seed. Saved as JSON next to every
//! checkpoint so a resumed run can refuse contradicting settings by name (`super::settings`).

use std::path::PathBuf;

use photomat_core::{Error, Result};
use serde::{Deserialize, Serialize};

/// `return Err(Error::Invalid(format!(…)))`: settings errors carry no backtrace, only the
/// message naming the field.
macro_rules! invalid {
    ($($arg:tt)*) => {
        return Err(Error::Invalid(format!($($arg)*)))
    };
}

use crate::loss::{DEFAULT_RANDOM_FEATURE_SEED, FINETUNE_L1_SIZE, REFERENCE_GRAM_SCALES};

/// Everything that determines a training run besides the GAN, the BRDF and E's architecture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Steps of stage 1 (aligned L1 + Gram). The paper trains 60 k.
    pub steps: u64,
    /// Steps of stage 2, the fine-tune with randomly rolled maps. The paper trains 60 k.
    pub finetune_steps: u64,
    /// Materials per step. Default 4 (the reference).
    pub batch: usize,
    /// Adam learning rate of stage 1. Default 1e-4 (the reference).
    pub lr: f64,
    /// Adam learning rate of the fine-tune. Default 5e-5 (the reference).
    pub finetune_lr: f64,
    /// Adam β₁. Default 0.9 (PyTorch's default, which the reference keeps).
    pub beta1: f64,
    /// Adam β₂. Default 0.999 (PyTorch's default).
    pub beta2: f64,
    /// Weight of the L1 term. Default 0.1.
    pub l1_weight: f64,
    /// Weight of the Gram term. Default 1.0.
    pub gram_weight: f64,
    /// Pyramid levels of stage 1's Gram term (3: scales 1, ½, ¼). The fine-tune uses 1.
    pub gram_scales: usize,
    /// Side of the area downsamples the fine-tune's L1 compares. Default 16.
    pub finetune_l1_size: usize,
    /// Truncation ψ of the GAN's latents (1 = none, the reference's training setting).
    pub psi: f64,
    /// Run seed: E's initial weights, the materials, lights and rolls of every step.
    pub seed: u64,
    /// VGG19 weights for the Gram term; `None` uses the seeded random conv bank.
    pub vgg19: Option<PathBuf>,
    /// Seed of the random conv bank (used when `vgg19` is `None`).
    pub feature_seed: u64,
    /// Consecutive steps with a non-finite loss after which training stops with an error.
    pub max_nan_steps: u32,
    /// Steps between the run's periodic outputs, kept by a resume unless it gives others.
    /// Absent from older `train.json` files: [`Cadence::default`].
    #[serde(default)]
    pub cadence: Cadence,
}

/// Steps between an estimator run's periodic outputs. They do not change what the run
/// trains, so a resume may give others.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cadence {
    /// Steps between training panels; at least 1.
    pub panel_every: u64,
    /// Steps between checkpoints; at least 1.
    pub checkpoint_every: u64,
}

impl Default for Cadence {
    fn default() -> Self {
        Self {
            panel_every: 500,
            checkpoint_every: 500,
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            steps: 60_000,
            finetune_steps: 60_000,
            batch: 4,
            lr: 1e-4,
            finetune_lr: 5e-5,
            beta1: 0.9,
            beta2: 0.999,
            l1_weight: 0.1,
            gram_weight: 1.0,
            gram_scales: REFERENCE_GRAM_SCALES,
            finetune_l1_size: FINETUNE_L1_SIZE,
            psi: 1.0,
            seed: 0,
            vgg19: None,
            feature_seed: DEFAULT_RANDOM_FEATURE_SEED,
            max_nan_steps: 10,
            cadence: Cadence::default(),
        }
    }
}

/// The two stages of training.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Stage {
    /// Stage 1: L1 and multi-scale Gram between the render of E's maps and M's image, both
    /// of the same F under the same light.
    Aligned,
    /// Stage 2: the maps and F are rolled per sample before rendering and relighting, so a
    /// flash falloff baked into the maps no longer lines up with the light; L1 on 16×16
    /// downsamples, Gram at full resolution.
    Finetune,
}

impl Stage {
    /// Short name for logs ("aligned", "finetune").
    pub fn name(self) -> &'static str {
        match self {
            Stage::Aligned => "aligned",
            Stage::Finetune => "finetune",
        }
    }
}

impl TrainConfig {
    /// Total steps of both stages.
    pub fn total_steps(&self) -> u64 {
        self.steps + self.finetune_steps
    }

    /// The stage of (0-based) step `step`: stage 1 for the first `steps`, then the fine-tune.
    pub fn stage_at(&self, step: u64) -> Stage {
        if step < self.steps {
            Stage::Aligned
        } else {
            Stage::Finetune
        }
    }

    /// Learning rate of `stage`.
    pub fn lr_of(&self, stage: Stage) -> f64 {
        match stage {
            Stage::Aligned => self.lr,
            Stage::Finetune => self.finetune_lr,
        }
    }

    /// Checks every field for a GAN of side `resolution`; errors name the field.
    pub fn validate(&self, resolution: usize) -> Result<()> {
        if self.cadence.panel_every == 0 || self.cadence.checkpoint_every == 0 {
            invalid!(
                "cadence.panel_every and checkpoint_every must be at least 1 (got {}, {})",
                self.cadence.panel_every,
                self.cadence.checkpoint_every
            );
        }
        if self.batch == 0 {
            invalid!("batch must be at least 1");
        }
        for (name, lr) in [("lr", self.lr), ("finetune_lr", self.finetune_lr)] {
            if !(lr.is_finite() && lr > 0.0) {
                invalid!("{name} {lr} must be positive and finite");
            }
        }
        for (name, b) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(0.0..1.0).contains(&b) {
                invalid!("{name} {b} must be in [0, 1)");
            }
        }
        for (name, w) in [
            ("l1_weight", self.l1_weight),
            ("gram_weight", self.gram_weight),
        ] {
            if !(w.is_finite() && w >= 0.0) {
                invalid!("{name} {w} must be non-negative and finite");
            }
        }
        if self.l1_weight == 0.0 && self.gram_weight == 0.0 {
            invalid!("l1_weight and gram_weight are both 0: nothing to train");
        }
        if self.gram_scales == 0 {
            invalid!("gram_scales must be at least 1");
        }
        let size = self.finetune_l1_size;
        if self.finetune_steps > 0 && (size == 0 || !resolution.is_multiple_of(size)) {
            invalid!(
                "finetune_l1_size {size} must divide the GAN's resolution {resolution} \
                 (the fine-tune's L1 compares {size}×{size} area downsamples)"
            );
        }
        if !(self.psi.is_finite() && self.psi >= 0.0) {
            invalid!("psi {} must be non-negative and finite", self.psi);
        }
        if self.max_nan_steps == 0 {
            invalid!("max_nan_steps must be at least 1");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_the_field() {
        let ok = TrainConfig::default();
        assert!(ok.validate(32).is_ok());
        let bad_size = TrainConfig {
            finetune_l1_size: 24,
            ..ok.clone()
        };
        let err = bad_size.validate(64).unwrap_err().to_string();
        assert!(
            err.contains("finetune_l1_size 24") && err.contains("64"),
            "{err}"
        );
        let bad_lr = TrainConfig {
            finetune_lr: -1.0,
            ..ok
        };
        assert!(
            bad_lr
                .validate(32)
                .unwrap_err()
                .to_string()
                .contains("finetune_lr")
        );
        assert_eq!(TrainConfig::default().stage_at(59_999), Stage::Aligned);
        assert_eq!(TrainConfig::default().stage_at(60_000), Stage::Finetune);
    }
}
