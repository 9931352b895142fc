//! What a training run's discriminator looks at: D's mean logit on real patches, on the same
//! patches under another sample's lights, on the same patches blurred (their texture removed,
//! their colour and highlight kept), and on G's fakes. A D that scores blurred reals like
//! reals gives G no reason to make texture; one that scores them like fakes does.
//!
//! ```text
//! cargo run --release -p photomat-data --example d_probe -- RUN DATA [N] [SEED]
//! ```
//! RUN: a `photomat train-gan` run folder (train.json + train_state.safetensors); DATA: its
//! data set (`photomat prepare` folder); N images per row (default 64).

use std::path::PathBuf;

use anyhow::Context;
use candle_core::{Device, Tensor};
use photomat_data::source::DatasetSource;
use photomat_generator::train::data::omega_for_placements;
use photomat_generator::train::state::read_config;
use photomat_generator::train::{Trainer, TrainingData};

/// A box blur of radius `r` texels with wrap-around edges, per channel.
///
/// # Shapes
/// (B, C, H, W) → same.
fn box_blur(x: &Tensor, r: i64) -> anyhow::Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    let mut rows = x.zeros_like()?;
    for d in -r..=r {
        rows = (rows + x.roll(d as i32, 2)?)?;
    }
    let mut out = rows.zeros_like()?;
    for d in -r..=r {
        out = (out + rows.roll(d as i32, 3)?)?;
    }
    let n = ((2 * r + 1) * (2 * r + 1)) as f64;
    debug_assert!(h > 2 * r as usize && w > 2 * r as usize);
    Ok((out / n)?)
}

fn mean(t: &Tensor) -> anyhow::Result<f64> {
    Ok(t.mean_all()?.to_dtype(candle_core::DType::F64)?.to_scalar()?)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (run, data) = match (args.first(), args.get(1)) {
        (Some(r), Some(d)) => (PathBuf::from(r), PathBuf::from(d)),
        _ => anyhow::bail!("usage: d_probe RUN DATA [N] [SEED]"),
    };
    let n: usize = args.get(2).map_or(Ok(64), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(7), |s| s.parse())?;
    let device = Device::Cpu;
    let mut config = read_config(&run)?;
    config.data = data;
    let source = DatasetSource::for_training(&config)?;
    let mut trainer = Trainer::new(config.clone(), &device)?;
    trainer
        .load_state(&run)
        .with_context(|| format!("cannot load the state of {}", run.display()))?;
    let d = trainer.discriminator();
    let size = config.generator.resolution;

    let reals = source.reals(n, seed, &device)?;
    let placements = source.fake_lights(n, seed ^ 0x9e37)?;
    let other_omega = omega_for_placements(&placements, size, &device)?;
    let seeds: Vec<u64> = (0..n as u64).map(|k| 1_000_000 + seed * 1000 + k).collect();
    let features = trainer
        .model()
        .features_for_seeds_at(&seeds, 1.0, size)?;
    let fakes = trainer.model().relight().forward(&features, &other_omega)?;

    let rows: Vec<(&str, Tensor, &Tensor)> = vec![
        ("reals", reals.images.clone(), &reals.omega),
        ("reals, another sample's lights", reals.images.clone(), &other_omega),
        ("reals blurred (box r=1)", box_blur(&reals.images, 1)?, &reals.omega),
        ("reals blurred (box r=3)", box_blur(&reals.images, 3)?, &reals.omega),
        ("fakes (G, training weights)", fakes.clone(), &other_omega),
        ("fakes, another sample's lights", fakes, &reals.omega),
    ];
    println!(
        "{} at step {} ({} images per row): D's mean logit",
        run.display(),
        trainer.steps_done(),
        n
    );
    for (name, images, omega) in rows {
        let logits = d.forward(&images, omega)?;
        println!("  {name:<34} {:+.3}", mean(&logits)?);
    }
    Ok(())
}
