//! The full configuration of a GAN training run ([`TrainConfig`], serialised as the run
//! folder's `train.json`): the architecture ([`GeneratorConfig`]), the data set path and every
//! hyper-parameter of StyleGAN2-ADA's training loop that PhotoMat uses, with the
//! reference defaults (docs/conventions.md).
//!
//! [`config_differences`] compares two configurations field by field (dotted JSON paths such
//! as `generator.resolution`), so that resuming a run with a contradicting setting fails
//! naming the field.

use std::path::PathBuf;

use candle_core::{Result, bail};
use photomat_train::AdamConfig;
use serde::{Deserialize, Serialize};

use crate::GeneratorConfig;

/// StyleGAN2's R1 weight heuristic: γ = 0.0002 · R² / batch (StyleGAN2-ADA `train.py`, `auto`
/// configuration).
pub fn default_r1_gamma(resolution: usize, batch: usize) -> f64 {
    0.0002 * (resolution * resolution) as f64 / batch as f64
}

/// Everything a training run depends on; `train.json` in the run folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// Architecture of G, M and D.
    pub generator: GeneratorConfig,
    /// The prepared data set folder (`photomat prepare` output).
    pub data: PathBuf,
    /// Images per step (for G's and D's phases alike). Default 4.
    pub batch: usize,
    /// Seed of the run: initial weights, latents, noise, crops, lights, rolls, style mixing.
    pub seed: u64,
    /// Base learning rate of G (and M) and D before the lazy-regularisation correction.
    /// Default 0.0025 (the reference at 256²).
    pub lr: f64,
    /// Adam's β₁. Default 0 (StyleGAN2).
    pub beta1: f64,
    /// Adam's β₂. Default 0.99 (StyleGAN2).
    pub beta2: f64,
    /// Adam's ε. Default 1e-8 (StyleGAN2).
    pub eps: f64,
    /// R1 weight γ; default [`default_r1_gamma`].
    pub r1_gamma: f64,
    /// Steps between lazy R1 penalties on D. Default 16.
    pub r1_interval: usize,
    /// G's lazy-regularisation interval: the path-length penalty runs every this many steps
    /// when `pl_weight` > 0, and G's Adam gets the lazy correction c = k/(k+1) either way, as
    /// in the reference (StyleGAN2-ADA). Default 4; 0 disables both.
    pub g_reg_interval: usize,
    /// Weight of the path-length regularisation ([`super::path_length`]); 0 disables it.
    /// Default 0 (the reference uses 2; it costs about a G forward and a double backward on
    /// half a batch every `g_reg_interval` steps). Absent from older `train.json` files: 0.
    #[serde(default)]
    pub pl_weight: f64,
    /// Probability that a batch mixes two latents' styles. Default 0.9.
    pub style_mixing_prob: f64,
    /// EMA half-life of G_ema in thousands of images. Default 10 · batch / 32 (StyleGAN2-ADA
    /// `auto`: 10 k images per batch of 32).
    pub ema_kimg: f64,
    /// EMA ramp-up: the half-life is at most `ema_rampup` × images seen so far (StyleGAN2-ADA
    /// `auto`: 0.05); `None` disables it.
    pub ema_rampup: Option<f64>,
    /// Consecutive steps with a skipped (non-finite) update after which training stops.
    /// Default 20.
    pub nan_limit: usize,
    /// Native-scale patch training, present exactly when the generator is spatial
    /// ([`GeneratorConfig::spatial`]): reals are R×R patches of the photos at their prepared
    /// size, fakes R×R windows of larger periodic samples. Absent from (and not written to)
    /// the `train.json` of fixed-size runs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub patches: Option<PatchTraining>,
    /// Weight λ of D's light-mismatch term ([`super::loss::discriminator_loss`]): real images
    /// shown under another sample's lights count as fakes, so that D must check that the
    /// highlight and falloff agree with ω (the matching-aware discriminator of Reed et al.
    /// 2016, "Generative Adversarial Text to Image Synthesis", §4.1). Default
    /// [`DEFAULT_LIGHT_MISMATCH`]; absent from older `train.json` files: 0 (the term off).
    #[serde(default)]
    pub light_mismatch: f64,
    /// Steps between the run's periodic outputs, so that a resumed run keeps them. Absent
    /// from older `train.json` files: [`Cadence::default`], the flags' defaults then.
    #[serde(default)]
    pub cadence: Cadence,
}

/// Steps between a run's periodic outputs. They do not change what the run trains: a resume
/// may give others ([`TrainConfig::with_resume_changes`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cadence {
    /// Steps between checkpoints (state and GAN model folder); at least 1.
    pub checkpoint_every: u64,
    /// Steps between sample grids; at least 1.
    pub sample_every: u64,
    /// Steps between SWD measurements (0: never).
    pub swd_every: u64,
    /// Fakes and real crops per SWD measurement; at least 1.
    pub swd_count: u64,
    /// Steps between snapshots of G_ema + M, each a GAN model folder
    /// `snapshots/step-NNNNNN/` of the run (0: none; absent from older `train.json` files).
    /// A run's quality swings between checkpoints a thousand steps apart, so the model to keep
    /// is picked afterwards by measuring the snapshots (`photomat_data::snapshots`).
    #[serde(default)]
    pub snapshot_every: u64,
}

