//! The random draws of one estimator training step, derived from the run seed and the step
//! only: the materials (a seed each, naming its z and noise through
//! [`photomat_generator::GanModel::features_for_seeds`]), the flash positions and the
//! fine-tune's rolls. A step's batch therefore does not depend on what happened before it,
//! and a resumed run sees exactly the batches of the uninterrupted one.
//!
//! Lights are [`LightSet::uniform`]: the highlight `(lx, ly) ~ U(−½, ½)²` in plane coordinates
//! ([`photomat_core::Highlight`]), the distribution the GAN's fakes use
//! (`docs/conventions.md`). For a spatial GAN, whose R×R materials are patches of side
//! R × texel size inside photos of side 2, [`StepDraws::highlights_on`] places them as its
//! training placed its patches' flashes: every other item's highlight inside the patch
//! (the drawn values × the patch side), the others anywhere over a photo (× 2), so that E
//! sees the specular peak and the photo's wide range of incidence angles alike.

use photomat_core::flash::PHOTO_SIDE;
use photomat_core::rng::SplitMix64;
use photomat_core::{Highlight, LightSet};

/// Golden-ratio increment: spreads consecutive steps over the seed space before mixing.
const STEP_SPREAD: u64 = 0x9E37_79B9_7F4A_7C15;

/// The draws of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepDraws {
    /// One material seed per batch item.
    pub material_seeds: Vec<u64>,
    /// One highlight per batch item, uniform on [−½, ½]².
    pub highlights: Vec<Highlight>,
    /// One roll (rows, columns) per batch item, each uniform in 0 … R − 1 (used by the
    /// fine-tune only).
    pub rolls: Vec<(usize, usize)>,
}

impl StepDraws {
    /// The highlights in world units for materials of world side `patch_side` (module docs):
    /// as drawn for the unit square (`None`), else item i's scaled by `patch_side` for even
    /// i and by [`PHOTO_SIDE`] for odd i.
    pub fn highlights_on(&self, patch_side: Option<f64>) -> Vec<Highlight> {
        match patch_side {
            None => self.highlights.clone(),
            Some(side) => self
                .highlights
                .iter()
                .enumerate()
                .map(|(i, h)| h.scaled(if i % 2 == 0 { side } else { PHOTO_SIDE }))
                .collect(),
        }
    }

    /// The draws of step `step` of the run seeded `seed`, for `batch` materials of side
    /// `resolution`.
    pub fn new(seed: u64, step: u64, batch: usize, resolution: usize) -> Self {
        // One SplitMix64 round of (seed, step) as the stream's start: distinct steps give
        // unrelated streams.
        let start = SplitMix64(seed ^ step.wrapping_mul(STEP_SPREAD)).next_u64();
        let mut rng = SplitMix64(start);
        let material_seeds = (0..batch).map(|_| rng.next_u64()).collect();
        let highlights = LightSet::uniform(batch, || rng.next_unit())
            .highlights()
            .to_vec();
        let r = resolution as u64;
        let rolls = (0..batch)
            .map(|_| ((rng.next_u64() % r) as usize, (rng.next_u64() % r) as usize))
            .collect();
        Self {
            material_seeds,
            highlights,
            rolls,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lights_are_the_stream_values_shifted_by_a_half() {
        let d = StepDraws::new(3, 7, 2, 32);
        let start = SplitMix64(3 ^ 7u64.wrapping_mul(STEP_SPREAD)).next_u64();
        let mut rng = SplitMix64(start);
        let _seeds = (rng.next_u64(), rng.next_u64());
        for h in &d.highlights {
            let (x, y) = (rng.next_unit() - 0.5, rng.next_unit() - 0.5);
            assert_eq!(*h, Highlight::new(x, y));
        }
    }

    #[test]
    fn spatial_highlights_alternate_between_the_patch_and_the_photo() {
        let d = StepDraws::new(5, 2, 4, 64);
        assert_eq!(d.highlights_on(None), d.highlights);
        let placed = d.highlights_on(Some(0.5));
        for (i, (p, h)) in placed.iter().zip(&d.highlights).enumerate() {
            let scale = if i % 2 == 0 { 0.5 } else { PHOTO_SIDE };
            assert_eq!(*p, Highlight::new(h.x * scale, h.y * scale));
        }
    }

    #[test]
    fn draws_repeat_per_step_and_cover_the_light_square() {
        assert_eq!(StepDraws::new(3, 7, 4, 32), StepDraws::new(3, 7, 4, 32));
        assert_ne!(StepDraws::new(3, 7, 4, 32), StepDraws::new(3, 8, 4, 32));
        assert_ne!(StepDraws::new(3, 7, 4, 32), StepDraws::new(4, 7, 4, 32));
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        for step in 0..200 {
            let d = StepDraws::new(1, step, 4, 32);
            for h in &d.highlights {
                assert!(h.x.abs() <= 0.5 && h.y.abs() <= 0.5);
                lo = lo.min(h.x.min(h.y));
                hi = hi.max(h.x.max(h.y));
            }
            assert!(d.rolls.iter().all(|&(a, b)| a < 32 && b < 32));
        }
        assert!(lo < -0.45 && hi > 0.45, "lights span [{lo}, {hi}]");
    }
}
