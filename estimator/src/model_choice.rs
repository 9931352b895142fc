//! Which BRDF model a sampled or captured material gets (`docs/trade.md`, "Choosing per
//! material"; `photomat sample` and `photomat capture`).
//!
//! A model folder holds its default estimator E at the root (`estimator.json` +
//! `estimator.safetensors`) and may hold more under `estimators/<name>/`, one per BRDF model,
//! all reading the same GAN's features. [`BrdfChoice`] says which to use: the default, one by
//! name, or **auto**: per material, every estimator decodes the material, each analytic render
//! is compared with M's relighting under the run's lights, and the material gets the cheapest
//! model whose error is within `tolerance` of the best one's (`E ≤ (1 + tolerance) · E_best`).
//! The error E is the L1 of *linear* radiance (the display images raised to 2.2): the display
//! encoding compresses a highlight's core, so an image-wide L1 of display values let a model
//! without any highlight (`lambert`) pass on materials whose highlight is small and dim.
//! "Cheapest" orders models by their map channels n (what a renderer stores, reads and
//! evaluates per texel; `lambert` 6 < `height(ggx)` 8 < `ggx` 10 < `coated` 11), ties by name
//! ([`cost_key`]): a fixed order, so a seed still names the same files on every run, where a
//! timed order could change with the machine's load.

use std::path::Path;

use anyhow::{Context, bail};
use candle_core::Device;
use serde::{Deserialize, Serialize};

use crate::EstimatorModel;
use crate::model_files::ESTIMATOR_MANIFEST_FILE;

/// Folder of a model folder's additional estimators, one sub-folder per BRDF model.
pub const ESTIMATORS_DIR: &str = "estimators";

/// Default `--tolerance` of auto: 10 % above the best model's L1, about the spread of one
/// estimator's L1 between training runs with different seeds.
pub const DEFAULT_TOLERANCE: f64 = 0.10;

/// Which estimator (and so which BRDF model) the materials of a run get.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum BrdfChoice {
    /// The model folder's root estimator.
    #[default]
    Default,
    /// The estimator of this specification (canonical names are compared).
    Named(String),
    /// Per material, the cheapest model within `tolerance` (relative) of the best
    /// linear-radiance L1.
    Auto { tolerance: f64 },
}

impl BrdfChoice {
    /// `auto`, or a specification of a registered model (checked here, before any model
    /// folder loads; kept in its canonical form).
    pub fn parse(text: &str, tolerance: f64) -> anyhow::Result<Self> {
        if text.trim() == "auto" {
            if !(tolerance.is_finite() && tolerance >= 0.0) {
                bail!("the tolerance must be a number ≥ 0, got {tolerance}");
            }
            Ok(Self::Auto { tolerance })
        } else {
            let brdf = photomat_core::lookup(text).context("invalid --brdf")?;
            Ok(Self::Named(brdf.name()))
        }
    }

    /// Whether this is [`BrdfChoice::Auto`].
    pub fn is_auto(&self) -> bool {
        matches!(self, BrdfChoice::Auto { .. })
    }
}

/// One candidate's score on one material.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Canonical specification.
    pub brdf: String,
    /// Map channels n: the cost order.
    pub channels: usize,
    /// L1 of its analytic render against M's relighting, display-encoded, mean over the run's
    /// lights (the figure `summary.json` reports).
    pub l1: f64,
    /// The same on linear radiance (display values raised to 2.2): the error auto compares.
    pub l1_linear: f64,
}

/// How a material's model was chosen: written into its `material.json` as `selection`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    /// The chosen specification.
    pub chosen: String,
    /// Relative tolerance over the best linear-radiance L1.
    pub tolerance: f64,
    /// Every candidate, cheapest first.
    pub candidates: Vec<Candidate>,
}

