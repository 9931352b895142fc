//! The settings of a relief-prior training run ([`PriorSettings`], the flags of `photomat
//! train-prior`) and its saved configuration ([`PriorTrainConfig`], `train.json`): a fresh run
//! takes the defaults and every given setting, a resumed one keeps `train.json` and refuses a
//! setting that contradicts it, by the one merge rule of [`photomat_train::settings`] (the
//! library may move; the cadence of outputs may change).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use photomat_core::lookup;
use photomat_core::paths::absolute;
use photomat_train::settings::{Merged, OnResume, Setting, merge};
use serde::{Deserialize, Serialize};

use super::objective::LossWeights;
use crate::maps::colour_specs;
use crate::network::PriorConfig;

/// Largest batch: a 256² example holds about 150 MB of activations and gradients at the
/// default widths.
pub const MAX_BATCH: u32 = 64;

/// Everything a run depends on; `train.json` in the run folder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorTrainConfig {
    /// The material library (`photomat library import` output).
    pub library: PathBuf,
    /// Materials with these licences are left out of the training photos.
    pub exclude_licences: Vec<String>,
    /// Canonical specification of the model the prior predicts.
    pub brdf: String,
    pub architecture: PriorConfig,
    /// Side of the training crops (photos rendered at this side). Default 256.
    pub size: usize,
    /// Examples per step. Default 4.
    pub batch: usize,
    /// Adam's learning rate. Default 2e-4.
    pub lr: f64,
    /// Seed of the weights and of every example.
    pub seed: u64,
    pub weights: LossWeights,
    /// Flash positions per example in the rendering loss. Default 3.
    pub render_lights: usize,
    pub cadence: Cadence,
}

/// Steps between a run's periodic outputs; a resume may change them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Cadence {
    /// Steps between checkpoints. Default 100.
    pub checkpoint_every: u64,
    /// Steps between snapshots of the prior, each scored on validation photos (0: none).
    /// Default 500.
    pub snapshot_every: u64,
    /// Validation photos per score. Default 16.
    pub validation_count: u64,
}

impl Default for Cadence {
    fn default() -> Self {
        Self {
            checkpoint_every: 100,
            snapshot_every: 500,
            validation_count: 16,
        }
    }
}

impl PriorTrainConfig {
    /// Checks the fields, naming the one at fault.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.architecture.validate()?;
        if self.size == 0 || !self.size.is_multiple_of(self.architecture.total_stride()) {
            bail!(
                "size {} must be a positive multiple of the network's stride {}",
                self.size,
                self.architecture.total_stride()
            );
        }
        if self.batch == 0 || self.render_lights == 0 {
            bail!("batch and render_lights must be at least 1");
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            bail!("lr {} must be positive and finite", self.lr);
        }
        let w = &self.weights;
        if [w.maps, w.normal, w.render]
            .iter()
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            bail!("loss weights must be finite and ≥ 0, got {w:?}");
        }
        if self.cadence.checkpoint_every == 0 || self.cadence.validation_count == 0 {
            bail!("cadence.checkpoint_every and validation_count must be at least 1");
        }
        Ok(())
    }
}

/// The settings of a run, as given; `None` keeps the default (fresh) or the saved value
/// (resume).
#[derive(Debug, Clone, Default, PartialEq, clap::Args)]
pub struct PriorSettings {
    /// Material library (`photomat library import` output); photos of its train split are
    /// rendered on the fly. Taken from RUN/train.json with --resume (give it to relocate a
    /// moved library).
    #[arg(long, value_name = "LIB")]
    pub library: Option<PathBuf>,

    /// The model whose maps the prior predicts, e.g. "height(ggx)" or lambert: its maps must be
    /// colour maps (diffuse, specular, roughness) and a relief (height or normal).
    #[arg(long, value_name = "SPEC")]
    pub brdf: Option<String>,

    /// Leave out library materials with this licence (repeatable), e.g. GPL-3+ for a prior
    /// shipped under CC-BY-SA (docs/data.md, "Licences").
    #[arg(long, value_name = "LICENCE")]
    pub exclude_licence: Vec<String>,

    /// Side of the training crops [default: 256].
    #[arg(long, value_name = "PIXELS")]
    pub size: Option<usize>,