impl Default for Cadence {
    fn default() -> Self {
        Self {
            checkpoint_every: 500,
            sample_every: 500,
            swd_every: 1000,
            swd_count: 64,
            snapshot_every: 0,
        }
    }
}

/// Default [`TrainConfig::light_mismatch`]. Without the term, D conditioned on ω by
/// concatenation alone let M ignore the light: a 13-kimg spatial run and a 6.4-kimg fixed-size
/// run on real photos rendered every material the same under all four preview lights
/// (docs/benchmarks/gan-training.md, "Light following"). With weight 1 a real under wrong lights
/// weighs as much as a fake.
pub const DEFAULT_LIGHT_MISMATCH: f64 = 1.0;

/// How a spatial G trains on patches (docs/conventions.md, "Training patches").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PatchTraining {
    /// Probability that a real patch (and a fake's light placement) is placed so that the
    /// photo's highlight lies inside it; otherwise the patch position is uniform over the
    /// photo. Default [`DEFAULT_HIGHLIGHT_PROB`].
    pub highlight_prob: f64,
    /// Extra base cells per side of the fakes: G makes samples of R + margin · cell texels,
    /// periodic at that side, and D sees a random R×R window of each, so that fakes are not
    /// R-periodic where real patches are not. Default 1 (G then costs ((R + cell)/R)² as
    /// much: 1.56× at R = 64 with its 16-texel cells); 0 trains on R-periodic fakes.
    pub margin_cells: usize,
}

/// Default [`PatchTraining::highlight_prob`]. Under uniform positions a 64² patch of a 512²
/// photo holds the (near-centred) highlight with probability (64/449)² ≈ 2 %
/// (`photomat_data::patch::uniform_highlight_inside` measures it per data set): M and D would
/// see the specular peak in one patch of fifty. With ½ every other patch shows it, as every
/// whole-photo crop did, while the other half keep the photo's native mix of regions.
pub const DEFAULT_HIGHLIGHT_PROB: f64 = 0.5;

impl Default for PatchTraining {
    fn default() -> Self {
        Self {
            highlight_prob: DEFAULT_HIGHLIGHT_PROB,
            margin_cells: 1,
        }
    }
}

impl TrainConfig {
    /// The reference hyper-parameters for `generator`, `data`, `batch` and `seed`.
    pub fn new(generator: GeneratorConfig, data: PathBuf, batch: usize, seed: u64) -> Self {
        let adam = AdamConfig::default();
        // batch 0 is rejected by validate(); the max only keeps γ finite until then.
        let r1_gamma = default_r1_gamma(generator.resolution, batch.max(1));
        let spatial = generator.spatial.is_some();
        Self {
            generator,
            data,
            batch,
            seed,
            lr: adam.lr,
            beta1: adam.beta1,
            beta2: adam.beta2,
            eps: adam.eps,
            r1_gamma,
            r1_interval: 16,
            g_reg_interval: 4,
            pl_weight: 0.0,
            style_mixing_prob: 0.9,
            ema_kimg: 10.0 * batch as f64 / 32.0,
            ema_rampup: Some(0.05),
            nan_limit: 20,
            patches: spatial.then(PatchTraining::default),
            light_mismatch: DEFAULT_LIGHT_MISMATCH,
            cadence: Cadence::default(),
        }
    }

    /// `self` (a saved configuration) with the fields that a resume may change taken from
    /// `requested`: where the data set lives, the base learning rate (what the message of a
    /// diverged run recommends lowering; `log.csv` records it per step) and the cadence of
    /// outputs. Everything else must stay as saved for the run to continue the same training.
    pub fn with_resume_changes(&self, requested: &TrainConfig) -> TrainConfig {
        let mut generator = self.generator.clone();
        // Relief may be switched on for a run without it: M's height projection starts at
        // zero, which leaves every output unchanged (`crate::relief`); never off again.
        generator.relief |= requested.generator.relief;
        TrainConfig {
            data: requested.data.clone(),
            lr: requested.lr,
            cadence: requested.cadence,
            generator,
            ..self.clone()
        }
    }

    /// Adam settings of G and M (lazy correction for `g_reg_interval`).
    pub fn adam_g(&self) -> AdamConfig {
        self.adam_base().lazy(self.g_reg_interval)
    }

    /// Adam settings of D (lazy correction for `r1_interval`).
    pub fn adam_d(&self) -> AdamConfig {
        self.adam_base().lazy(self.r1_interval)
    }

    fn adam_base(&self) -> AdamConfig {
        AdamConfig {
            lr: self.lr,
            beta1: self.beta1,
            beta2: self.beta2,
            eps: self.eps,
        }
    }

