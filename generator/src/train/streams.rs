//! Seeds of the random draws of one training step, derived from the run seed, the step and
//! the purpose of the draw, so that a step's randomness does not depend on what happened
//! before it: two runs with the same seed draw the same latents, noise, crops, lights, rolls
//! mixing cut-offs and local latent fields, and a resumed run draws exactly what the uninterrupted run would have.
//!
//! A seed is the SplitMix64 output of the run seed mixed with the step, a stream tag and an
//! index (e.g. the batch item), each through one SplitMix64 round (a bijective mixer: distinct
//! inputs give well-spread, distinct states).

use photomat_core::rng::SplitMix64;

/// What a random draw is for. Each phase of a step (G's, D's) has its own latents, noise,
/// lights and rolls, as in StyleGAN2-ADA, where every phase draws its own z.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum Stream {
    /// Latents of G's phase.
    GLatent = 1,
    /// Second latents for style mixing in G's phase.
    GMixLatent = 2,
    /// Noise images of G's phase.
    GNoise = 3,
    /// Style-mixing decision and cut-off of G's phase.
    GMixing = 4,
    /// Roll offsets of G's phase (tileable mode).
    GRoll = 5,
    /// Light positions of G's fakes.
    GLights = 6,
    /// Local latent fields of G's phase (spatial G).
    GField = 7,
    /// Latents of D's phase.
    DLatent = 11,
    /// Second latents for style mixing in D's phase.
    DMixLatent = 12,
    /// Noise images of D's phase.
    DNoise = 13,
    /// Style-mixing decision and cut-off of D's phase.
    DMixing = 14,
    /// Roll offsets of D's phase.
    DRoll = 15,
    /// Light positions of D's fakes.
    DLights = 16,
    /// Local latent fields of D's phase (spatial G).
    DField = 18,
    /// Latents of the path-length step.
    PlLatent = 21,
    /// Second latents for style mixing in the path-length step.
    PlMixLatent = 22,
    /// Noise images of the path-length step.
    PlNoise = 23,
    /// Style-mixing decision and cut-off of the path-length step.
    PlMixing = 24,
    /// Roll offsets of the path-length step.
    PlRoll = 25,
    /// Light positions of the path-length step.
    PlLights = 26,
    /// Image-space noise y of the path-length step.
    PlImageNoise = 27,
    /// Local latent fields of the path-length step (spatial G).
    PlField = 28,
    /// The real crops of the step.
    Crops = 17,
    /// Fixed draws of the sample grids and metrics (step unused).
    Fixed = 99,
}

/// The seed of draw `index` of `stream` at `step` of the run seeded `run_seed`.
pub fn stream_seed(run_seed: u64, step: u64, stream: Stream, index: u64) -> u64 {
    let mut h = run_seed;
    for v in [step, stream as u64, index] {
        h = SplitMix64(h ^ v.wrapping_mul(0x9E37_79B9_7F4A_7C15)).next_u64();
    }
    h
}

/// `n` seeds, one per batch item.
pub fn stream_seeds(run_seed: u64, step: u64, stream: Stream, n: usize) -> Vec<u64> {
    (0..n as u64)
        .map(|i| stream_seed(run_seed, step, stream, i))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeds_differ_by_every_input_and_repeat_exactly() {
        let base = stream_seed(1, 10, Stream::GLatent, 0);
        assert_eq!(base, stream_seed(1, 10, Stream::GLatent, 0));
        let others = [
            stream_seed(2, 10, Stream::GLatent, 0),
            stream_seed(1, 11, Stream::GLatent, 0),
            stream_seed(1, 10, Stream::DLatent, 0),
            stream_seed(1, 10, Stream::GLatent, 1),
        ];
        for o in others {
            assert_ne!(o, base);
        }
        let s = stream_seeds(1, 0, Stream::Crops, 64);
        let unique: std::collections::HashSet<_> = s.iter().collect();
        assert_eq!(unique.len(), 64);
    }
}
