//! Where a training step gets its real crops and the light positions of its fakes.
//!
//! [`TrainingData`] is the trainer's only view of the data: every draw is a pure function of
//! a seed (the step's seed for the purpose, [`super::streams`]), so that runs are
//! reproducible and resumable. [`DatasetSource`] implements it over a `photomat prepare`
//! folder with the data crate's [`CropSampler`] and [`LightSampler`] (DESIGN §4: resize to
//! 2H×2H, random H×H window and symmetry; fakes get lights from the same distribution).

use std::path::Path;

use candle_core::{Device, Result, Tensor, bail};
use photomat_core::Highlight;
use photomat_data::dataset::FlashDataset;
use photomat_data::sampler::{CropSampler, LightSampler};

/// A batch of real crops.
#[derive(Debug, Clone)]
pub struct RealBatch {
    /// Crops in encoded space [−1, 1] (`2·display − 1`), (B, 3, R, R), f32.
    pub images: Tensor,
    /// Per-pixel direction to the flash of each crop, (B, 3, R, R), f32.
    pub omega: Tensor,
}

/// The data a training step draws from; every draw is determined by its seed.
pub trait TrainingData {
    /// `batch` real crops of side R and their ω maps, drawn from `seed`.
    fn reals(&self, batch: usize, seed: u64, device: &Device) -> Result<RealBatch>;

    /// `batch` light positions for generated samples, drawn from `seed`, in the plane
    /// coordinates of an R×R sample.
    fn fake_highlights(&self, batch: usize, seed: u64) -> Result<Vec<Highlight>>;
}

/// A prepared flash-photo data set as [`TrainingData`] for R×R models.
#[derive(Debug, Clone)]
pub struct DatasetSource {
    dataset: FlashDataset,
    size: usize,
}

impl DatasetSource {
    /// Opens the data set folder `dir` for R = `size`. Errors name the folder: missing or
    /// unreadable index, no photos, photos smaller than 2R (crops are taken from the photo
    /// resized to 2R×2R, so a smaller photo would be upsampled and blurred).
    pub fn open(dir: &Path, size: usize) -> Result<Self> {
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
        Ok(Self { dataset, size })
    }

    /// The opened data set.
    pub fn dataset(&self) -> &FlashDataset {
        &self.dataset
    }
}

impl TrainingData for DatasetSource {
    fn reals(&self, batch: usize, seed: u64, device: &Device) -> Result<RealBatch> {
        let crops = CropSampler::new(self.size, seed)
            .and_then(|mut s| s.sample(&self.dataset, batch, device))
            .map_err(|e| {
                candle_core::Error::msg(format!("data set {}: {e}", self.dataset.root().display()))
            })?;
        Ok(RealBatch {
            images: crops.images,
            omega: crops.omega,
        })
    }

    fn fake_highlights(&self, batch: usize, seed: u64) -> Result<Vec<Highlight>> {
        let mut lights =
            LightSampler::new(&self.dataset, self.size, seed).map_err(candle_core::Error::wrap)?;
        Ok(lights.sample(batch))
    }
}
