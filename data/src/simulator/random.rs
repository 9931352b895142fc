//! Random streams of the simulator: one independent, reproducible generator per photo, and the
//! few distributions the simulator draws from (normal, log-uniform).
//!
//! Photo `i` of a run with seed `K` draws everything (family seed, highlight, camera, sensor
//! noise) from its own [`StdRng`] seeded with a SplitMix64 mix of `(K, i)`, in a fixed order;
//! its phone pose, when poses are on, from a second stream ([`pose_rng`]).
//! Photos therefore do not depend on each other, on the order in which threads finish, or on
//! the thread count. `StdRng` is reproducible for a given `rand` version (rand 0.9: ChaCha12);
//! a `rand` upgrade may change the pictures a seed gives, never their distribution.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

// The SplitMix64 finaliser (a bijective, well-mixed 64-bit hash) shared with the noise.
use crate::procedural::noise::mix64;

/// The generator of photo `index` in a run seeded with `seed`.
pub fn photo_rng(seed: u64, index: u64) -> StdRng {
    StdRng::seed_from_u64(mix64(mix64(seed) ^ index))
}

/// The generator of photo `index`'s phone pose ([`super::pose`]): a stream of its own, so
/// that turning poses on leaves every other draw of the photo (family, highlight, camera,
/// noise) as it was, and runs without poses keep their bytes.
pub fn pose_rng(seed: u64, index: u64) -> StdRng {
    // Any fixed odd constant separates the two streams; this one spells "pose".
    const POSE_STREAM: u64 = 0x706f_7365;
    StdRng::seed_from_u64(mix64(mix64(seed ^ POSE_STREAM) ^ index))
}

/// A standard normal sample (Box–Muller; one of the pair is discarded, which keeps the draw
/// count per sample fixed and the streams simple).
pub fn standard_normal(rng: &mut impl Rng) -> f64 {
    // 1 − U lies in (0, 1]: ln never sees 0.
    let u1 = 1.0 - rng.random::<f64>();
    let u2 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Uniform sample in `[lo, hi]` (returns `lo` for an empty range, so fixed settings cost no
/// special case).
pub fn uniform(rng: &mut impl Rng, (lo, hi): (f64, f64)) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// Log-uniform sample in `[lo, hi]`, both positive: scale-like quantities (exposure, noise).
pub fn log_uniform(rng: &mut impl Rng, (lo, hi): (f64, f64)) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * rng.random::<f64>()).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photo_streams_differ_by_seed_and_index_and_repeat() {
        let first = |seed, index| photo_rng(seed, index).random::<u64>();
        assert_eq!(first(7, 3), first(7, 3));
        assert_ne!(first(7, 3), first(7, 4));
        assert_ne!(first(7, 3), first(8, 3));
        // The mix is not symmetric in (seed, index).
        assert_ne!(first(3, 7), first(7, 3));
    }

    #[test]
    fn standard_normal_has_unit_moments() {
        let mut rng = photo_rng(1, 0);
        let n = 200_000;
        let samples: Vec<f64> = (0..n).map(|_| standard_normal(&mut rng)).collect();
        let mean = samples.iter().sum::<f64>() / n as f64;
        let var = samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        // Standard errors: 1/√n ≈ 0.0022 for the mean, √(2/n) ≈ 0.0032 for the variance.
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.015, "variance {var}");
    }

    #[test]
    fn log_uniform_stays_in_range() {
        let mut rng = photo_rng(2, 0);
        for _ in 0..1000 {
            let v = log_uniform(&mut rng, (0.5, 2.0));
            assert!((0.5..=2.0).contains(&v));
        }
        assert_eq!(uniform(&mut rng, (0.3, 0.3)), 0.3);
    }
}
