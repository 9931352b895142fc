//! The documented fallback feature extractor of the Gram loss when no VGG19 weights are given
//! (pretrained weights cannot be downloaded on the build machines, `docs/neural-models.md`, "Gram
//! loss"): a seeded random multi-scale conv bank with VGG19's pooled five-stage structure but
//! narrow.
//!
//! Random-weight convolutional networks give usable texture statistics: Ustyuzhaninov,
//! Brendel, Gatys & Bethge (2017), "What does it take to generate natural textures?" (ICLR),
//! synthesise textures close in quality to VGG's from the Gram matrices of a single-layer
//! multi-scale random conv net. This bank keeps VGG's pooled pyramid so the loss has the
//! reference's multi-scale structure at a fraction of its cost.
//!
//! Architecture ([`PooledConvStack`]): five stages of one 3×3 conv + bias + ReLU followed by a
//! 2×2 average pool, widths 3 → 16 → 32 → 64 → 64 → 64 ([`RANDOM_FEATURE_WIDTHS`]); input
//! `2x − 1` (the networks' [−1, 1] range, zero-mean for mid-grey); weights N(0, 2/fan_in)
//! (He et al. 2015: keeps the activations' scale through ReLU layers) from a SplitMix64 stream
//! per layer keyed by the seed, biases 0. The same seed gives the same extractor on every
//! machine. Padding is **circular**: for a periodic image every stage commutes with rolls by
//! multiples of its total stride, so the Gram matrices of a tileable material do not depend
//! on where its period starts (tested in `tests/losses.rs`).
//!
//! Cost: ≈ 7 kFLOP per input texel forward, about 1/110 of VGG19 up to pool5 (≈ 0.78 MFLOP).

use candle_core::{DType, Device, Result, Tensor};
use photomat_core::rng::SplitMix64;
use photomat_kernels::Conv2dSpec;

use super::extractor::{ConvLayer, PooledConvStack};

/// Channel widths: the RGB input, then each stage's output.
pub const RANDOM_FEATURE_WIDTHS: [usize; 6] = [3, 16, 32, 64, 64, 64];

/// Default seed of the fallback extractor (any fixed value; part of the training config).
pub const DEFAULT_RANDOM_FEATURE_SEED: u64 = 0x6772_616D; // "gram"

/// The seeded random bank (see the module docs), weights in `dtype` on `device`.
pub fn random_features(seed: u64, dtype: DType, device: &Device) -> Result<PooledConvStack> {
    let stages = RANDOM_FEATURE_WIDTHS
        .windows(2)
        .enumerate()
        .map(|(k, io)| {
            let (ci, co) = (io[0], io[1]);
            let fan_in = ci * 9;
            let he = (2.0 / fan_in as f64).sqrt();
            let mut rng = SplitMix64(seed ^ (0xA5A5_0000_0000_0000 | k as u64));
            let w: Vec<f64> = rng.normals(co * fan_in).iter().map(|v| v * he).collect();
            Ok(vec![ConvLayer {
                weight: Tensor::from_vec(w, (co, ci, 3, 3), device)?.to_dtype(dtype)?,
                bias: Tensor::zeros(co, dtype, device)?,
            }])
        })
        .collect::<Result<Vec<_>>>()?;
    PooledConvStack::new(
        stages,
        [0.5; 3],
        [0.5; 3],
        Conv2dSpec::circular(1, 1),
        format!("random conv bank (seed {seed})"),
    )
}
