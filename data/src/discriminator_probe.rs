//! What a training run's discriminator looks at: D's mean logit on real patches, on the same
//! patches under other samples' lights, on the same patches blurred (their texture removed,
//! their colour and highlight kept), and on G's fakes (docs/benchmarks/gan-training.md, "What the
//! GAN's discriminator looks at").
//!
//! G learns only what D tells apart. A D that scores blurred reals like reals gives G no
//! reason to make texture (grain, tiles, weave), however low the SWD goes; one that scores
//! them like fakes does. The light rows say the same of the light: a D that scores reals under
//! other lights like reals cannot teach M to follow the flash. [`DiscriminatorProbe::texture_gap`]
//! and [`DiscriminatorProbe::light_gap`] are the two differences.
//!
//! The reals are drawn as training draws them ([`DatasetSource::for_training`], the run's
//! patch or crop options), the other lights from the data's light distribution, the fakes from
//! the run's training G (not G_ema: D is judged against the G it trains with) relit by M under
//! those lights. Everything is a function of `seed`.

use std::path::Path;

use candle_core::{Device, Result, Tensor};
use photomat_generator::discriminator::Discriminator;
use photomat_generator::train::data::omega_for_placements;
use photomat_generator::train::state::read_config;
use photomat_generator::train::{Trainer, TrainingData};
use serde::Serialize;

use crate::source::DatasetSource;

/// Radii of the two box blurs, in texels: 1 (3×3) softens the finest grain, 3 (7×7) removes
/// texture up to a few texels while keeping a highlight tens of texels wide.
pub const BLUR_RADII: [usize; 2] = [1, 3];

/// D's mean logit on each kind of image.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiscriminatorProbe {
    /// Training steps of the run's state.
    pub step: u64,
    /// Images per row.
    pub count: usize,
    /// Real patches under their own lights.
    pub reals: f64,
    /// The same patches under other samples' lights.
    pub reals_other_lights: f64,
    /// The same patches box-blurred with [`BLUR_RADII`], under their own lights.
    pub reals_blurred: [f64; 2],
    /// G's fakes under their lights.
    pub fakes: f64,
    /// The same fakes under the reals' lights.
    pub fakes_other_lights: f64,
}

impl DiscriminatorProbe {
    /// How much lower D scores reals without their texture (the larger [`BLUR_RADII`]): near
    /// 0, D does not look at texture.
    pub fn texture_gap(&self) -> f64 {
        self.reals - self.reals_blurred[1]
    }

    /// How much lower D scores reals under other samples' lights: near 0, D does not look at
    /// the light.
    pub fn light_gap(&self) -> f64 {
        self.reals - self.reals_other_lights
    }
}

/// Probes the discriminator of the `photomat train-gan` run folder `run` (train.json +
/// train_state.safetensors) on `count` images per row drawn from `seed`; `data` replaces the
/// data set the run recorded (a moved data set).
pub fn probe_discriminator(
    run: &Path,
    data: Option<&Path>,
    count: usize,
    seed: u64,
) -> Result<DiscriminatorProbe> {
    let device = Device::Cpu;
    let mut config = read_config(run)?;
    if let Some(data) = data {
        config.data = data.to_path_buf();
    }
    let source = DatasetSource::for_training(&config)?;
    let mut trainer = Trainer::new(config.clone(), &device)?;
    trainer.load_state(run)?;
    let size = config.generator.resolution;
    let reals = source.reals(count, seed, &device)?;
    let other = source.fake_lights(count, seed ^ OTHER_LIGHTS_KEY)?;
    let other_omega = omega_for_placements(&other, size, &device)?;
    let seeds: Vec<u64> = (0..count as u64)
        .map(|k| (seed ^ FAKE_SEEDS_KEY).wrapping_add(k))
        .collect();
    let features = trainer.model().features_for_seeds_at(&seeds, 1.0, size)?;
    let fakes = trainer.model().relight().forward(&features, &other_omega)?;
    let d = trainer.discriminator();
    Ok(DiscriminatorProbe {
        step: trainer.steps_done(),
        count,
        reals: mean_logit(d, &reals.images, &reals.omega)?,
        reals_other_lights: mean_logit(d, &reals.images, &other_omega)?,
        reals_blurred: [
            mean_logit(d, &box_blur(&reals.images, BLUR_RADII[0])?, &reals.omega)?,
            mean_logit(d, &box_blur(&reals.images, BLUR_RADII[1])?, &reals.omega)?,
        ],
        fakes: mean_logit(d, &fakes, &other_omega)?,
        fakes_other_lights: mean_logit(d, &fakes, &reals.omega)?,
    })
}

/// D's mean logit on `images` under `omega`, both (B, 3, R, R).
pub fn mean_logit(d: &Discriminator, images: &Tensor, omega: &Tensor) -> Result<f64> {
    d.forward(images, omega)?
        .mean_all()?
        .to_dtype(candle_core::DType::F64)?
        .to_scalar()
}

/// Keys mixed into the seed for the other lights and the fakes' seeds, so that neither
/// repeats the reals' draw.
const OTHER_LIGHTS_KEY: u64 = 0x6f74_6865_726c_6974; // "otherlit"
const FAKE_SEEDS_KEY: u64 = 0x6661_6b65_7365_6564; // "fakeseed"

/// A (2r+1)² box blur with wrap-around edges, per channel and image.
///
/// # Shapes
/// (B, C, H, W) → same.
pub fn box_blur(x: &Tensor, radius: usize) -> Result<Tensor> {
    let r = radius as i32;
    let mut rows = x.zeros_like()?;
    for d in -r..=r {
        rows = (rows + x.roll(d, 2)?)?;
    }
    let mut out = rows.zeros_like()?;
    for d in -r..=r {
        out = (out + rows.roll(d, 3)?)?;
    }
    let taps = (2 * radius + 1) * (2 * radius + 1);
    out / taps as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_blur_keeps_constants_and_the_mean_and_averages_its_window() {
        let dev = Device::Cpu;
        // A period-2 checkerboard: a 3×3 window holds 5 of one value and 4 of the other.
        let data: Vec<f32> = (0..36).map(|i| ((i / 6 + i % 6) % 2) as f32).collect();
        let x = Tensor::from_vec(data, (1, 1, 6, 6), &dev).unwrap();
        let y = box_blur(&x, 1)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert!(
            (y[0] - 4.0 / 9.0).abs() < 1e-6 && (y[1] - 5.0 / 9.0).abs() < 1e-6,
            "{y:?}"
        );
        let mean = |t: &Tensor| t.mean_all().unwrap().to_scalar::<f32>().unwrap();
        assert!((mean(&box_blur(&x, 2).unwrap()) - mean(&x)).abs() < 1e-6);
        let c = Tensor::full(0.25f32, (2, 3, 8, 8), &dev).unwrap();
        let blurred = box_blur(&c, 3)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert!(blurred.iter().all(|v| (v - 0.25).abs() < 1e-6));
    }
}
