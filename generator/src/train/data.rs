//! Where a training step gets its real images and the light placements of its fakes.
//!
//! [`TrainingData`] is the trainer's only view of the data: every draw is a pure function of
//! a seed (the step's seed for the purpose, [`super::streams`]), so that runs are
//! reproducible and resumable. The data crate implements it over a `photomat prepare` folder
//! (`photomat_data::source::DatasetSource`): whole-photo crops for the fixed-size G, native-
//! scale patches for a spatial G (docs/conventions.md, "Training patches").
//!
//! A sample's flash geometry is a [`FlashPlacement`]: the world side of the square the R×R
//! sample covers and the highlight relative to its centre, so that ω and 1/d² are the
//! photo's own, whether the sample is a unit-square crop or a patch of a photo.

use candle_core::{DType, Device, Result, Tensor};
use photomat_core::{FlashGeometry, Highlight};

/// A batch of real crops or patches.
#[derive(Debug, Clone)]
pub struct RealBatch {
    /// Images in encoded space [−1, 1] (`2·display − 1`), (B, 3, R, R), f32.
    pub images: Tensor,
    /// Per-pixel direction to the flash of each image, (B, 3, R, R), f32.
    pub omega: Tensor,
}

/// Where the flash is for one R×R sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlashPlacement {
    /// Highlight (the point under the flash) relative to the sample's centre, in world units
    /// (x right, y up); it may lie outside the sample.
    pub highlight: Highlight,
    /// World side of the square the sample covers: 1 for the fixed-size G's crops (the unit
    /// square), 2P/S for a P×P patch of an S×S photo.
    pub side: f64,
}

impl FlashPlacement {
    /// A placement on the unit square (the fixed-size G's crops).
    pub fn unit(highlight: Highlight) -> Self {
        Self {
            highlight,
            side: photomat_core::flash::PLANE_SIDE,
        }
    }
}

/// The data a training step draws from; every draw is determined by its seed.
pub trait TrainingData {
    /// `batch` real images of side R and their ω maps, drawn from `seed`.
    fn reals(&self, batch: usize, seed: u64, device: &Device) -> Result<RealBatch>;

    /// `batch` flash placements for generated samples, drawn from `seed` from the
    /// distribution of the reals' (the same geometry without the pixels).
    fn fake_lights(&self, batch: usize, seed: u64) -> Result<Vec<FlashPlacement>>;

    /// World side of every sample this data describes (the `side` of each placement that
    /// [`TrainingData::fake_lights`] returns): where fixed lights of a preview go.
    fn sample_side(&self) -> f64;

    /// Side in texels of every real image [`TrainingData::reals`] returns.
    fn sample_side_texels(&self) -> usize;
}

/// The per-texel ω maps of `placements` over R×R samples, each on its own side.
///
/// # Shapes
/// → (placements.len(), 3, R, R), f32.
pub fn omega_for_placements(
    placements: &[FlashPlacement],
    size: usize,
    device: &Device,
) -> Result<Tensor> {
    let geometry = |p: &[FlashPlacement]| -> Result<Tensor> {
        let highlights: Vec<Highlight> = p.iter().map(|p| p.highlight).collect();
        Ok(
            FlashGeometry::with_side(&highlights, size, p[0].side, DType::F32, device)
                .map_err(candle_core::Error::wrap)?
                .omega,
        )
    };
    match placements.first() {
        None => candle_core::bail!("flash placements: none given"),
        // One call when the batch shares its side (always, for one data set).
        Some(first) if placements.iter().all(|p| p.side == first.side) => geometry(placements),
        Some(_) => Tensor::cat(
            &placements
                .chunks(1)
                .map(geometry)
                .collect::<Result<Vec<_>>>()?,
            0,
        ),
    }
}
