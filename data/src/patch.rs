//! Native-scale training patches of flash photos for a spatial generator, and the matching
//! flash placements of its fakes (geometry in docs/conventions.md, "Training patches").
//!
//! Unlike [`crate::sampler::CropSampler`], nothing is resized: a prepared S×S photo is the
//! plane square of side [`PHOTO_SIDE`] = 2 centred at the origin, the flash at height 1 above
//! its detected highlight, so a texel is 2/S world units whatever the patch size. A P×P patch
//! at pixel offset (r₀, c₀) covers x ∈ [2c₀/S − 1, 2(c₀+P)/S − 1] and
//! y ∈ [1 − 2(r₀+P)/S, 1 − 2r₀/S]; its geometry is the square of side 2P/S with the highlight
//! at the photo highlight's position relative to the patch centre. Per-texel ω and 1/d² of the
//! patch are therefore the photo's own, cut at the patch ([`PatchWindow`]).
//!
//! [`PatchSampler`] draws per batch item, in this order: a photo (uniform), whether the patch
//! must hold the highlight (probability [`PatchOptions::highlight_prob`]), the top and left
//! offsets (uniform over all positions, or uniform over those whose window contains the
//! highlight), and one of the eight symmetries of the square (uniform). The symmetry applies
//! to the pixels and to the highlight alike (as for crops). Under uniform positions alone the
//! highlight is rarely inside a small patch: [`uniform_highlight_inside`] gives that fraction
//! for a data set (about (P/(S − P + 1))² for centred highlights, 2 % for 64² patches of 512²
//! photos), which is why the option exists.
//!
//! [`PatchLightSampler`] draws the same placements without loading pixels: with the seed of a
//! [`PatchSampler`] it returns exactly that sampler's highlights.

use candle_core::{DType, Device, Tensor};
use photomat_core::flash::FlashGeometry;
use photomat_core::image_io::PlanarImage;
use photomat_core::{Error, Highlight, Result};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::dataset::FlashDataset;
use crate::highlight::PHOTO_SIDE;
use crate::sampler::{CropWindow, Symmetry};

/// World side of a P×P patch of an S×S photo: 2P/S (a texel is 2/S world units).
pub fn patch_side(patch: usize, photo_size: usize) -> f64 {
    PHOTO_SIDE * patch as f64 / photo_size as f64
}

/// What patches to draw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PatchOptions {
    /// Patch side P in pixels (the model's training resolution), at most the photos' side S.
    pub size: usize,
    /// Probability that a patch is placed so that the photo's highlight lies inside it
    /// (module docs); the rest are placed uniformly.
    pub highlight_prob: f64,
}

impl PatchOptions {
    fn validate(&self, photo_size: usize) -> Result<()> {
        if self.size == 0 || self.size > photo_size {
            return Err(Error::Invalid(format!(
                "a patch of {p}×{p} does not fit photos of {photo_size}×{photo_size}",
                p = self.size
            )));
        }
        if !(0.0..=1.0).contains(&self.highlight_prob) {
            return Err(Error::Invalid(format!(
                "the highlight probability {} is not in [0, 1]",
                self.highlight_prob
            )));
        }
        Ok(())
    }
}

/// Where one patch comes from: a P×P window of the S×S photo (then a symmetry).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PatchWindow {
    /// The window in photo pixels (its `size` is P) and the symmetry.
    pub window: CropWindow,
    /// Photo side S in pixels.
    pub photo_size: usize,
}

impl PatchWindow {
    /// World side of the patch: 2P/S.
    pub fn side(&self) -> f64 {
        patch_side(self.window.size, self.photo_size)
    }

    /// The photo's highlight (continuous pixel coordinates of the S×S photo) relative to
    /// the patch's centre in world units, after the symmetry; it may lie outside the patch.
    pub fn highlight(&self, photo_highlight_px: (f64, f64)) -> Highlight {
        let (row, col) = self.window.highlight_px(photo_highlight_px);
        Highlight::from_pixel_on(row, col, self.window.size, self.side())
    }

