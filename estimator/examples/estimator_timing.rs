//! Wall time of one forward and one forward + backward pass of the default estimator E
//! (paper §4 "Implementation", n = 8) on the CPU, the number the crate docs and the project
//! notes quote. Median of several runs after one warm-up.
//!
//! `cargo run --release -p photomat-estimator --example estimator_timing -- [SIZE] [BATCH] [RUNS]`
//! (defaults 64, 4, 5).

use std::time::{Duration, Instant};

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_estimator::{Estimator, EstimatorConfig};

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let size = args.first().copied().unwrap_or(64);
    let batch = args.get(1).copied().unwrap_or(4);
    let runs = args.get(2).copied().unwrap_or(5).max(1);

    let device = Device::Cpu;
    let vars = VarMap::new();
    let e = Estimator::new(
        EstimatorConfig::default(),
        VarBuilder::from_varmap(&vars, DType::F32, &device),
    )?;
    let x = Tensor::randn(0f32, 1.0, (batch, 32, size, size), &device)?;

    let mut forward = Vec::new();
    let mut backward = Vec::new();
    for run in 0..=runs {
        let t0 = Instant::now();
        let y = e.forward(&x)?;
        let loss = y.abs()?.mean_all()?;
        loss.to_scalar::<f32>()?;
        let t1 = Instant::now();
        let grads = loss.backward()?;
        std::hint::black_box(&grads);
        let t2 = Instant::now();
        if run > 0 {
            forward.push(t1 - t0);
            backward.push(t2 - t1);
        }
    }
    let (f, b) = (median(forward), median(backward));
    println!(
        "estimator n=8, {batch}×32×{size}×{size}, {} parameters, {} threads: forward {:.1} ms, \
         backward {:.1} ms, forward+backward {:.1} ms (median of {runs})",
        EstimatorConfig::default().num_parameters(),
        candle_core::utils::get_num_threads(),
        f.as_secs_f64() * 1e3,
        b.as_secs_f64() * 1e3,
        (f + b).as_secs_f64() * 1e3,
    );
    Ok(())
}
