//! The settings of an estimator training run ([`EstimatorSettings`], the flags of
//! `photomat train-estimator`) and how they become the run's [`TrainManifest`]: the defaults of
//! a fresh run for the GAN and BRDF model it names, then the one merge rule of
//! [`photomat_train::settings`] over [`ESTIMATOR_SETTINGS`]. A resume refuses every setting
//! that contradicts `train.json` but the step counts, which may grow, and the cadence of
//! outputs.
//!
//! [`EstimatorSettings`] is also the command line's argument group: each field's doc comment is
//! its `--help` text, so a flag is declared once.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use photomat_core::lookup;
use photomat_core::paths::absolute;
use photomat_generator::model_files::read_gan_manifest;
use photomat_train::settings::{Merged, OnResume, Setting, merge};

use super::config::TrainConfig;
use super::state::TrainManifest;
use crate::EstimatorConfig;

/// Default stage-1 steps for a new run (the paper trains 60 k; CPU runs set fewer).
pub const DEFAULT_STEPS: u64 = 60_000;
/// Default fine-tune steps for a new run (the paper trains 60 k).
pub const DEFAULT_FINETUNE_STEPS: u64 = 60_000;
/// Largest batch a run accepts: a 256² UNet step holds about 60 MB per material at width 1,
/// so 256 materials already need more than a workstation's memory (`photomat_core::memory`
/// checks the actual estimate before a run starts).
pub const MAX_BATCH: usize = 256;

/// The settings of a run, as given; `None` keeps the default for a fresh run and the saved
/// value for a resumed one.
#[derive(Debug, Clone, Default, PartialEq, clap::Args)]
pub struct EstimatorSettings {
    /// GAN model folder (`photomat train-gan` output: gan.json + gan.safetensors). Taken from
    /// RUN_E/train.json with --resume.
    #[arg(long, value_name = "RUN")]
    pub gan: Option<PathBuf>,

    /// BRDF model E decodes into, e.g. `ggx`, `height(ggx)`, `coated` (`photomat brdfs` lists
    /// them). Taken from RUN_E/train.json with --resume.
    #[arg(long, value_name = "SPEC")]
    pub brdf: Option<String>,

    /// Steps of stage 1 (aligned L1 + Gram) [default: 60000, the paper's].
    #[arg(long, value_name = "N")]
    pub steps: Option<u64>,

    /// Steps of stage 2, the fine-tune with rolled maps [default: 60000, the paper's].
    #[arg(long, value_name = "M")]
    pub finetune_steps: Option<u64>,

    /// Materials per step, at most 256 [default: 4].
    #[arg(long, value_name = "B",
          value_parser = clap::value_parser!(u32).range(1..=MAX_BATCH as i64))]
    pub batch: Option<u32>,

    /// Adam learning rate of stage 1 [default: 1e-4].
    #[arg(long, value_name = "LR")]
    pub lr: Option<f64>,

    /// Adam learning rate of the fine-tune [default: 5e-5].
    #[arg(long, value_name = "LR")]
    pub finetune_lr: Option<f64>,

    /// VGG19 weights (safetensors, torchvision's `vgg19().features` names
    /// `features.{0,2,5,…,34}.{weight,bias}`) for the Gram loss; without it a seeded random
    /// conv bank is used.
    #[arg(long, value_name = "FILE", long_help = VGG19_HELP)]
    pub vgg19: Option<PathBuf>,

    /// Width multiplier of E's channels (1 = the paper's 32…256; 0.25 for CPU training)
    /// [default: 1].
    #[arg(long, value_name = "W")]
    pub width: Option<f64>,

    /// Seed of the run: E's initial weights, every step's materials, lights and rolls
    /// [default: 0].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,

    /// Steps between training panels in RUN_E/panels/ [default: 500; on --resume the run's,
    /// from train.json].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub panel_every: Option<u64>,

    /// Steps between checkpoints [default: 500; on --resume the run's].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,
}