    /// The patch of the photo (C, S, S): (C, P, P).
    pub fn crop(&self, photo: &PlanarImage) -> Result<PlanarImage> {
        self.window.crop(photo)
    }
}

/// Offsets t ∈ 0 ..= S − P whose window [t, t + P) holds the continuous coordinate h, as
/// an inclusive range; clamped to the nearest position when h is outside the photo.
fn holding_range(h: f64, photo_size: usize, patch: usize) -> (usize, usize) {
    let last = (photo_size - patch) as f64;
    let f = h.floor();
    let lo = (f - patch as f64 + 1.0).clamp(0.0, last) as usize;
    let hi = f.clamp(0.0, last) as usize;
    (lo, hi)
}

/// The patch distribution shared by [`PatchSampler`] and [`PatchLightSampler`] (module docs).
fn draw(
    rng: &mut StdRng,
    highlights_px: &[(f64, f64)],
    photo_size: usize,
    options: &PatchOptions,
) -> (usize, PatchWindow) {
    let photo = rng.random_range(0..highlights_px.len());
    let near = rng.random::<f64>() < options.highlight_prob;
    let (p, last) = (options.size, photo_size - options.size);
    let (hr, hc) = highlights_px[photo];
    let mut offset = |h: f64| {
        let (lo, hi) = if near {
            holding_range(h, photo_size, p)
        } else {
            (0, last)
        };
        rng.random_range(lo..=hi)
    };
    let top = offset(hr);
    let left = offset(hc);
    let symmetry = Symmetry::ALL[rng.random_range(0..8)];
    (
        photo,
        PatchWindow {
            window: CropWindow {
                size: p,
                top,
                left,
                symmetry,
            },
            photo_size,
        },
    )
}

/// The fraction of uniformly placed P×P patches (photo uniform, offsets uniform in
/// 0 ..= S − P) that hold their photo's highlight: exact, from the index's highlights.
pub fn uniform_highlight_inside(dataset: &FlashDataset, patch: usize) -> Result<f64> {
    let s = dataset.size();
    if dataset.is_empty() || patch == 0 || patch > s {
        return Err(Error::Invalid(format!(
            "patches of {patch} from {} photos of {s}×{s}",
            dataset.len()
        )));
    }
    let positions = (s - patch + 1) as f64;
    // Offsets t with t ≤ h < t + P, for h inside the photo.
    let holding = |h: f64| {
        if !(0.0..s as f64).contains(&h) {
            return 0.0;
        }
        let (lo, hi) = holding_range(h, s, patch);
        (hi - lo + 1) as f64 / positions
    };
    let total: f64 = (0..dataset.len())
        .map(|i| {
            let (r, c) = dataset.highlight_px(i);
            holding(r) * holding(c)
        })
        .sum();
    Ok(total / dataset.len() as f64)
}

/// A batch of training patches.
#[derive(Debug, Clone)]
pub struct PatchBatch {
    /// Patches in the networks' range [−1, 1] (`2·display − 1`), (B, 3, P, P), f32.
    pub images: Tensor,
    /// Per-pixel unit direction to the flash, (B, 3, P, P), f32.
    pub omega: Tensor,
    /// The flash of each patch relative to its centre, in world units.
    pub highlights: Vec<Highlight>,
    /// World side of every patch (2P/S).
    pub side: f64,
}

/// Random native-scale patches of a [`FlashDataset`] (module docs).
#[derive(Debug, Clone)]
pub struct PatchSampler {
    options: PatchOptions,
    rng: StdRng,
}

impl PatchSampler {
    /// A sampler of `options.size`² patches, deterministic under `seed`.
    pub fn new(options: PatchOptions, seed: u64) -> Self {
        Self {
            options,
            rng: StdRng::seed_from_u64(seed),
        }
    }

