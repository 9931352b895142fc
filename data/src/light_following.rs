//! Whether a spatial GAN's relighting follows the light: the highlight detector run on M's
//! images of generated materials under known flash positions, next to the same detector on
//! real patches whose flash is known (docs/benchmarks/gan-training.md, "Light following").
//!
//! A GAN can lower its SWD while M ignores ω: every material then looks the same under every
//! light, and its highlight (if any) sits wherever G painted it. Here each of `count`
//! materials is relit under one flash drawn from the patch distribution of the data set with
//! the highlight inside the patch ([`PatchLightSampler`] with probability 1), the detector
//! looks for the highlight in M's image, and the distance between the detected and the
//! conditioned highlight is reported in % of the patch width. The reals are `count` patches of
//! the data set drawn the same way, against the highlight its index records for their photo
//! (the detector's full-photo estimate, which is what training conditioned D on; the same
//! detector then runs on the patch alone). A relighting that
//! follows the light lands near the reals' figure; one that ignores it lands near the error
//! of a guess (about 40 % of the width for uniform highlights and a centre guess).
//!
//! The detectors were built for whole photos, where the falloff and vignetting they fit span
//! the image; on a patch the falloff is nearly flat and even real patches give large errors.
//! So the check also runs at the photo's scale: `count` materials sampled at the photos' side
//! S (a spatial G samples any size), each lit by a flash whose highlight is uniform over the
//! central half of the square (phone photos, and the data sets, keep the highlight near the
//! centre, where a detector that always answers "centre" would look right), the detector on
//! the whole image. Beside it, the error of that centre guess on the same lights; the matching
//! real figure is the detector's own accuracy on whole photos (`photomat eval-detector`, below
//! 1 % of the width on simulated photos).

use candle_core::{DType, Tensor};
use photomat_core::flash::FlashGeometry;
use photomat_core::rng::SplitMix64;
use photomat_core::{Error, Highlight, LightSet, Result};
use photomat_generator::GanModel;
use photomat_generator::train::samples::display_tiles;

use crate::dataset::FlashDataset;
use crate::highlight::{HighlightDetector, PHOTO_SIDE};
use crate::patch::{PatchLightSampler, PatchOptions, PatchSampler, patch_side};

/// Key mixed into the seed for the material seeds (the lights and patches use the seed).
const MATERIAL_SEED_KEY: u64 = 0x6C69_6768_745F_666F; // "light_fo"

/// Distances between detected and conditioned highlights, in % of the image width.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct DistanceStats {
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// 90th percentile (nearest rank).
    pub p90: f64,
    /// Largest.
    pub max: f64,
}

impl DistanceStats {
    /// Statistics of `values` (at least one).
    fn of(mut values: Vec<f64>) -> Self {
        values.sort_by(f64::total_cmp);
        let n = values.len();
        let rank = |q: f64| values[((q * n as f64).ceil() as usize).clamp(1, n) - 1];
        Self {
            mean: values.iter().sum::<f64>() / n as f64,
            median: rank(0.5),
            p90: rank(0.9),
            max: values[n - 1],
        }
    }
}

/// What [`light_following`] measured.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LightFollowing {
    /// Materials relit (and real patches cut).
    pub count: usize,
    /// Side of the images, in texels (the model's training resolution).
    pub size: usize,
    /// M's images of generated materials.
    pub fakes: DistanceStats,
    /// Real patches.
    pub reals: DistanceStats,
    /// Side S of the photo-scale images (the data set's photo side).
    pub photo_size: usize,
    /// M's images of generated materials at the photo's scale (module docs).
    pub photo_fakes: DistanceStats,
    /// The error of always answering "the centre" on the photo-scale lights.
    pub photo_centre_guess: DistanceStats,
}