    /// Examples per step, at most 64 [default: 4].
    #[arg(long, value_name = "B", value_parser = clap::value_parser!(u32).range(1..=MAX_BATCH as i64))]
    pub batch: Option<u32>,

    /// Adam learning rate [default: 2e-4].
    #[arg(long, value_name = "LR")]
    pub lr: Option<f64>,

    /// Width multiplier of the network's channels (1: 24…160) [default: 1].
    #[arg(long, value_name = "W")]
    pub width: Option<f64>,

    /// Seed of the run: the initial weights and every example [default: 0].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,

    /// Weight of the normals' L1 [default: 2].
    #[arg(long, value_name = "W")]
    pub normal_weight: Option<f64>,

    /// Weight of the rendering loss [default: 1].
    #[arg(long, value_name = "W")]
    pub render_weight: Option<f64>,

    /// Steps between checkpoints [default: 100; on --resume the run's].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,

    /// Steps between snapshots, each scored on validation photos (0: none) [default: 500; on
    /// --resume the run's].
    #[arg(long, value_name = "N")]
    pub snapshot_every: Option<u64>,

    /// Validation photos per score [default: 16; on --resume the run's].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..=10_000))]
    pub validation_count: Option<u64>,
}

/// A row of [`PRIOR_SETTINGS`] for an optional setting `$name` setting `$place`.
macro_rules! row {
    ($on:expr, $flag:literal, $field:expr, $name:ident, |$c:ident| $place:expr) => {
        Setting {
            flag: $flag,
            field: $field,
            on_resume: $on,
            given: |s| s.$name.map(|v| v.to_string()),
            current: |$c| $place.to_string(),
            apply: |s, $c| {
                if let Some(v) = s.$name {
                    $place = v as _;
                }
            },
        }
    };
}

const FIXED: OnResume = OnResume::Fixed;
const CADENCE: OnResume = OnResume::MayChange { why: "" };

/// Every setting of a prior run, with its flag and its field of `train.json`.
pub const PRIOR_SETTINGS: [Setting<PriorSettings, PriorTrainConfig>; 13] = [
    Setting {
        flag: "--library",
        field: "library",
        on_resume: OnResume::MayChange {
            why: "the library moved; its materials must be the same",
        },
        given: |s| {
            s.library
                .as_deref()
                .map(|p| absolute(p).display().to_string())
        },
        current: |c| c.library.display().to_string(),
        apply: |s, c| {
            if let Some(p) = &s.library {
                c.library = absolute(p);
            }
        },
    },
    Setting {
        flag: "--brdf",
        field: "brdf",
        on_resume: FIXED,
        given: |s| {
            s.brdf
                .as_deref()
                .map(|b| lookup(b).map_or_else(|_| b.to_string(), |m| m.name()))
        },
        current: |c| c.brdf.clone(),
        // Set with the architecture it decides ([`PriorSettings::fresh_base`]).
        apply: |_, _| {},
    },
    Setting {
        flag: "--exclude-licence",
        field: "exclude_licences",
        on_resume: FIXED,
        given: |s| (!s.exclude_licence.is_empty()).then(|| s.exclude_licence.join(",")),
        current: |c| c.exclude_licences.join(","),
        apply: |s, c| c.exclude_licences = s.exclude_licence.clone(),
    },
    row!(FIXED, "--size", "size", size, |c| c.size),
    row!(FIXED, "--batch", "batch", batch, |c| c.batch),
    row!(FIXED, "--lr", "lr", lr, |c| c.lr),
    Setting {
        flag: "--width",
        field: "architecture.encoder_channels",
        on_resume: FIXED,
        given: |s| {
            s.width
                .map(|w| format!("{:?}", scaled(&PriorConfig::new(0), w).encoder_channels))
        },
        current: |c| format!("{:?}", c.architecture.encoder_channels),
        apply: |s, c| {
            if let Some(w) = s.width {
                let colour = c.architecture.colour_channels;
                c.architecture = scaled(&PriorConfig::new(colour), w);
            }
        },
    },
    row!(FIXED, "--seed", "seed", seed, |c| c.seed),
    row!(
        FIXED,
        "--normal-weight",
        "weights.normal",
        normal_weight,
        |c| c.weights.normal
    ),
    row!(
        FIXED,
        "--render-weight",
        "weights.render",
        render_weight,
        |c| c.weights.render
    ),
    row!(
        CADENCE,
        "--checkpoint-every",
        "cadence.checkpoint_every",
        checkpoint_every,
        |c| c.cadence.checkpoint_every
    ),
    row!(
        CADENCE,
        "--snapshot-every",
        "cadence.snapshot_every",
        snapshot_every,
        |c| c.cadence.snapshot_every
    ),
    row!(
        CADENCE,
        "--validation-count",
        "cadence.validation_count",
        validation_count,
        |c| c.cadence.validation_count
    ),
];

