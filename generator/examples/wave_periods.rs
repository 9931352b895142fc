//! What the periodic waves of a trained spatial G learned (`photomat_generator::waves`): for
//! each wave, the period and direction it takes over many materials, and how strongly each
//! block reads it.
//!
//! `cargo run --release -p photomat-generator --example wave_periods -- GAN [COUNT] [SIDE]`
//!
//! GAN is a model folder with `spatial.waves` > 0; COUNT materials (seeds 0 … COUNT − 1,
//! ψ = 1, default 256); SIDE the sample side the waves are rounded to (default 512). A period
//! is the lattice's spacing in texels, `side / |m|` with m the whole cycles per side.

use candle_core::{Device, IndexOp};
use photomat_generator::GanModel;
use photomat_generator::waves::PeriodicWaves;

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(dir) = args.first() else {
        anyhow::bail!("usage: wave_periods GAN [COUNT] [SIDE]");
    };
    let count: u64 = args.get(1).map_or(Ok(256), |s| s.parse())?;
    let side: usize = args.get(2).map_or(Ok(512), |s| s.parse())?;
    let model = GanModel::load(std::path::Path::new(dir), &Device::Cpu)?;
    let g = model.generator();
    let Some(waves) = g.synthesis().periodic_waves() else {
        anyhow::bail!("{dir}: this generator has no periodic waves (spatial.waves is 0)");
    };
    let seeds: Vec<u64> = (0..count).collect();
    let ws = g.ws(&model.latents(&seeds)?, 1.0)?;
    let k = waves.wave_vectors(&ws.i((.., 0))?)?;
    let cycles = PeriodicWaves::cycles_per_side(&k, side)?;
    let cycles: Vec<Vec<Vec<f32>>> = cycles.to_vec3()?;
    let norms = waves.projection_norms()?;
    println!(
        "{dir}: {} waves, {count} materials, rounded to a {side}-texel side",
        waves.waves()
    );
    println!(
        "wave | period (texels) p10 / median / p90 | flat (m = 0) | direction median (deg) | projection norm per block"
    );
    for j in 0..waves.waves() {
        let mut periods = Vec::new();
        let mut angles = Vec::new();
        for material in &cycles {
            let [mx, my] = [material[j][0] as f64, material[j][1] as f64];
            let m = mx.hypot(my);
            if m > 0.0 {
                periods.push(side as f64 / m);
                // Direction of the wave vector, folded to [0°, 180°) (k and −k are one lattice).
                angles.push(my.atan2(mx).to_degrees().rem_euclid(180.0));
            }
        }
        periods.sort_by(f64::total_cmp);
        angles.sort_by(f64::total_cmp);
        let flat = count as usize - periods.len();
        let (p10, p50, p90, a50) = if periods.is_empty() {
            (f64::NAN, f64::NAN, f64::NAN, f64::NAN)
        } else {
            (
                quantile(&periods, 0.1),
                quantile(&periods, 0.5),
                quantile(&periods, 0.9),
                quantile(&angles, 0.5),
            )
        };
        let per_block: Vec<String> = norms.iter().map(|b| format!("{:.2}", b[j])).collect();
        println!(
            "{j} | {p10:.1} / {p50:.1} / {p90:.1} | {flat} | {a50:.0} | {}",
            per_block.join(" ")
        );
    }
    Ok(())
}