/// The index of the cheapest candidate within `tolerance` of the best linear-radiance L1;
/// `candidates` must be sorted cheapest first. A non-finite error never qualifies.
pub fn choose(candidates: &[Candidate], tolerance: f64) -> Option<usize> {
    let best = candidates
        .iter()
        .map(|c| c.l1_linear)
        .filter(|e| e.is_finite())
        .fold(f64::INFINITY, f64::min);
    candidates
        .iter()
        .position(|c| c.l1_linear.is_finite() && c.l1_linear <= best * (1.0 + tolerance))
}

/// The cost order of estimators: fewer map channels first, then the model's name.
pub fn cost_key(estimator: &EstimatorModel) -> (usize, String) {
    (estimator.brdf().channels(), estimator.brdf().name())
}

/// Every estimator of the model folder `dir`: the root one first, then those of
/// `estimators/*/` sorted cheapest first ([`cost_key`]). Each must read
/// `feature_channels` features, and no two may decode into the same model.
pub fn load_estimators(
    dir: &Path,
    feature_channels: usize,
    device: &Device,
) -> anyhow::Result<Vec<EstimatorModel>> {
    let mut folders = vec![dir.to_path_buf()];
    let extra = dir.join(ESTIMATORS_DIR);
    if extra.is_dir() {
        let mut subfolders: Vec<_> = std::fs::read_dir(&extra)
            .with_context(|| format!("cannot list {}", extra.display()))?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .filter(|path| path.join(ESTIMATOR_MANIFEST_FILE).is_file())
            .collect();
        subfolders.sort();
        folders.extend(subfolders);
    }
    let mut estimators: Vec<EstimatorModel> = Vec::new();
    for folder in &folders {
        let estimator = EstimatorModel::load(folder, device)
            .with_context(|| format!("cannot load the estimator in '{}'", folder.display()))?;
        let reads = estimator.estimator().config().in_channels;
        if reads != feature_channels {
            bail!(
                "the estimator in '{}' reads {reads} feature channels but the GAN produces \
                 {feature_channels} (estimator.json and gan.json come from different runs)",
                folder.display()
            );
        }
        let name = estimator.brdf().name();
        if estimators.iter().any(|e| e.brdf().name() == name) {
            bail!(
                "two estimators of '{}' decode into '{name}'; keep one",
                dir.display()
            );
        }
        estimators.push(estimator);
    }
    estimators[1..].sort_by_cached_key(cost_key);
    Ok(estimators)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn candidate(brdf: &str, channels: usize, l1_linear: f64) -> Candidate {
        Candidate {
            brdf: brdf.into(),
            channels,
            l1: 0.0,
            l1_linear,
        }
    }

    #[test]
    fn auto_takes_the_cheapest_model_within_the_tolerance() {
        let c = [
            candidate("lambert", 6, 0.050),
            candidate("height(ggx)", 8, 0.040),
            candidate("coated", 11, 0.038),
        ];
        // 0.050 > 1.1 · 0.038 = 0.0418 ≥ 0.040: height(ggx).
        assert_eq!(choose(&c, 0.10), Some(1));
        // 0.050 ≤ 1.5 · 0.038: lambert.
        assert_eq!(choose(&c, 0.5), Some(0));
        // No slack: the best.
        assert_eq!(choose(&c, 0.0), Some(2));
    }

    #[test]
    fn auto_skips_non_finite_errors() {
        let c = [
            candidate("lambert", 6, f64::NAN),
            candidate("ggx", 10, 0.04),
        ];
        assert_eq!(choose(&c, 10.0), Some(1));
        assert_eq!(choose(&[candidate("x", 1, f64::INFINITY)], 0.1), None);
    }

    #[test]
    fn choice_parses_auto_and_names() {
        assert_eq!(
            BrdfChoice::parse("auto", 0.2).unwrap(),
            BrdfChoice::Auto { tolerance: 0.2 }
        );
        assert_eq!(
            BrdfChoice::parse("coated", 0.2).unwrap(),
            BrdfChoice::Named("coated".into())
        );
        assert!(BrdfChoice::parse("auto", -1.0).is_err());
    }
}