    /// `batch` patches of `dataset` with their ω maps and highlights (see [`PatchBatch`]).
    pub fn sample(
        &mut self,
        dataset: &FlashDataset,
        batch: usize,
        device: &Device,
    ) -> Result<PatchBatch> {
        if batch == 0 || dataset.is_empty() {
            return Err(Error::Invalid(format!(
                "cannot sample a batch of {batch} from a dataset of {} photos",
                dataset.len()
            )));
        }
        let s = dataset.size();
        self.options.validate(s)?;
        let highlights_px: Vec<_> = (0..dataset.len())
            .map(|i| dataset.highlight_px(i))
            .collect();
        let draws: Vec<_> = (0..batch)
            .map(|_| draw(&mut self.rng, &highlights_px, s, &self.options))
            .collect();
        let patches = draws
            .par_iter()
            .map(|(photo, window)| {
                let image = dataset.load_image(*photo)?;
                Ok((
                    window.crop(&image)?,
                    window.highlight(highlights_px[*photo]),
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        let p = self.options.size;
        let mut pixels = Vec::with_capacity(batch * 3 * p * p);
        let mut highlights = Vec::with_capacity(batch);
        for (patch, highlight) in patches {
            pixels.extend(patch.data.iter().map(|v| 2.0 * v - 1.0));
            highlights.push(highlight);
        }
        let side = draws[0].1.side();
        let images = Tensor::from_vec(pixels, (batch, 3, p, p), device)?;
        let omega = FlashGeometry::with_side(&highlights, p, side, DType::F32, device)?.omega;
        Ok(PatchBatch {
            images,
            omega,
            highlights,
            side,
        })
    }
}

/// Flash placements for generated P×P samples, from the distribution of [`PatchSampler`]'s.
#[derive(Debug, Clone)]
pub struct PatchLightSampler {
    options: PatchOptions,
    photo_size: usize,
    highlights_px: Vec<(f64, f64)>,
    rng: StdRng,
}

impl PatchLightSampler {
    /// A sampler over `dataset`'s highlights, deterministic under `seed`; with the seed of a
    /// [`PatchSampler`] it draws exactly that sampler's highlights.
    pub fn new(dataset: &FlashDataset, options: PatchOptions, seed: u64) -> Result<Self> {
        if dataset.is_empty() {
            return Err(Error::Invalid("a light sampler needs photos".into()));
        }
        options.validate(dataset.size())?;
        Ok(Self {
            options,
            photo_size: dataset.size(),
            highlights_px: (0..dataset.len())
                .map(|i| dataset.highlight_px(i))
                .collect(),
            rng: StdRng::seed_from_u64(seed),
        })
    }

    /// World side of every placement (2P/S).
    pub fn side(&self) -> f64 {
        patch_side(self.options.size, self.photo_size)
    }

    /// `batch` highlights relative to the patch centre, in world units.
    pub fn sample(&mut self, batch: usize) -> Vec<Highlight> {
        (0..batch)
            .map(|_| {
                let (photo, window) = draw(
                    &mut self.rng,
                    &self.highlights_px,
                    self.photo_size,
                    &self.options,
                );
                window.highlight(self.highlights_px[photo])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holding_range_is_every_window_that_holds_the_point() {
        let (s, p) = (20, 6);
        for h in [-3.0, 0.0, 0.5, 4.99, 5.0, 13.2, 19.9, 25.0] {
            let (lo, hi) = holding_range(h, s, p);
            assert!(lo <= hi && hi <= s - p, "{h}: {lo}..={hi}");
            let holding: Vec<usize> = (0..=s - p)
                .filter(|&t| h >= t as f64 && h < (t + p) as f64)
                .collect();
            if holding.is_empty() {
                // Outside the photo: the nearest position.
                assert_eq!(lo, hi, "{h}");
            } else {
                assert_eq!((lo, hi), (holding[0], *holding.last().unwrap()), "{h}");
            }
        }
    }
}