/// Measures the light following of the spatial model `model` against `dataset` (module docs)
/// with `detector`, from `count` materials and patches drawn from `seed`.
pub fn light_following(
    model: &GanModel,
    dataset: &FlashDataset,
    detector: &dyn HighlightDetector,
    count: usize,
    seed: u64,
) -> Result<LightFollowing> {
    let config = model.config();
    if config.spatial.is_none() {
        return Err(Error::Invalid(
            "the light-following check needs a spatial GAN (trained on patches with their own \
             flash geometry)"
                .into(),
        ));
    }
    if count == 0 {
        return Err(Error::Invalid(
            "the light-following check needs at least one material".into(),
        ));
    }
    let size = config.resolution;
    let options = PatchOptions {
        size,
        highlight_prob: 1.0,
    };
    let side = patch_side(size, dataset.size());
    let device = model.device();

    let highlights = PatchLightSampler::new(dataset, options, seed)?.sample(count);
    let seeds: Vec<u64> = (0..count as u64)
        .map(|i| seed ^ MATERIAL_SEED_KEY.wrapping_add(i))
        .collect();
    let features = model.features_for_seeds_at(&seeds, 1.0, size)?;
    let omega = FlashGeometry::with_side(&highlights, size, side, DType::F32, device)?.omega;
    let fakes = model.relight().forward(&features, &omega)?;
    let fake_distances = distances(&fakes, &highlights, side, detector)?;

    let reals = PatchSampler::new(options, seed).sample(dataset, count, device)?;
    let real_distances = distances(&reals.images, &reals.highlights, side, detector)?;

    let photo_size = dataset.size().div_ceil(config.cell_size()) * config.cell_size();
    let photo_side = PHOTO_SIDE * photo_size as f64 / dataset.size() as f64;
    let mut rng = SplitMix64(seed ^ MATERIAL_SEED_KEY.rotate_left(17));
    // Uniform over the central half: x, y ∈ [−side/4, side/4] (U(−½, ½) · side/2).
    let lights = LightSet::uniform(count, || rng.next_unit());
    let mut photo_distances = Vec::with_capacity(count);
    let mut centre_guess = Vec::with_capacity(count);
    // A material at a time: S² features of 32 channels for the whole batch would be large.
    for (&material, h) in seeds.iter().zip(lights.highlights()) {
        let light = [h.scaled(photo_side / 2.0)];
        centre_guess.push(100.0 * light[0].x.hypot(light[0].y) / photo_side);
        let features = model.features_for_seeds_at(&[material], 1.0, photo_size)?;
        let omega =
            FlashGeometry::with_side(&light, photo_size, photo_side, DType::F32, device)?.omega;
        let image = model.relight().forward(&features, &omega)?;
        photo_distances.extend(distances(&image, &light, photo_side, detector)?);
    }
    Ok(LightFollowing {
        count,
        size,
        fakes: DistanceStats::of(fake_distances),
        reals: DistanceStats::of(real_distances),
        photo_size,
        photo_fakes: DistanceStats::of(photo_distances),
        photo_centre_guess: DistanceStats::of(centre_guess),
    })
}

/// Per image of `images` (B, 3, P, P) in the networks' range [−1, 1], the distance in % of P
/// between the detected highlight and `highlights[i]` (world units on a square of `side`).
fn distances(
    images: &Tensor,
    highlights: &[Highlight],
    side: f64,
    detector: &dyn HighlightDetector,
) -> Result<Vec<f64>> {
    let size = images.dim(3)?;
    display_tiles(images)?
        .iter()
        .zip(highlights)
        .map(|(image, h)| {
            let (row, col) = h.to_pixel_on(size, side);
            let detection = detector.detect(image)?;
            Ok(100.0 * detection.error_px(row, col) / size as f64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_use_nearest_ranks() {
        let s = DistanceStats::of(vec![4.0, 1.0, 3.0, 2.0, 10.0]);
        assert_eq!(s.median, 3.0);
        assert_eq!(s.p90, 10.0);
        assert_eq!(s.max, 10.0);
        assert!((s.mean - 4.0).abs() < 1e-12);
    }
}
