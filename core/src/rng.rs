//! The workspace's one seeded random generator: SplitMix64 (Steele, Lea & Flood, "Fast
//! splittable pseudorandom number generators", OOPSLA 2014), a tiny, well-mixed 64-bit stream,
//! and its tensor form [`pseudo_random`].
//!
//! candle's CPU generator cannot be seeded, so everything that must repeat draws from here:
//! seeded parameter initialisation, latents and training streams (generator, estimator), the
//! procedural textures and photo streams (data), the hex-tiling offsets (export) and the test
//! inputs of every crate. It lives in `photomat-core` because core is the one crate all of
//! them already depend on and it pulls in nothing new; the kernels crate uses it only in its
//! tests and benchmarks (a dev-dependency), so core stays free to call the kernels later.

use candle_core::{DType, Device, Result, Shape, Tensor};

/// The golden-ratio increment by which the stream's state advances.
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// A SplitMix64 stream; the state is the seed, advanced by the golden-ratio increment.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        finalize(self.0)
    }

    /// Uniform in [0, 1) from the top 53 bits (every f64 step of that grid equally likely).
    pub fn next_unit(&mut self) -> f64 {
        unit_f64(self.next_u64())
    }

    /// Uniform in (0, 1]: never 0, for draws whose logarithm is taken (Box–Muller).
    pub fn next_open01(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }

    /// `n` samples of N(0, 1) by the Box–Muller transform (pairs of draws; the last pair's
    /// second value is dropped when `n` is odd).
    pub fn normals(&mut self, n: usize) -> Vec<f64> {
        let mut v = Vec::with_capacity(n + 1);
        while v.len() < n {
            let (u1, u2) = (self.next_open01(), self.next_open01());
            let r = (-2.0 * u1.ln()).sqrt();
            let t = std::f64::consts::TAU * u2;
            v.push(r * t.cos());
            v.push(r * t.sin());
        }
        v.truncate(n);
        v
    }
}

/// SplitMix64 as a hash: a well-mixed, bijective 64-bit function of `z`, equal to the first
/// output of the stream seeded with `z` (`SplitMix64(z).next_u64()`).
pub fn mix64(z: u64) -> u64 {
    finalize(z.wrapping_add(GOLDEN_GAMMA))
}

/// The top 53 bits of `bits` as a uniform value in [0, 1).
pub fn unit_f64(bits: u64) -> f64 {
    (bits >> 11) as f64 / (1u64 << 53) as f64
}

/// SplitMix64's output function (Stafford's "Mix13" variant of the MurmurHash3 finaliser).
fn finalize(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Values uniform in [−1, 1) from a SplitMix64 stream seeded by `seed`, converted to `dtype`:
/// reproducible tensors for tests, benchmarks and fixtures. It returns candle's `Result`, like
/// the tensor code that calls it.
///
/// # Shapes
/// Any shape; the values fill it in row-major order.
pub fn pseudo_random(
    shape: impl Into<Shape>,
    seed: u64,
    dtype: DType,
    device: &Device,
) -> Result<Tensor> {
    let shape = shape.into();
    let mut rng = SplitMix64(seed);
    let values: Vec<f64> = (0..shape.elem_count())
        .map(|_| rng.next_unit() * 2.0 - 1.0)
        .collect();
    Tensor::from_vec(values, shape, device)?.to_dtype(dtype)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_matches_the_reference_stream() {
        // First outputs for seed 0 of the reference C implementation (Vigna, splitmix64.c).
        let mut rng = SplitMix64(0);
        assert_eq!(rng.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(rng.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(mix64(0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(mix64(12345), SplitMix64(12345).next_u64());
    }

    #[test]
    fn splitmix_units_lie_in_their_intervals() {
        let mut rng = SplitMix64(42);
        for _ in 0..10_000 {
            let (u, o) = (rng.next_unit(), rng.next_open01());
            assert!((0.0..1.0).contains(&u) && o > 0.0 && o <= 1.0);
        }
        assert_eq!(unit_f64(0), 0.0);
        assert!(unit_f64(u64::MAX) < 1.0);
    }

    #[test]
    fn pseudo_random_is_reproducible_and_in_range() -> Result<()> {
        let a = pseudo_random((3, 5), 7, DType::F64, &Device::Cpu)?;
        let b = pseudo_random((3, 5), 7, DType::F64, &Device::Cpu)?;
        let (va, vb) = (
            a.flatten_all()?.to_vec1::<f64>()?,
            b.flatten_all()?.to_vec1::<f64>()?,
        );
        assert_eq!(va, vb);
        let c = pseudo_random((3, 5), 8, DType::F64, &Device::Cpu)?;
        assert_ne!(
            va,
            c.flatten_all()?.to_vec1::<f64>()?,
            "another seed, other values"
        );
        assert!(va.iter().all(|x| (-1.0..1.0).contains(x)));
        Ok(())
    }
}
