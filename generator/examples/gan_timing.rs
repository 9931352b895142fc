//! Parameter counts and CPU time of one G + M forward, its backward, a D forward + backward
//! and an R1 step, on photomat-kernels' ops and on plain candle ops, in the same process.
//!
//! ```text
//! cargo run --release -p photomat-generator --example gan_timing -- \
//!     [resolution] [multiplier] [batch] [--iters N] [--baseline | --fast]
//! ```
//!
//! Defaults: 64², multiplier 1, batch 4, 3 timed iterations after one warm-up. Each iteration
//! runs every case once on plain candle ops ([`photomat_kernels::with_reference_ops`], the
//! implementation before the kernels were used) and once on the kernels, interleaved so that
//! both see the same machine load; the medians and their ratio are printed. `--baseline` or
//! `--fast` times one implementation only.
//!
//! The process runs with the system allocator (the `photomat` CLI uses mimalloc, which
//! takes the page faults out of both paths' element-wise passes).
//!
//! Cases (f32, z ~ N(0, I), random noise, per-texel ω ~ N(0, 1)):
//! - `G+M fwd`: z → F → RGB, and `G+M bwd`: the backward pass of mean(RGB);
//! - `D fwd+bwd`: logits of real-like images, backward of their mean to D's parameters;
//! - `D R1 fwd+bwd`: the R1 penalty (a first backward to the image, kept in the graph) and
//!   the backward of its mean to D's parameters (a double backward).

use std::time::Instant;

use candle_core::{DType, Device, Result, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_generator::{
    Discriminator, Generator, GeneratorConfig, NoiseInput, Relight, parameter_count,
};
use photomat_kernels::with_reference_ops;

fn count(build: impl Fn(VarBuilder) -> Result<()>) -> Result<usize> {
    let vm = VarMap::new();
    build(VarBuilder::from_varmap(&vm, DType::F32, &Device::Cpu))?;
    Ok(parameter_count(&vm, false))
}

/// The networks and inputs of one timing run.
struct Setup {
    g: Generator,
    m: Relight,
    d: Discriminator,
    z: Tensor,
    omega: Tensor,
    image: Tensor,
}

/// Seconds of each case in one run: [G+M fwd, G+M bwd, D fwd+bwd, D R1 fwd+bwd].
fn run_once(s: &Setup) -> Result<[f64; 4]> {
    let t0 = Instant::now();
    let rgb =
        s.m.forward(&s.g.forward(&s.z, 1.0, &NoiseInput::Random)?, &s.omega)?;
    let loss = rgb.mean_all()?;
    let _ = loss.to_scalar::<f32>()?;
    let t1 = Instant::now();
    let grads = loss.backward()?;
    let t2 = Instant::now();
    assert!(grads.get_ids().next().is_some());
    let d_loss = s.d.forward(&s.image, &s.omega)?.mean_all()?;
    let grads = d_loss.backward()?;
    let t3 = Instant::now();
    assert!(grads.get_ids().next().is_some());
    let r1 = s.d.r1_penalty(&s.image, &s.omega)?.mean_all()?;
    let grads = r1.backward()?;
    let t4 = Instant::now();
    assert!(grads.get_ids().next().is_some());
    Ok([t1 - t0, t2 - t1, t3 - t2, t4 - t3].map(|d| d.as_secs_f64()))
}

fn median_ms(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2] * 1e3
}

fn main() -> Result<()> {
    let mut positional = Vec::new();
    let (mut iters, mut modes) = (3usize, vec![true, false]); // true: plain candle.
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--iters" => {
                iters = args.next().and_then(|s| s.parse().ok()).expect("--iters N");
            }
            "--baseline" => modes = vec![true],
            "--fast" => modes = vec![false],
            _ => positional.push(a),
        }
    }
    let resolution = positional
        .first()
        .map_or(64, |s| s.parse().expect("resolution"));
    let multiplier = positional
        .get(1)
        .map_or(1.0, |s| s.parse().expect("multiplier"));
    let batch = positional.get(2).map_or(4, |s| s.parse().expect("batch"));
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
        "{resolution}², multiplier {multiplier}, batch {batch}: G {g_params} (+{} w_avg), M {m_params}, D {d_params} trainable parameters; {} threads",
        cfg.latent_dim,
        photomat_kernels::alloc::thread_count()
    );

    let dev = Device::Cpu;
    let vars = VarMap::new();
    let vb = VarBuilder::from_varmap(&vars, DType::F32, &dev);
    let setup = Setup {
        g: Generator::new(&cfg, vb.pp("g"))?,
        m: Relight::new(&cfg, vb.pp("m"))?,
        d: Discriminator::new(&cfg, vb.pp("d"))?,
        z: Tensor::randn(0f32, 1., (batch, cfg.latent_dim), &dev)?,
        omega: Tensor::randn(0f32, 1., (batch, 3, resolution, resolution), &dev)?,
        image: Tensor::randn(0f32, 1., (batch, 3, resolution, resolution), &dev)?,
    };
    // times[mode][case] over the timed iterations.
    let mut times = vec![vec![Vec::new(); 4]; modes.len()];
    for it in 0..=iters {
        for (k, &plain) in modes.iter().enumerate() {
            let t = if plain {
                with_reference_ops(|| run_once(&setup))?
            } else {
                run_once(&setup)?
            };
            if it > 0 {
                for (case, v) in t.into_iter().enumerate() {
                    times[k][case].push(v);
                }
            }
        }
    }
    let names = ["G+M fwd", "G+M bwd", "D fwd+bwd", "D R1 fwd+bwd"];
    println!("median of {iters} (ms):");
    for (case, name) in names.iter().enumerate() {
        let med: Vec<f64> = (0..modes.len())
            .map(|k| median_ms(&times[k][case]))
            .collect();
        match med.as_slice() {
            [plain, fast] => println!(
                "  {name:<13} candle {plain:>8.1}  kernels {fast:>8.1}  speed-up {:.2}×",
                plain / fast
            ),
            [one] => println!(
                "  {name:<13} {} {one:>8.1}",
                if modes[0] { "candle" } else { "kernels" }
            ),
            _ => unreachable!("one or two modes"),
        }
    }
    Ok(())
}
