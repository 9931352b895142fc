//! Seconds per estimator training step (`photomat_estimator::train`, the step of
//! `photomat train-estimator`) with the fallback random-feature Gram loss, and the loss before
//! and after a short run, on a freshly initialised GAN (multiplier ¼, `train-gan`'s CPU
//! default) and `ggx`.
//!
//! Each timing is the median of several steps after one warm-up, reported next to a baseline
//! measured in the same process on the same batch shape: E's forward + backward alone, so the
//! ratio says what the rest of the step (G, M, the renderer, the Gram loss, Adam) costs; and
//! G's forward pass for the batch alone (`g_s`, its share of the step `g/step`).
//!
//! `cargo run --release -p photomat-estimator --example train_step_timing -- [STEPS] [RUNS]`
//! (defaults 200 loss steps at 32², width ¼, and 5 timed steps per configuration).

use std::time::Instant;

use candle_core::Device;
use photomat_brdfs as _;
use photomat_estimator::train::{EstimatorTrainer, TrainConfig};
use photomat_estimator::{EstimatorConfig, EstimatorModel};
use photomat_generator::{GanModel, GeneratorConfig};

/// The allocator the `photomat` binary runs with (element-wise ops are allocation bound).
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn trainer(size: usize, width: f64, steps: u64) -> anyhow::Result<EstimatorTrainer> {
    let gan_cfg = GeneratorConfig {
        resolution: size,
        channel_multiplier: 0.25,
        ..Default::default()
    };
    let gan = GanModel::new(&gan_cfg, 1, &Device::Cpu)?;
    let brdf = photomat_core::lookup("ggx")?;
    let arch = EstimatorConfig::for_brdf(brdf.as_ref()).with_width(width)?;
    let model = EstimatorModel::new_seeded(brdf, arch, 2, &Device::Cpu)?;
    let config = TrainConfig {
        steps,
        finetune_steps: steps,
        batch: 4,
        seed: 3,
        ..Default::default()
    };
    Ok(EstimatorTrainer::new(gan, model, config)?)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let loss_steps = args.first().copied().unwrap_or(200);
    let runs = args.get(1).copied().unwrap_or(5).max(1) as usize;

    println!("size width stage   step_s  e_fwd_bwd_s  ratio    g_s  g/step");
    for size in [32, 64] {
        for width in [1.0, 0.25] {
            let mut t = trainer(size, width, (runs + 1) as u64)?;
            let features = t.gan().features_for_seeds(&[1, 2, 3, 4], 1.0)?.detach();
            for stage in ["aligned", "finetune"] {
                let (mut step_s, mut base_s, mut g_s) = (Vec::new(), Vec::new(), Vec::new());
                for run in 0..=runs {
                    let t0 = Instant::now();
                    t.step()?;
                    let t1 = Instant::now();
                    let y = t.model().estimator().forward(&features)?;
                    let grads = y.abs()?.mean_all()?.backward()?;
                    std::hint::black_box(&grads);
                    let t2 = Instant::now();
                    std::hint::black_box(t.gan().features_for_seeds(&[5, 6, 7, 8], 1.0)?);
                    let t3 = Instant::now();
                    if run > 0 {
                        step_s.push((t1 - t0).as_secs_f64());
                        base_s.push((t2 - t1).as_secs_f64());
                        g_s.push((t3 - t2).as_secs_f64());
                    }
                }
                let (s, b, g) = (median(step_s), median(base_s), median(g_s));
                println!(
                    "{size:>4} {width:>5} {stage:<8} {s:>6.3} {b:>12.3} {:>6.2} {g:>6.3} {:>6.2}",
                    s / b,
                    g / s
                );
            }
        }
    }

    let mut t = trainer(32, 0.25, loss_steps)?;
    let mut totals = Vec::new();
    let t0 = Instant::now();
    for _ in 0..loss_steps {
        totals.push(t.step()?.total);
    }
    let k = (loss_steps as usize / 10).max(1);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    println!(
        "32², width 0.25, stage 1, lr 1e-4: mean loss of steps 1–{k} {:.5}, of the last {k} {:.5} \
         (ratio {:.3}) over {loss_steps} steps, {:.1} s",
        mean(&totals[..k]),
        mean(&totals[totals.len() - k..]),
        mean(&totals[totals.len() - k..]) / mean(&totals[..k]),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