/// `config` with every width multiplied by `width` (rounded, at least 1).
fn scaled(config: &PriorConfig, width: f64) -> PriorConfig {
    let scale = |c: &usize| ((*c as f64 * width).round() as usize).max(1);
    PriorConfig {
        encoder_channels: config.encoder_channels.iter().map(scale).collect(),
        decoder_channels: config.decoder_channels.iter().map(scale).collect(),
        ..config.clone()
    }
}

impl PriorSettings {
    /// The configuration of the run: a fresh one from the defaults, or `saved` (read from
    /// `file`) with the changes a resume allows; then validated.
    pub fn merge(
        &self,
        saved: Option<(PriorTrainConfig, &Path)>,
    ) -> anyhow::Result<Merged<PriorTrainConfig>> {
        if let Some(w) = self.width
            && !(w.is_finite() && w > 0.0)
        {
            bail!("--width {w} must be positive and finite");
        }
        let (base, resumed_from) = match saved {
            Some((config, file)) => (config, Some(file)),
            None => (self.fresh_base()?, None),
        };
        let merged = merge(&PRIOR_SETTINGS, self, base, resumed_from)?;
        merged
            .config
            .validate()
            .context("invalid training settings")?;
        Ok(merged)
    }

    /// The defaults of a fresh run for the library and model these settings name.
    fn fresh_base(&self) -> anyhow::Result<PriorTrainConfig> {
        let Some(library) = &self.library else {
            bail!("--library LIB is required for a new run (a `photomat library import` output)");
        };
        let Some(spec) = &self.brdf else {
            bail!("--brdf SPEC is required for a new run, e.g. \"height(ggx)\"");
        };
        let brdf = lookup(spec).context("invalid --brdf")?;
        let colour: usize = colour_specs(&brdf).iter().map(|s| s.channels).sum();
        Ok(PriorTrainConfig {
            library: absolute(library),
            exclude_licences: Vec::new(),
            brdf: brdf.name(),
            architecture: PriorConfig::new(colour),
            size: 256,
            batch: 4,
            lr: 2e-4,
            seed: 0,
            weights: LossWeights::default(),
            render_lights: 3,
            cadence: Cadence::default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use photomat_brdfs as _;

    use super::*;

    #[test]
    fn a_resume_refuses_another_model_or_width_and_takes_another_cadence() {
        let fresh = PriorSettings {
            library: Some("lib".into()),
            brdf: Some("height(ggx)".into()),
            width: Some(0.5),
            ..PriorSettings::default()
        };
        let saved = fresh.merge(None).unwrap().config;
        assert_eq!(saved.architecture.encoder_channels, [12, 24, 48, 64, 80]);
        assert_eq!(saved.architecture.colour_channels, 7);
        let file = Path::new("run/train.json");
        let later = PriorSettings {
            snapshot_every: Some(50),
            width: Some(0.5),
            ..PriorSettings::default()
        };
        let merged = later.merge(Some((saved.clone(), file))).unwrap();
        assert_eq!(merged.config.cadence.snapshot_every, 50);
        assert_eq!(merged.config.architecture, saved.architecture);
        let other = PriorSettings {
            brdf: Some("lambert".into()),
            width: Some(1.0),
            ..PriorSettings::default()
        };
        let err = other.merge(Some((saved, file))).unwrap_err().to_string();
        assert!(
            err.contains("--brdf lambert contradicts") && err.contains("--width"),
            "{err}"
        );
    }
}
