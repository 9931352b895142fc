//! The SWD of a GAN model against a data set: the quantity `photomat eval-gan` prints and
//! the trainer logs, so that both measure the same thing.
//!
//! `count` fakes are relit samples of G and M: each from its own seed (latent and noise,
//! [`GanModel::features_for_seeds`], ψ = 1, i.e. no truncation), under a light drawn from the
//! data set's light distribution ([`TrainingData::fake_lights`]: the crops' flash
//! placements), with per-texel ω ([`omega_for_placements`]). `count` reals are crops drawn as
//! the trainer draws them ([`TrainingData::reals`]). Both sets are in the encoded space
//! [−1, 1]; M's output is not clamped (clamping would hide overshoot the metric should see).
//! Every draw derives from `seed`, so a model, data set, count and seed give one value.

use candle_core::{Device, Result, Tensor, bail};
use photomat_core::rng::SplitMix64;

use super::{SwdConfig, SwdReport, sliced_wasserstein};
use crate::GanModel;
use crate::train::data::{TrainingData, omega_for_placements};

/// Images generated or loaded per batch: bounds memory (G's activations at 256² are large)
/// while keeping the matrix products efficient.
pub const EVAL_BATCH: usize = 8;

/// Keys separating the seed streams of the fakes' latents, their lights and the real crops.
const FAKE_KEY: u64 = 0x6576_616C_5F66_616B; // "eval_fak"
const LIGHT_KEY: u64 = 0x6576_616C_5F6C_6974; // "eval_lit"
const REAL_KEY: u64 = 0x6576_616C_5F72_6561; // "eval_rea"

/// Which set a progress report is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EvalPhase {
    /// Relit samples of the model.
    Fakes,
    /// Crops of the data set.
    Reals,
}

/// The material seeds of the `count` fakes of an evaluation seeded `seed`.
pub fn fake_seeds(seed: u64, count: usize) -> Vec<u64> {
    let mut rng = SplitMix64(seed ^ FAKE_KEY);
    (0..count).map(|_| rng.next_u64()).collect()
}

/// `count` relit samples of `model` under lights of `data`, drawn from `seed` (module docs),
/// generated [`EVAL_BATCH`] at a time; `progress` receives the number finished so far.
///
/// # Shapes
/// → (count, 3, R, R), f32, encoded space.
pub fn relit_samples(
    model: &GanModel,
    data: &dyn TrainingData,
    count: usize,
    seed: u64,
    progress: &mut dyn FnMut(usize),
) -> Result<Tensor> {
    let r = model.config().resolution;
    let seeds = fake_seeds(seed, count);
    let lights = data.fake_lights(count, seed ^ LIGHT_KEY)?;
    let mut batches = Vec::with_capacity(count.div_ceil(EVAL_BATCH));
    for (i, (seeds, lights)) in seeds
        .chunks(EVAL_BATCH)
        .zip(lights.chunks(EVAL_BATCH))
        .enumerate()
    {
        let features = model.features_for_seeds(seeds, 1.0)?;
        let omega = omega_for_placements(lights, r, model.device())?;
        batches.push(model.relight().forward(&features, &omega)?);
        progress((i * EVAL_BATCH + seeds.len()).min(count));
    }
    Tensor::cat(&batches, 0)
}

/// `count` real crops of `data` drawn from `seed`, [`EVAL_BATCH`] at a time; `progress`
/// receives the number finished so far.
///
/// # Shapes
/// → (count, 3, R, R), f32, encoded space.
pub fn real_crops(
    data: &dyn TrainingData,
    count: usize,
    seed: u64,
    device: &Device,
    progress: &mut dyn FnMut(usize),
) -> Result<Tensor> {
    let mut rng = SplitMix64(seed ^ REAL_KEY);
    let mut batches = Vec::with_capacity(count.div_ceil(EVAL_BATCH));
    let mut done = 0;
    while done < count {
        let n = EVAL_BATCH.min(count - done);
        batches.push(data.reals(n, rng.next_u64(), device)?.images);
        done += n;
        progress(done);
    }
    Tensor::cat(&batches, 0)
}

/// The SWD between `count` relit samples of `model` and `count` real crops of `data`, all
/// drawn from `seed` (module docs). `progress(phase, done)` reports each finished batch.
pub fn model_swd(
    model: &GanModel,
    data: &dyn TrainingData,
    count: usize,
    seed: u64,
    config: &SwdConfig,
    progress: &mut dyn FnMut(EvalPhase, usize),
) -> Result<SwdReport> {
    if count == 0 {
        bail!("the SWD needs at least one image per set, got a count of 0");
    }
    let fakes = relit_samples(model, data, count, seed, &mut |n| {
        progress(EvalPhase::Fakes, n)
    })?;
    let reals = real_crops(data, count, seed, model.device(), &mut |n| {
        progress(EvalPhase::Reals, n)
    })?;
    let (rr, fr) = (reals.dim(2)?, fakes.dim(2)?);
    if rr != fr {
        bail!("the data set's crops are {rr}×{rr} but the model's samples are {fr}×{fr}");
    }
    sliced_wasserstein(&reals, &fakes, config, seed)
}
