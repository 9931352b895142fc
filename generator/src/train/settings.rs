//! The settings of a GAN training run ([`GanSettings`], the flags of `photomat train-gan`) and
//! how they become the run's [`TrainConfig`]: the defaults of a fresh run, then the one merge
//! rule of [`photomat_train::settings`] over the table [`GAN_SETTINGS`] (a resume keeps
//! `train.json` and refuses a fixed setting that contradicts it; the data folder may move, the
//! learning rate and the cadence of outputs may change, relief may be switched on).
//!
//! [`GanSettings`] is also the command line's argument group: each field's doc comment is its
//! `--help` text, so a flag is declared once.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use anyhow::bail;
use photomat_core::paths::absolute;
use photomat_train::settings::{Merged, OnResume, Setting, merge};

use super::config::TrainConfig;
use crate::relight::DEFAULT_RELIGHT_LOBES;
use crate::{GeneratorConfig, MAX_RESOLUTION, MIN_RESOLUTION, SpatialConfig};

/// Default model side for a fresh run (CPU-sized).
pub const DEFAULT_SIZE: usize = 64;
/// Default channel multiplier for a fresh run (CPU-sized; the reference is 1).
pub const DEFAULT_MULTIPLIER: f64 = 0.25;
/// Default batch (the reference trains 32 on 8 GPUs; 4 keeps a CPU step in seconds).
pub const DEFAULT_BATCH: usize = 4;
/// Largest batch a run accepts: a 64² step at multiplier ¼ holds about 25 MB per image, so
/// 1024 images is already more than the 24 GB of a workstation (`photomat_core::memory`
/// checks the actual estimate before a run starts).
pub const MAX_BATCH: usize = 1024;

/// The settings of a run, as given; `None` (or `false`) keeps the default for a fresh run and
/// the saved value for a resumed one.
#[derive(Debug, Clone, Default, PartialEq, clap::Args)]
pub struct GanSettings {
    /// Prepared data set folder (`photomat prepare` output); its photos must be at least twice
    /// the model size. Taken from RUN/train.json with --resume (give it to relocate a moved
    /// data set).
    #[arg(long, value_name = "DATASET")]
    pub data: Option<PathBuf>,

    /// Model side: a power of two in 32 … 1024 [default: 64].
    #[arg(long, value_name = "PIXELS")]
    pub size: Option<usize>,

    /// Channel multiplier of G and D (1 = the reference's widths) [default: 0.25].
    #[arg(long, value_name = "M")]
    pub multiplier: Option<f64>,

    /// Dimension of z and w [default: 512].
    #[arg(long, value_name = "D")]
    pub latent_dim: Option<usize>,

