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

/// How each fake is cut from the model's material.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FakeWindows {
    /// G's own R×R output: a fixed-size model's material, a spatial model's training window.
    #[default]
    Native,
    /// The top-left R×R window of a material of this side (a spatial model): the
    /// size-generalisation check of an any-size G. Its samples are periodic and G is
    /// translation-equivariant, so any window is distributed like this one; each window comes
    /// from its own material (its own z), as at side R.
    OfLargerSamples {
        /// Side of each material, texels (≥ R).
        side: usize,
    },
    /// A fixed-size model's unit-square material stretched to the data's texel size
    /// (bilinear on F, R × (1/R) / texel texels) and its centre P×P window, P the data's patch
    /// side: what a fixed-size model gives at the photos' native scale, the baseline an
    /// any-size generator is compared with (`docs/neural-models.md`).
    Stretched,
}

/// `count` relit samples of `model` under lights of `data`, drawn from `seed` (module docs),
/// generated [`EVAL_BATCH`] at a time and cut as `windows` says; `progress` receives the
/// number finished so far. Fewer samples are generated at once at larger sides so that memory
/// stays that of one batch at R.
///
/// # Shapes
/// → (count, 3, P, P), f32, encoded space; P = R but for [`FakeWindows::Stretched`] (the
/// data's patch side).
pub fn relit_samples(
    model: &GanModel,
    data: &dyn TrainingData,
    count: usize,
    seed: u64,
    windows: FakeWindows,
    progress: &mut dyn FnMut(usize),
) -> Result<Tensor> {
    let r = model.config().resolution;
    let (side, window) = match windows {
        FakeWindows::Native => (r, r),
        FakeWindows::OfLargerSamples { side } if side < r => {
            bail!("samples of side {side} are smaller than the model's {r}×{r} windows")
        }
        FakeWindows::OfLargerSamples { side } => (side, r),
        FakeWindows::Stretched => stretched_sides(model, data)?,
    };
    let batch = (EVAL_BATCH * r * r / (side * side)).max(1);
    let seeds = fake_seeds(seed, count);
    let lights = data.fake_lights(count, seed ^ LIGHT_KEY)?;
    let mut batches = Vec::with_capacity(count.div_ceil(batch));
    let mut done = 0;
    for (seeds, lights) in seeds.chunks(batch).zip(lights.chunks(batch)) {
        let features = match windows {
            FakeWindows::Stretched => {
                // The centre window: away from the stretched image's clamped border.
                let offset = (side - window) / 2;
                model
                    .features_for_seeds(seeds, 1.0)?
                    .upsample_bilinear2d(side, side, false)?
                    .narrow(2, offset, window)?
                    .narrow(3, offset, window)?
            }
            _ => model
                .features_for_seeds_at(seeds, 1.0, side)?
                .narrow(2, 0, window)?
                .narrow(3, 0, window)?,
        }
        .contiguous()?;
        let omega = omega_for_placements(lights, window, model.device())?;
        batches.push(model.relight().forward(&features, &omega)?);
        done += seeds.len();
        progress(done);
    }
    Tensor::cat(&batches, 0)
}

/// For [`FakeWindows::Stretched`]: the side a fixed-size model's unit-square material takes
/// at the data's texel size, and the data's patch side.
fn stretched_sides(model: &GanModel, data: &dyn TrainingData) -> Result<(usize, usize)> {
    if model.config().spatial.is_some() {
        bail!("stretched fakes are for fixed-size models; a spatial model samples any size");
    }
    let window = data.sample_side_texels();
    let texel = data.sample_side() / window as f64;
    let side = (photomat_core::flash::PLANE_SIDE / texel).round() as usize;
    if side < window {
        bail!(
            "the model's material spans {side} texels at the data's texel size, less than the \
             data's {window}×{window} patches"
        );
    }
    Ok((side, window))
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
/// drawn from `seed` (module docs); the fakes are windows of samples of `sample_side`
/// ([`relit_samples`]). `progress(phase, done)` reports each finished batch.
pub fn model_swd(
    model: &GanModel,
    data: &dyn TrainingData,
    count: usize,
    seed: u64,
    windows: FakeWindows,
    config: &SwdConfig,
    progress: &mut dyn FnMut(EvalPhase, usize),
) -> Result<SwdReport> {
    if count == 0 {
        bail!("the SWD needs at least one image per set, got a count of 0");
    }
    let fakes = relit_samples(model, data, count, seed, windows, &mut |n| {
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