    /// Checks every field; errors name the field and its value.
    pub fn validate(&self) -> Result<()> {
        self.generator.validate()?;
        if self.batch == 0 {
            bail!("batch must be at least 1");
        }
        self.adam_base().validate()?;
        if !(self.r1_gamma.is_finite() && self.r1_gamma >= 0.0) {
            bail!("r1_gamma {} must be finite and ≥ 0", self.r1_gamma);
        }
        if self.r1_interval == 0 {
            bail!("r1_interval must be at least 1");
        }
        if !(self.pl_weight.is_finite() && self.pl_weight >= 0.0) {
            bail!("pl_weight {} must be finite and ≥ 0", self.pl_weight);
        }
        if !(self.light_mismatch.is_finite() && self.light_mismatch >= 0.0) {
            bail!(
                "light_mismatch {} must be finite and ≥ 0",
                self.light_mismatch
            );
        }
        if self.pl_weight > 0.0 && self.g_reg_interval == 0 {
            bail!("path-length regularisation (pl_weight > 0) needs g_reg_interval ≥ 1");
        }
        if !(0.0..=1.0).contains(&self.style_mixing_prob) {
            bail!(
                "style_mixing_prob {} must be in [0, 1]",
                self.style_mixing_prob
            );
        }
        if !(self.ema_kimg.is_finite() && self.ema_kimg >= 0.0) {
            bail!("ema_kimg {} must be finite and ≥ 0", self.ema_kimg);
        }
        if let Some(r) = self.ema_rampup
            && !(r.is_finite() && r > 0.0)
        {
            bail!("ema_rampup {r} must be positive and finite");
        }
        if self.nan_limit == 0 {
            bail!("nan_limit must be at least 1");
        }
        let c = &self.cadence;
        if c.checkpoint_every == 0 || c.sample_every == 0 || c.swd_count == 0 {
            bail!(
                "cadence.checkpoint_every, sample_every and swd_count must be at least 1 \
                 (got {}, {}, {})",
                c.checkpoint_every,
                c.sample_every,
                c.swd_count
            );
        }
        match (&self.generator.spatial, &self.patches) {
            (Some(_), None) => bail!("a spatial generator trains on patches: set `patches`"),
            (None, Some(_)) => {
                bail!("`patches` needs a spatial generator (generator.spatial)")
            }
            (Some(_), Some(p)) if !(0.0..=1.0).contains(&p.highlight_prob) => bail!(
                "patches.highlight_prob {} must be in [0, 1]",
                p.highlight_prob
            ),
            _ => {}
        }
        Ok(())
    }
}

/// The fields in which `a` and `b` differ, as `path: a-value ≠ b-value` strings with dotted
/// paths (`generator.channel_multiplier: 0.25 ≠ 0.125`), sorted by path.
pub fn config_differences(a: &TrainConfig, b: &TrainConfig) -> Vec<String> {
    let (Ok(va), Ok(vb)) = (serde_json::to_value(a), serde_json::to_value(b)) else {
        return vec!["configuration cannot be serialised".into()];
    };
    let mut out = Vec::new();
    diff_values("", &va, &vb, &mut out);
    out.sort();
    out
}

fn diff_values(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(ma), Value::Object(mb)) => {
            let keys: std::collections::BTreeSet<&String> = ma.keys().chain(mb.keys()).collect();
            for k in keys {
                let p = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                diff_values(
                    &p,
                    ma.get(k).unwrap_or(&Value::Null),
                    mb.get(k).unwrap_or(&Value::Null),
                    out,
                );
            }
        }
        _ if a != b => out.push(format!("{path}: {a} ≠ {b}")),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_the_reference() {
        let g = GeneratorConfig {
            resolution: 64,
            ..Default::default()
        };
        let c = TrainConfig::new(g, "data".into(), 4, 1);
        c.validate().unwrap();
        assert!((c.r1_gamma - 0.0002 * 4096.0 / 4.0).abs() < 1e-12);
        assert!((c.ema_kimg - 1.25).abs() < 1e-12);
        assert!((c.adam_d().lr - 0.0025 * 16.0 / 17.0).abs() < 1e-15);
        assert!((c.adam_g().lr - 0.0025 * 0.8).abs() < 1e-15);
    }

    #[test]
    fn differences_name_the_field() {
        let a = TrainConfig::new(GeneratorConfig::default(), "d".into(), 4, 1);
        let mut b = a.clone();
        assert!(config_differences(&a, &b).is_empty());
        b.generator.channel_multiplier = 0.5;
        b.seed = 2;
        let d = config_differences(&a, &b);
        assert_eq!(d.len(), 2, "{d:?}");
        assert!(
            d[0].starts_with("generator.channel_multiplier: 1.0 ≠ 0.5"),
            "{d:?}"
        );
        assert!(d[1].starts_with("seed: 1 ≠ 2"), "{d:?}");
    }
}