    /// Images per step, at most 1024 [default: 4].
    #[arg(long, value_name = "B",
          value_parser = clap::value_parser!(u32).range(1..=MAX_BATCH as i64))]
    pub batch: Option<u32>,

    /// Seed of the run: initial weights and every random draw [default: 0].
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,

    /// Tileable generator: circular padding, F rolled per sample before M.
    #[arg(long)]
    pub tileable: bool,

    /// Base learning rate of G, M and D before the lazy-regularisation correction
    /// [default: 0.0025].
    #[arg(long, value_name = "LR")]
    pub lr: Option<f64>,

    /// Weight of StyleGAN2's path-length regularisation of G, every 4 steps on half a batch
    /// (the reference uses 2; a step then takes about 1.25× as long) [default: 0, off].
    #[arg(long, value_name = "W")]
    pub pl_weight: Option<f64>,

    /// Learning-rate multiplier of every layer of M [default: the reference's 0.01]. M's
    /// weights move by about lr·multiplier/√64 per step, so short CPU runs (a few thousand
    /// steps) need a larger one (e.g. 0.1) for M to learn to move the highlight.
    #[arg(long, value_name = "M")]
    pub relight_lr_multiplier: Option<f64>,

    /// R1 weight γ on D's gradient at real images, applied every 16 steps
    /// [default: the reference's 0.0002·size²/batch]. Raise it (e.g. ×10) when D overpowers G
    /// on a small data set (real/fake logit gap growing without bound in log.csv).
    #[arg(long, value_name = "GAMMA")]
    pub r1_gamma: Option<f64>,

    /// Exponents s of the Phong lobes ω_z^s that the relighting MLP reads next to the light
    /// direction, comma-separated, or `none` for the paper's MLP on features ‖ ω [default:
    /// 4,16,64,256,1024: highlight peaks from 0.5 to 0.03 rad wide, which an MLP on ω alone
    /// learns slowly].
    #[arg(long, value_name = "S,S,…")]
    pub relight_lobes: Option<Lobes>,

    /// Weight of the discriminator's light-mismatch term: real photos shown under another
    /// sample's flash count as fakes, so that the relighting must follow the light (0: off,
    /// StyleGAN2's loss) [default: 1].
    #[arg(long, value_name = "W")]
    pub light_mismatch: Option<f64>,

    /// Spatial (any-size) generator: a field of local latents replaces the 4×4 constant, and
    /// the run trains on --size × --size patches cut from the photos at their prepared
    /// resolution (no shrinking), each with the photo's own flash geometry. Implies
    /// --tileable. The model then samples materials of any multiple of size/4 texels.
    #[arg(long)]
    pub spatial: bool,

    /// Leave out StyleGAN2's per-pixel noise inputs: all variation then comes from the
    /// latents (the local latents of a spatial generator), as in spatial texture GANs. On a
    /// CPU-sized spatial run the learned noise became a per-texel speckle.
    #[arg(long)]
    pub no_noise: bool,

    /// Gain k of the discriminator's input sharpening: D reads x + k·(x − 3×3 mean of x), the
    /// images' detail amplified k + 1 times, so that it sees texture that is faint next to
    /// the colour and the highlight [default: 0, StyleGAN2's D; 9 is what was measured].
    #[arg(long, value_name = "K")]
    pub d_sharpen: Option<f64>,

    /// Relief in the neural material: M shades each texel in the frame of a normal from a
    /// learned height channel of F, so that the light dependence M learns can be relief that
    /// the estimator's normals then show. May be switched on when resuming a run without it
    /// (its projection starts at zero: outputs unchanged until it trains).
    #[arg(long)]
    pub relief: bool,

    /// Channels of the spatial generator's local latents (one vector per size/4 cell)
    /// [default: 32].
    #[arg(long, value_name = "N", requires = "spatial",
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub local_dim: Option<u32>,

    /// Periodic channels of the spatial generator: N plane waves whose wave vectors follow
    /// the material's style, added at every block, for lattices that repeat across many
    /// cells (tiles, weave; PSGAN's periodic latents) [default: 0].
    #[arg(long, value_name = "N", requires = "spatial",
          value_parser = clap::value_parser!(u32).range(0..=256))]
    pub waves: Option<u32>,

    /// Probability that a training patch holds the photo's highlight [default: 0.5]; under
    /// uniform positions a 64² patch of a 512² photo holds it in about 2 % of draws.
    #[arg(long, value_name = "P", requires = "spatial")]
    pub highlight_prob: Option<f64>,

    /// Steps between checkpoints (state, GAN model folder) [default: 500; on --resume the
    /// run's, from train.json].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub checkpoint_every: Option<u64>,

    /// Steps between sample grids in RUN/samples/ [default: 500; on --resume the run's].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub sample_every: Option<u64>,

    /// Steps between SWD measurements of G_ema against the data set (logged in log.csv;
    /// 0: never) [default: 1000; on --resume the run's].
    #[arg(long, value_name = "N")]
    pub swd_every: Option<u64>,

    /// Fakes and real crops per SWD measurement (a fixed, seeded set) [default: 64; on
    /// --resume the run's].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub swd_count: Option<u64>,

    /// Steps between snapshots of G_ema + M, each a model folder RUN/snapshots/step-NNNNNN/
    /// (0: none; about 2 MB each for the bundled recipe). The model's quality swings between
    /// checkpoints, so keep snapshots and pick one with `photomat rank-snapshots` [default:
    /// 0; on --resume the run's].
    #[arg(long, value_name = "N")]
    pub snapshot_every: Option<u64>,
}

/// The exponents of `--relight-lobes` (a newtype: clap reads a bare `Vec` as repeated values).
#[derive(Debug, Clone, PartialEq)]
pub struct Lobes(pub Vec<f64>);

impl FromStr for Lobes {
    type Err = String;

