//! Can the discriminator of a run's architecture learn to see texture at all? D alone (no G),
//! fresh from the run's seed, is trained on two tasks side by side for a few hundred steps:
//! real patches against the same patches box-blurred 7×7 (texture), and real patches against
//! the same patches under other samples' lights (light). Every 50 steps it prints D's mean
//! logit gap on a held-out batch for each task. A D that learns the light gap in a few dozen
//! steps and the texture gap never cannot teach G texture, whatever the GAN's settings.
//!
//! ```text
//! cargo run --release -p photomat-data --example d_capacity -- RUN DATA [STEPS] [MULTIPLIER] [LR] [TASKS] [BOOST]
//! ```
//! RUN: a `photomat train-gan` run folder (its train.json gives the architecture, batch, seed
//! and Adam settings); MULTIPLIER and LR override its channel multiplier and learning rate;
//! TASKS `both` (default) or `texture` (the blurred patches alone as negatives); BOOST k > 0
//! feeds D `x + k·(x − blur₃ₓ₃ x)` instead of x (high frequencies ×(k+1)).

use std::path::PathBuf;

use anyhow::Context;
use candle_core::{Device, Tensor};
use photomat_data::discriminator_probe::{box_blur, mean_logit};
use photomat_data::source::DatasetSource;
use photomat_generator::train::TrainingData;
use photomat_generator::train::data::omega_for_placements;
use photomat_generator::train::fresh_discriminator;
use photomat_generator::train::loss::softplus;
use photomat_generator::train::state::read_config;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: d_capacity RUN DATA [STEPS] [MULTIPLIER] [LR] [both|texture] [BOOST]";
    let run = PathBuf::from(args.first().context(usage)?);
    let data = PathBuf::from(args.get(1).context(usage)?);
    let steps: usize = args.get(2).map_or(Ok(300), |s| s.parse())?;
    let mut config = read_config(&run)?;
    config.data = data;
    if let Some(m) = args.get(3) {
        config.generator.channel_multiplier = m.parse()?;
    }
    if let Some(lr) = args.get(4) {
        config.lr = lr.parse()?;
    }
    // Optional preconditioning of D's input: x + k·(x − blur₃ₓ₃(x)), high frequencies ×(k+1).
    let boost: f64 = args.get(6).map_or(Ok(0.0), |s| s.parse())?;
    let pre = |x: &Tensor| -> anyhow::Result<Tensor> {
        if boost == 0.0 {
            return Ok(x.clone());
        }
        Ok((x + ((x - box_blur(x, 1)?)? * boost)?)?)
    };
    let light_task = match args.get(5).map(String::as_str) {
        None | Some("both") => true,
        Some("texture") => false,
        Some(other) => anyhow::bail!("TASKS must be both or texture, got {other}"),
    };
    let device = Device::Cpu;
    let source = DatasetSource::for_training(&config)?;
    let size = config.generator.resolution;
    let (_vars, d, mut adam) = fresh_discriminator(&config, &device)?;
    let b = config.batch;
    let other_omega = |n: usize, seed: u64| -> anyhow::Result<Tensor> {
        let placements = source.fake_lights(n, seed)?;
        Ok(omega_for_placements(&placements, size, &device)?)
    };
    let held = source.reals(64, 0xfeed, &device)?;
    let held_blurred = pre(&box_blur(&held.images, 3)?)?;
    let held_images = pre(&held.images)?;
    let held_other = other_omega(64, 0xbeef)?;
    println!(
        "D of {} (multiplier {}, {size}², batch {b}, lr {}): mean logit gaps on 64 held-out patches",
        run.display(),
        config.generator.channel_multiplier,
        config.lr
    );
    println!("{:>6}  {:>12}  {:>12}", "step", "texture gap", "light gap");
    for step in 0..=steps {
        if step % 50 == 0 {
            let real = mean_logit(&d, &held_images, &held.omega)?;
            let blurred = mean_logit(&d, &held_blurred, &held.omega)?;
            let other = mean_logit(&d, &held_images, &held_other)?;
            println!(
                "{step:>6}  {:>12.3}  {:>12.3}",
                real - blurred,
                real - other
            );
        }
        if step == steps {
            break;
        }
        let reals = source.reals(b, 1000 + step as u64, &device)?;
        let blurred = pre(&box_blur(&reals.images, 3)?)?;
        let images = pre(&reals.images)?;
        let omega2 = other_omega(b, 5000 + step as u64)?;
        let real_logits = d.forward(&images, &reals.omega)?;
        let texture = (softplus(&real_logits.neg()?)?.mean_all()?
            + softplus(&d.forward(&blurred, &reals.omega)?)?.mean_all()?)?;
        let loss = match light_task {
            true => {
                (texture
                    + softplus(&real_logits.neg()?)?.mean_all()?
                    + softplus(&d.forward(&images, &omega2)?)?.mean_all()?)?
            }
            false => texture,
        };
        adam.step(&loss.backward()?)?;
    }
    Ok(())
}
