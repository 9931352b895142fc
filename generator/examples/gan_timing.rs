//! Parameter counts and forward/backward time of G + M (and D) on the CPU.
//!
//! ```text
//! cargo run --release -p photomat-generator --example gan_timing -- [resolution] [multiplier] [batch]
//! ```
//!
//! Defaults: 64², multiplier 1, batch 4. Times one G + M forward (z → F → RGB under per-texel
//! ω) and one backward of the mean of the output, after one warm-up iteration, median of 3.

use std::time::Instant;

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_generator::{
    Discriminator, Generator, GeneratorConfig, NoiseInput, Relight, parameter_count,
};

fn count(build: impl Fn(VarBuilder) -> candle_core::Result<()>) -> candle_core::Result<usize> {
    let vm = VarMap::new();
    build(VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu))?;
    Ok(parameter_count(&vm, false))
}

fn main() -> candle_core::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let resolution = args
        .get(1)
        .map_or(Ok(64), |s| s.parse())
        .expect("resolution");
    let multiplier = args
        .get(2)
        .map_or(Ok(1.0), |s| s.parse())
        .expect("multiplier");
    let batch = args.get(3).map_or(Ok(4), |s| s.parse()).expect("batch");
    let cfg = GeneratorConfig {
        resolution,
        channel_multiplier: multiplier,
        ..Default::default()
    };
    cfg.validate()?;
    let g_params = count(|vb| Generator::new(&cfg, vb).map(|_| ()))?;
    let m_params = count(|vb| Relight::new(&cfg, vb).map(|_| ()))?;
    let d_params = count(|vb| Discriminator::new(&cfg, vb).map(|_| ()))?;
    println!(
        "{resolution}², multiplier {multiplier}: G {g_params} (+{} w_avg), M {m_params}, D {d_params} trainable parameters",
        cfg.latent_dim
    );

    let dev = Device::Cpu;
    let vars = VarMap::new();
    let vb = VarBuilder::from_varmap(&vars, DType::F32, &dev);
    let g = Generator::new(&cfg, vb.pp("g"))?;
    let m = Relight::new(&cfg, vb.pp("m"))?;
    let z = Tensor::randn(0f32, 1., (batch, cfg.latent_dim), &dev)?;
    let omega = Tensor::randn(0f32, 1., (batch, 3, resolution, resolution), &dev)?;
    let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
    for _ in 0..4 {
        let t0 = Instant::now();
        let rgb = m.forward(&g.forward(&z, 1.0, &NoiseInput::Random)?, &omega)?;
        let loss = rgb.mean_all()?;
        let _ = loss.to_scalar::<f32>()?;
        let t1 = Instant::now();
        let grads = loss.backward()?;
        let t2 = Instant::now();
        assert!(!grads.get_ids().collect::<Vec<_>>().is_empty());
        fwd.push((t1 - t0).as_secs_f64());
        bwd.push((t2 - t1).as_secs_f64());
    }
    let median = |v: &mut Vec<f64>| {
        v.remove(0); // warm-up
        v.sort_by(f64::total_cmp);
        v[v.len() / 2] * 1e3
    };
    println!(
        "G+M batch {batch}: forward {:.0} ms, backward {:.0} ms (median of 3)",
        median(&mut fwd),
        median(&mut bwd)
    );
    Ok(())
}