    /// `none`, or comma-separated finite exponents ≥ 1.
    fn from_str(text: &str) -> Result<Self, String> {
        if text.trim() == "none" {
            return Ok(Lobes(Vec::new()));
        }
        text.split(',')
            .map(|part| match part.trim().parse::<f64>() {
                Ok(s) if s.is_finite() && s >= 1.0 => Ok(s),
                _ => Err(format!(
                    "'{}' is not a lobe exponent (a number ≥ 1; or give `none`)",
                    part.trim()
                )),
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Lobes)
    }
}

/// Lobe exponents as `--relight-lobes` spells them: comma-separated, or `none`.
pub fn lobes_text(lobes: &[f64]) -> String {
    if lobes.is_empty() {
        return "none".into();
    }
    lobes
        .iter()
        .map(|s| s.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// The value of a spatial generator's field as text, `none` for a fixed-size one.
fn spatial_text(c: &TrainConfig, field: fn(&SpatialConfig) -> String) -> String {
    c.generator.spatial.as_ref().map_or("none".into(), field)
}

/// A row of [`GAN_SETTINGS`] for an optional setting `$name` of [`GanSettings`] that sets the
/// configuration's `$place` (converted by `as`): its text is the value's `Display`.
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

/// A cadence row: the cadence of outputs may change on resume.
macro_rules! cadence_row {
    ($flag:literal, $name:ident) => {
        row!(
            OnResume::MayChange { why: "" },
            $flag,
            concat!("cadence.", stringify!($name)),
            $name,
            |c| c.cadence.$name
        )
    };
}

/// Fixed when the run starts.
const FIXED: OnResume = OnResume::Fixed;

/// Every setting of a run, with its flag and its field of `train.json` (module docs).
pub const GAN_SETTINGS: [Setting<GanSettings, TrainConfig>; 25] = [
    Setting {
        flag: "--data",
        field: "data",
        on_resume: OnResume::MayChange {
            why: "the data set moved; the photos must be the same",
        },
        given: |s| s.data.as_deref().map(|d| absolute(d).display().to_string()),
        current: |c| c.data.display().to_string(),
        apply: |s, c| {
            if let Some(d) = &s.data {
                c.data = absolute(d);
            }
        },
    },
    row!(FIXED, "--size", "generator.resolution", size, |c| c
        .generator
        .resolution),
    row!(
        FIXED,
        "--multiplier",
        "generator.channel_multiplier",
        multiplier,
        |c| c.generator.channel_multiplier
    ),
    row!(
        FIXED,
        "--latent-dim",
        "generator.latent_dim",
        latent_dim,
        |c| c.generator.latent_dim
    ),
    row!(FIXED, "--batch", "batch", batch, |c| c.batch),
    row!(FIXED, "--seed", "seed", seed, |c| c.seed),
    Setting {
        flag: "--tileable",
        field: "generator.tileable",
        on_resume: FIXED,
        given: |s| s.tileable.then(|| "true".to_string()),
        current: |c| c.generator.tileable.to_string(),
        apply: |_, c| c.generator.tileable = true,
    },
    row!(
        OnResume::MayChange {
            why: "log.csv's `lr` column records it per step"
        },
        "--lr",
        "lr",
        lr,
        |c| c.lr
    ),
    row!(FIXED, "--pl-weight", "pl_weight", pl_weight, |c| c
        .pl_weight),
    row!(
        FIXED,
        "--relight-lr-multiplier",
        "generator.relight_lr_multiplier",
        relight_lr_multiplier,
        |c| c.generator.relight_lr_multiplier
    ),
    row!(FIXED, "--r1-gamma", "r1_gamma", r1_gamma, |c| c.r1_gamma),
    Setting {
        flag: "--relight-lobes",
        field: "generator.relight_lobes",
        on_resume: FIXED,
        given: |s| s.relight_lobes.as_ref().map(|l| lobes_text(&l.0)),
        current: |c| lobes_text(&c.generator.relight_lobes),
        apply: |s, c| {
            if let Some(l) = &s.relight_lobes {
                c.generator.relight_lobes = l.0.clone();
            }
        },
    },
    row!(
        FIXED,
        "--light-mismatch",
        "light_mismatch",
        light_mismatch,
        |c| c.light_mismatch
    ),
    Setting {
        flag: "--spatial",
        field: "generator.spatial",
        on_resume: FIXED,
        given: |s| s.spatial.then(|| "true".to_string()),
        current: |c| c.generator.spatial.is_some().to_string(),
        // Built with the generator ([`fresh_base`]): a spatial G is chosen before anything
        // else is set.
        apply: |_, _| {},
    },
    Setting {
        flag: "--no-noise",
        field: "generator.noise_inputs",
        on_resume: FIXED,
        given: |s| s.no_noise.then(|| "false".to_string()),
        current: |c| c.generator.noise_inputs.to_string(),
        apply: |_, c| c.generator.noise_inputs = false,
    },
    row!(
        FIXED,
        "--d-sharpen",
        "generator.d_input_sharpen",
        d_sharpen,
        |c| c.generator.d_input_sharpen
    ),
    Setting {
        flag: "--relief",
        field: "generator.relief",
        on_resume: OnResume::MayChange {
            why: "M's height projection starts at zero, so the model's outputs are unchanged \
                  until it trains",
        },
        given: |s| s.relief.then(|| "true".to_string()),
        current: |c| c.generator.relief.to_string(),
        apply: |_, c| c.generator.relief = true,
    },
    Setting {
        flag: "--local-dim",
        field: "generator.spatial.local_dim",
        on_resume: FIXED,
        given: |s| s.local_dim.map(|v| v.to_string()),
        current: |c| spatial_text(c, |s| s.local_dim.to_string()),
        apply: |s, c| {
            if let (Some(v), Some(spatial)) = (s.local_dim, c.generator.spatial.as_mut()) {
                spatial.local_dim = v as usize;
            }
        },
    },
    Setting {
        flag: "--waves",
        field: "generator.spatial.waves",
        on_resume: FIXED,
        given: |s| s.waves.map(|v| v.to_string()),
        current: |c| spatial_text(c, |s| s.waves.to_string()),
        apply: |s, c| {
            if let (Some(v), Some(spatial)) = (s.waves, c.generator.spatial.as_mut()) {
                spatial.waves = v as usize;
            }
        },
    },
    Setting {
        flag: "--highlight-prob",
        field: "patches.highlight_prob",
        on_resume: FIXED,
        given: |s| s.highlight_prob.map(|v| v.to_string()),
        current: |c| {
            c.patches
                .as_ref()
                .map_or("none".into(), |p| p.highlight_prob.to_string())
        },
        apply: |s, c| {
            if let (Some(p), Some(patches)) = (s.highlight_prob, c.patches.as_mut()) {
                patches.highlight_prob = p;
            }
        },
    },
    cadence_row!("--checkpoint-every", checkpoint_every),
    cadence_row!("--sample-every", sample_every),
    cadence_row!("--swd-every", swd_every),
    cadence_row!("--swd-count", swd_count),
    cadence_row!("--snapshot-every", snapshot_every),
];

impl GanSettings {
    /// The configuration of the run: a fresh one from the defaults and these settings, or the
    /// one saved in `run/train.json` (`saved`) with the changes a resume allows (module docs).
    pub fn merge(
        &self,
        saved: Option<(TrainConfig, &Path)>,
    ) -> anyhow::Result<Merged<TrainConfig>> {
        let (base, resumed_from) = match saved {
            Some((config, file)) => (config, Some(file)),
            None => (self.fresh_base()?, None),
        };
        let merged = merge(&GAN_SETTINGS, self, base, resumed_from)?;
        merged
            .config
            .validate()
            .map_err(|e| anyhow::anyhow!("invalid training settings: {e}"))?;
        Ok(merged)
    }

    /// The configuration a fresh run starts from before its settings are merged: the
    /// reference hyper-parameters for the generator these settings shape (side, spatial or
    /// not), the data set, batch and seed, which the reference's defaults derive from (R1's γ,
    /// the EMA half-life).
    fn fresh_base(&self) -> anyhow::Result<TrainConfig> {
        let Some(data) = &self.data else {
            bail!("--data DATASET is required for a new run (a prepared data set folder)");
        };
        let size = self.size.unwrap_or(DEFAULT_SIZE);
        if !size.is_power_of_two() || !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&size) {
            bail!(
                "--size {size} is not supported: use a power of two in {MIN_RESOLUTION} … \
                 {MAX_RESOLUTION} (32, 64, 128, 256, 512, 1024)"
            );
        }
        if !self.spatial
            && (self.local_dim.is_some() || self.waves.is_some() || self.highlight_prob.is_some())
        {
            bail!(
                "--local-dim, --waves and --highlight-prob configure a spatial generator: add \
                 --spatial"
            );
        }
        let defaults = GeneratorConfig::default();
        let generator = GeneratorConfig {
            resolution: size,
            channel_multiplier: DEFAULT_MULTIPLIER,
            // A spatial G is translation-equivariant only with wrap-around padding.
            tileable: self.spatial,
            spatial: self.spatial.then(SpatialConfig::default),
            relight_lobes: DEFAULT_RELIGHT_LOBES.to_vec(),
            ..defaults
        };
        let batch = self.batch.map_or(DEFAULT_BATCH, |b| b as usize);
        Ok(TrainConfig::new(generator, absolute(data), batch, 0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fresh(settings: GanSettings) -> TrainConfig {
        GanSettings {
            data: Some("data".into()),
            ..settings
        }
        .merge(None)
        .unwrap()
        .config
    }

    #[test]
    fn a_fresh_run_takes_the_cpu_defaults_and_every_given_setting() {
        let c = fresh(GanSettings::default());
        assert_eq!(
            (c.generator.resolution, c.batch, c.seed),
            (DEFAULT_SIZE, DEFAULT_BATCH, 0)
        );
        assert_eq!(c.generator.channel_multiplier, DEFAULT_MULTIPLIER);
        assert_eq!(c.generator.relight_lobes, DEFAULT_RELIGHT_LOBES);
        let c = fresh(GanSettings {
            size: Some(32),
            batch: Some(8),
            spatial: true,
            waves: Some(4),
            highlight_prob: Some(0.25),
            relight_lobes: Some("none".parse().unwrap()),
            swd_every: Some(7),
            ..GanSettings::default()
        });
        // γ follows the reference heuristic for the given side and batch.
        assert_eq!(c.r1_gamma, super::super::config::default_r1_gamma(32, 8));
        assert!(c.generator.tileable, "a spatial generator is tileable");
        assert_eq!(c.generator.spatial.as_ref().map(|s| s.waves), Some(4));
        assert_eq!(c.patches.as_ref().map(|p| p.highlight_prob), Some(0.25));
        assert!(c.generator.relight_lobes.is_empty());
        assert_eq!(c.cadence.swd_every, 7);
    }

    #[test]
    fn spatial_flags_without_spatial_and_a_missing_data_set_are_refused() {
        let err = GanSettings {
            data: Some("data".into()),
            waves: Some(2),
            ..GanSettings::default()
        }
        .merge(None)
        .unwrap_err()
        .to_string();
        assert!(err.contains("add --spatial"), "{err}");
        let err = GanSettings::default().merge(None).unwrap_err().to_string();
        assert!(err.contains("--data DATASET is required"), "{err}");
    }

    #[test]
    fn a_resume_names_every_contradicted_field_and_notes_what_may_change() {
        let saved = fresh(GanSettings {
            seed: Some(3),
            ..GanSettings::default()
        });
        let file = Path::new("run/train.json");
        let resume = |s: GanSettings| s.merge(Some((saved.clone(), file)));
        let same = GanSettings {
            batch: Some(4),
            seed: Some(3),
            ..GanSettings::default()
        };
        assert_eq!(resume(same.clone()).unwrap().config, saved);
        let err = resume(GanSettings {
            batch: Some(8),
            tileable: true,
            ..same.clone()
        })
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("--batch 8 contradicts batch = 4")
                && err.contains("--tileable true contradicts generator.tileable = false"),
            "{err}"
        );
        let merged = resume(GanSettings {
            lr: Some(0.001),
            relief: true,
            sample_every: Some(10),
            ..same
        })
        .unwrap();
        assert_eq!(merged.config.lr, 0.001);
        assert!(merged.config.generator.relief);
        assert_eq!(merged.config.cadence.sample_every, 10);
        assert_eq!(merged.notes.len(), 3, "{:?}", merged.notes);
    }

    #[test]
    fn every_setting_a_resume_may_change_is_one_the_saved_state_accepts() {
        // Loading a state compares the saved configuration with the resumed one up to
        // `TrainConfig::with_resume_changes`: every may-change row must be among its fields.
        let saved = fresh(GanSettings::default());
        let changed = GanSettings {
            data: Some("elsewhere".into()),
            lr: Some(0.5),
            relief: true,
            checkpoint_every: Some(3),
            sample_every: Some(3),
            swd_every: Some(3),
            swd_count: Some(3),
            snapshot_every: Some(3),
            ..GanSettings::default()
        };
        let may_change = GAN_SETTINGS
            .iter()
            .filter(|s| matches!(s.on_resume, OnResume::MayChange { .. }))
            .filter(|s| (s.given)(&changed).is_some())
            .count();
        assert_eq!(
            may_change,
            GAN_SETTINGS
                .iter()
                .filter(|s| matches!(s.on_resume, OnResume::MayChange { .. }))
                .count(),
            "the test gives every may-change setting"
        );
        let resumed = changed
            .merge(Some((saved.clone(), Path::new("train.json"))))
            .unwrap()
            .config;
        assert_ne!(resumed, saved);
        assert_eq!(saved.with_resume_changes(&resumed), resumed);
    }
}
