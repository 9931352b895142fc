//! A prepared flash-photo data set as the GAN trainer's [`TrainingData`]: the data crate
//! implements the generator's trait, so the generator does not depend on this crate.
//!
//! Two modes:
//! - **crops** ([`DatasetSource::open`]), for the fixed-size G: whole photos resized to 2R×2R,
//!   random R×R windows and symmetries ([`CropSampler`]); every crop is the unit square and
//!   fakes get highlights from the same distribution ([`LightSampler`]).
//! - **patches** ([`DatasetSource::open_patches`]), for a spatial G: R×R patches of the photos
//!   at their prepared size ([`PatchSampler`]), each on the square of side 2R/S it covers in the
//!   photo; fakes get the same placements without the pixels ([`PatchLightSampler`]).
//!
//! [`DatasetSource::for_training`] picks the mode a [`TrainConfig`] asks for.

use std::path::Path;

use candle_core::{Device, Result, bail};
use photomat_generator::GeneratorConfig;
use photomat_generator::train::config::DEFAULT_HIGHLIGHT_PROB;
use photomat_generator::train::{FlashPlacement, RealBatch, TrainConfig, TrainingData};

use crate::dataset::FlashDataset;
use crate::patch::{PatchLightSampler, PatchOptions, PatchSampler, patch_side};
use crate::sampler::{CropSampler, LightSampler};

/// How the source cuts its photos.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SourceMode {
    /// R×R crops of the photos resized to 2R×2R (the unit square).
    Crops {
        /// Model size R.
        size: usize,
    },
    /// Native-scale patches.
    Patches(PatchOptions),
}

/// A prepared flash-photo data set as [`TrainingData`].
#[derive(Debug, Clone)]
pub struct DatasetSource {
    dataset: FlashDataset,
    mode: SourceMode,
}

/// Opens `dir` with errors that name it: missing, unreadable index, no photos.
fn open_dataset(dir: &Path) -> Result<FlashDataset> {
    if !dir.is_dir() {
        bail!(
            "data set {} does not exist or is not a folder (make one with `photomat prepare`)",
            dir.display()
        );
    }
    let dataset = FlashDataset::open(dir)
        .map_err(|e| candle_core::Error::msg(format!("data set {}: {e}", dir.display())))?;
    if dataset.is_empty() {
        bail!(
            "data set {} holds no photos (index.json lists none; see its report.txt)",
            dir.display()
        );
    }
    Ok(dataset)
}

impl DatasetSource {
    /// Opens the data set folder `dir` in crop mode for R = `size`. Errors name the folder:
    /// missing or unreadable index, no photos, photos smaller than 2R (crops are taken from
    /// the photo resized to 2R×2R, so a smaller photo would be upsampled and blurred).
    pub fn open(dir: &Path, size: usize) -> Result<Self> {
        let dataset = open_dataset(dir)?;
        if dataset.size() < 2 * size {
            bail!(
                "data set {}: its photos are {s}×{s}, a {size}² model needs photos of at least \
                 {t}×{t} (2× the model size); prepare it again with `--size {t}` or train a \
                 smaller model",
                dir.display(),
                s = dataset.size(),
                t = 2 * size
            );
        }
        Ok(Self {
            dataset,
            mode: SourceMode::Crops { size },
        })
    }

    /// Opens the data set folder `dir` in patch mode. Errors name the folder, and say so when
    /// a patch is larger than the photos or the probability is not in [0, 1].
    pub fn open_patches(dir: &Path, options: PatchOptions) -> Result<Self> {
        let dataset = open_dataset(dir)?;
        // Checks the options against the photos (the light sampler validates them).
        PatchLightSampler::new(&dataset, options, 0)
            .map_err(|e| candle_core::Error::msg(format!("data set {}: {e}", dir.display())))?;
        Ok(Self {
            dataset,
            mode: SourceMode::Patches(options),
        })
    }

    /// The source a training run of `config` draws from: patches of R² when
    /// `config.patches` is set (a spatial G), crops of R² otherwise, from `config.data`.
    pub fn for_training(config: &TrainConfig) -> Result<Self> {
        let size = config.generator.resolution;
        match &config.patches {
            None => Self::open(&config.data, size),
            Some(p) => Self::open_patches(
                &config.data,
                PatchOptions {
                    size,
                    highlight_prob: p.highlight_prob,
                },
            ),
        }
    }

    /// The source a model of architecture `config` is compared with (`eval-gan`): patches
    /// of R² at the default highlight probability for a spatial G, crops of R² otherwise.
    pub fn for_model(dir: &Path, config: &GeneratorConfig) -> Result<Self> {
        let size = config.resolution;
        match config.spatial {
            None => Self::open(dir, size),
            Some(_) => Self::open_patches(
                dir,
                PatchOptions {
                    size,
                    highlight_prob: DEFAULT_HIGHLIGHT_PROB,
                },
            ),
        }
    }

    /// The opened data set.
    pub fn dataset(&self) -> &FlashDataset {
        &self.dataset
    }

    /// How the photos are cut.
    pub fn mode(&self) -> SourceMode {
        self.mode
    }

    fn named<T>(&self, r: photomat_core::Result<T>) -> Result<T> {
        r.map_err(|e| {
            candle_core::Error::msg(format!("data set {}: {e}", self.dataset.root().display()))
        })
    }
}

impl TrainingData for DatasetSource {
    fn reals(&self, batch: usize, seed: u64, device: &Device) -> Result<RealBatch> {
        let (images, omega) = match self.mode {
            SourceMode::Crops { size } => {
                let crops = self.named(
                    CropSampler::new(size, seed)
                        .and_then(|mut s| s.sample(&self.dataset, batch, device)),
                )?;
                (crops.images, crops.omega)
            }
            SourceMode::Patches(options) => {
                let patches = self.named(PatchSampler::new(options, seed).sample(
                    &self.dataset,
                    batch,
                    device,
                ))?;
                (patches.images, patches.omega)
            }
        };
        Ok(RealBatch { images, omega })
    }

    fn fake_lights(&self, batch: usize, seed: u64) -> Result<Vec<FlashPlacement>> {
        match self.mode {
            SourceMode::Crops { size } => {
                let mut lights = self.named(LightSampler::new(&self.dataset, size, seed))?;
                Ok(lights
                    .sample(batch)
                    .into_iter()
                    .map(FlashPlacement::unit)
                    .collect())
            }
            SourceMode::Patches(options) => {
                let mut lights =
                    self.named(PatchLightSampler::new(&self.dataset, options, seed))?;
                let side = lights.side();
                Ok(lights
                    .sample(batch)
                    .into_iter()
                    .map(|highlight| FlashPlacement { highlight, side })
                    .collect())
            }
        }
    }

    fn sample_side(&self) -> f64 {
        match self.mode {
            SourceMode::Crops { .. } => photomat_core::flash::PLANE_SIDE,
            SourceMode::Patches(options) => patch_side(options.size, self.dataset.size()),
        }
    }

    fn sample_side_texels(&self) -> usize {
        match self.mode {
            SourceMode::Crops { size } => size,
            SourceMode::Patches(options) => options.size,
        }
    }
}