/// `--help` text of `--vgg19`: what the file holds and how to write it.
const VGG19_HELP: &str = "VGG19 weights for the Gram loss, as a safetensors file with \
torchvision's `vgg19().features` tensors `features.{0,2,5,7,10,12,14,16,19,21,23,25,28,30,32,34}.{weight,bias}` \
(max-pools are replaced by average pools; features after pool1–pool5, ImageNet-normalised input). \
Write it once with PyTorch, torchvision and safetensors:

  import torchvision
  from safetensors.torch import save_file
  vgg = torchvision.models.vgg19(weights=torchvision.models.VGG19_Weights.IMAGENET1K_V1)
  save_file({f\"features.{k}\": v.contiguous() for k, v in vgg.features.state_dict().items()}, \"vgg19.safetensors\")

Without --vgg19, a seeded random conv bank with the same five pooled stages (3→16→32→64→64→64) \
gives the Gram statistics (Ustyuzhaninov et al. 2017).";

/// E's encoder widths at width multiplier `width`, as text (what a resume compares).
fn encoder_widths(width: f64) -> String {
    match EstimatorConfig::default().with_width(width) {
        Ok(config) => format!("encoder widths {:?}", config.encoder_channels),
        Err(e) => e.to_string(),
    }
}

/// The canonical name of a model specification, or the specification as given when it does
/// not name a registered model (the fresh run's lookup reports that).
fn canonical_brdf(spec: &str) -> String {
    lookup(spec).map_or_else(|_| spec.to_string(), |brdf| brdf.name())
}

/// A row of [`ESTIMATOR_SETTINGS`] for an optional setting `$name` that sets the training
/// configuration's field `$place` (converted by `as`).
macro_rules! row {
    ($on:expr, $flag:literal, $name:ident, |$c:ident| $place:expr) => {
        Setting {
            flag: $flag,
            field: concat!("config.", stringify!($name)),
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
/// The step counts may grow when a run resumes (a longer run continues the same training).
const LONGER: OnResume = OnResume::MayChange {
    why: "a longer run continues the same training",
};
/// The cadence of outputs does not change what the run trains.
const CADENCE: OnResume = OnResume::MayChange { why: "" };

/// Every setting of an estimator run, with its flag and its field of `train.json`.
pub const ESTIMATOR_SETTINGS: [Setting<EstimatorSettings, TrainManifest>; 12] = [
    Setting {
        flag: "--gan",
        field: "gan",
        on_resume: FIXED,
        given: |s| s.gan.as_deref().map(|g| absolute(g).display().to_string()),
        current: |c| c.gan.display().to_string(),
        apply: |s, c| {
            if let Some(g) = &s.gan {
                c.gan = absolute(g);
            }
        },
    },
    Setting {
        flag: "--brdf",
        field: "brdf",
        on_resume: FIXED,
        given: |s| s.brdf.as_deref().map(canonical_brdf),
        current: |c| c.brdf.clone(),
        apply: |s, c| {
            if let Some(spec) = &s.brdf {
                c.brdf = canonical_brdf(spec);
            }
        },
    },
    Setting {
        flag: "--width",
        field: "architecture.encoder_channels",
        on_resume: FIXED,
        given: |s| s.width.map(encoder_widths),
        current: |c| format!("encoder widths {:?}", c.architecture.encoder_channels),
        // From the reference widths, so that applying the saved width again changes nothing.
        apply: |s, c| {
            let reference = EstimatorConfig {
                in_channels: c.architecture.in_channels,
                out_channels: c.architecture.out_channels,
                ..EstimatorConfig::default()
            };
            if let Some(width) = s.width
                && let Ok(scaled) = reference.with_width(width)
            {
                c.architecture = scaled;
            }
        },
    },
    row!(LONGER, "--steps", steps, |c| c.config.steps),
    row!(LONGER, "--finetune-steps", finetune_steps, |c| c
        .config
        .finetune_steps),
    row!(FIXED, "--batch", batch, |c| c.config.batch),
    row!(FIXED, "--lr", lr, |c| c.config.lr),
    row!(FIXED, "--finetune-lr", finetune_lr, |c| c
        .config
        .finetune_lr),
    Setting {
        flag: "--vgg19",
        field: "config.vgg19",
        on_resume: FIXED,
        given: |s| {
            s.vgg19
                .as_deref()
                .map(|v| absolute(v).display().to_string())
        },
        current: |c| {
            c.config
                .vgg19
                .as_deref()
                .map_or("none".into(), |v| v.display().to_string())
        },
        apply: |s, c| {
            if let Some(v) = &s.vgg19 {
                c.config.vgg19 = Some(absolute(v));
            }
        },
    },
    row!(FIXED, "--seed", seed, |c| c.config.seed),
    Setting {
        field: "config.cadence.panel_every",
        ..row!(CADENCE, "--panel-every", panel_every, |c| c
            .config
            .cadence
            .panel_every)
    },
    Setting {
        field: "config.cadence.checkpoint_every",
        ..row!(CADENCE, "--checkpoint-every", checkpoint_every, |c| c
            .config
            .cadence
            .checkpoint_every)
    },
];

impl EstimatorSettings {
    /// The manifest of the run: a fresh one for the GAN and model these settings name (whose
    /// `gan.json` is read for E's input width and the GAN's resolution), or the saved one of
    /// `run/train.json` (`saved`) with the changes a resume allows; then validated.
    pub fn merge(
        &self,
        saved: Option<(TrainManifest, &Path)>,
    ) -> anyhow::Result<Merged<TrainManifest>> {
        if let Some(width) = self.width {
            EstimatorConfig::default()
                .with_width(width)
                .context("invalid --width")?;
        }
        let (base, resumed_from) = match saved {
            Some((manifest, file)) => (manifest, Some(file)),
            None => (self.fresh_base()?, None),
        };
        merge(&ESTIMATOR_SETTINGS, self, base, resumed_from)
    }

    /// The manifest a fresh run starts from before its settings are merged: the GAN folder and
    /// model it names, E's reference architecture for them, the reference training settings.
    fn fresh_base(&self) -> anyhow::Result<TrainManifest> {
        let Some(gan) = self.gan.as_deref().map(absolute) else {
            bail!("--gan RUN is required for a new run (a `photomat train-gan` output folder)");
        };
        let Some(spec) = &self.brdf else {
            bail!("--brdf SPEC is required for a new run (`photomat brdfs` lists the models)");
        };
        let brdf = lookup(spec).context("invalid --brdf")?;
        let gan_config = read_gan_manifest(&gan)
            .with_context(|| format!("cannot load the GAN model {}", gan.display()))?
            .architecture;
        Ok(TrainManifest {
            brdf: brdf.name(),
            architecture: EstimatorConfig {
                in_channels: gan_config.feature_channels,
                out_channels: brdf.channels(),
                ..EstimatorConfig::default()
            },
            config: TrainConfig {
                steps: DEFAULT_STEPS,
                finetune_steps: DEFAULT_FINETUNE_STEPS,
                ..TrainConfig::default()
            },
            gan,
            step: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn saved() -> TrainManifest {
        TrainManifest {
            brdf: "lambert".into(),
            architecture: EstimatorConfig::default().with_width(0.25).unwrap(),
            config: TrainConfig::default(),
            gan: PathBuf::from("/runs/gan"),
            step: 10,
        }
    }

    #[test]
    fn a_resume_lets_the_steps_grow_and_refuses_another_width_or_batch() {
        let file = Path::new("/runs/e/train.json");
        let longer = EstimatorSettings {
            steps: Some(90_000),
            width: Some(0.25),
            ..EstimatorSettings::default()
        };
        let merged = longer.merge(Some((saved(), file))).unwrap();
        assert_eq!(merged.config.config.steps, 90_000);
        assert_eq!(merged.config.architecture, saved().architecture);
        assert_eq!(merged.notes.len(), 1, "{:?}", merged.notes);
        let other = EstimatorSettings {
            width: Some(0.5),
            batch: Some(8),
            ..EstimatorSettings::default()
        };
        let err = other.merge(Some((saved(), file))).unwrap_err().to_string();
        assert!(
            err.contains("--width encoder widths [16, 32, 64, 128, 128]")
                && err.contains("--batch 8 contradicts config.batch = 4"),
            "{err}"
        );
    }
}
