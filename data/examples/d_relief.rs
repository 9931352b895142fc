//! Can the discriminator of a run's architecture see relief in one flash photo? D alone (no
//! G), fresh from the run's seed, learns to tell simulated photos of the procedural families
//! from photos of the same maps under the same flash with the relief removed (normal map +z,
//! `photomat_data::relief_signature::without_relief`). Every 50 steps it prints D's mean logit
//! gap (with relief − without) on held-out pairs. A D that cannot open this gap cannot ask G
//! for relief, whatever the GAN's settings (`docs/benchmarks/relief.md`, "Does M's relighting show
//! relief?"; the same question for texture is `d_capacity`).
//!
//! ```text
//! cargo run --release -p photomat-data --example d_relief -- RUN [STEPS] [PAIRS]
//! ```
//! RUN: a `photomat train-gan` run folder (its train.json gives D's architecture, input
//! sharpening, batch, seed and Adam settings). Defaults: 300 steps, 256 training pairs (64 more
//! are held out). Materials are whole family samples at the model's side (on the unit square),
//! each under a flash whose highlight is uniform over the central 80 %.

use std::path::PathBuf;

use anyhow::Context;
use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_core::rng::SplitMix64;
use photomat_core::{FlashGeometry, Highlight, lookup, render};
use photomat_data::discriminator_probe::mean_logit;
use photomat_data::procedural::families;
use photomat_data::relief_signature::without_relief;
use photomat_generator::train::fresh_discriminator;
use photomat_generator::train::loss::softplus;
use photomat_generator::train::state::read_config;

/// Pairs kept out of training, on which the gap is measured.
const HELD_OUT: usize = 64;

/// (with relief, without, ω) for `count` materials from `first`, images in D's range [−1, 1].
fn pairs(first: usize, count: usize, size: usize) -> anyhow::Result<(Tensor, Tensor, Tensor)> {
    let device = Device::Cpu;
    let all = families();
    let mut rng = SplitMix64(0x7265_6c69_6566 ^ first as u64);
    let (mut with, mut without, mut omega) = (Vec::new(), Vec::new(), Vec::new());
    for i in first..first + count {
        let family = &all[i % all.len()];
        let brdf = lookup(&family.brdf())?;
        let maps = family.generate(size, i as u64, &device)?;
        let light = [Highlight {
            x: 0.8 * (rng.next_unit() - 0.5),
            y: 0.8 * (rng.next_unit() - 0.5),
        }];
        with.push(render(brdf.as_ref(), &maps, &light)?.affine(2.0, -1.0)?);
        without.push(render(brdf.as_ref(), &without_relief(&maps)?, &light)?.affine(2.0, -1.0)?);
        omega.push(FlashGeometry::new(&light, size, DType::F32, &device)?.omega);
    }
    let cat = |v: Vec<Tensor>| -> anyhow::Result<Tensor> {
        Ok(Tensor::cat(&v, 0)?.to_dtype(DType::F32)?)
    };
    Ok((cat(with)?, cat(without)?, cat(omega)?))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: d_relief RUN [STEPS] [PAIRS]";
    let run = PathBuf::from(args.first().context(usage)?);
    let steps: usize = args.get(1).map_or(Ok(300), |s| s.parse())?;
    let count: usize = args.get(2).map_or(Ok(256), |s| s.parse())?;
    let config = read_config(&run)?;
    let size = config.generator.resolution;
    let device = Device::Cpu;
    let (train_with, train_without, train_omega) = pairs(0, count, size)?;
    let (held_with, held_without, held_omega) = pairs(count, HELD_OUT, size)?;
    let (_vars, d, mut adam) = fresh_discriminator(&config, &device)?;
    let b = config.batch;
    println!(
        "D of {} (multiplier {}, input sharpening {}, {size}², batch {b}, lr {}): mean logit \
         gap with − without relief on {HELD_OUT} held-out pairs",
        run.display(),
        config.generator.channel_multiplier,
        config.generator.d_input_sharpen,
        config.lr
    );
    println!("{:>6}  {:>10}", "step", "relief gap");
    for step in 0..=steps {
        if step % 50 == 0 {
            let gap = mean_logit(&d, &held_with, &held_omega)?
                - mean_logit(&d, &held_without, &held_omega)?;
            println!("{step:>6}  {gap:>10.3}");
        }
        if step == steps {
            break;
        }
        let first = (step * b) % (count - b + 1);
        let pick = |t: &Tensor| t.narrow(0, first, b);
        let omega = pick(&train_omega)?;
        let loss = (softplus(&d.forward(&pick(&train_with)?, &omega)?.neg()?)?.mean_all()?
            + softplus(&d.forward(&pick(&train_without)?, &omega)?)?.mean_all()?)?;
        adam.step(&loss.backward()?)?;
    }
    Ok(())
}
