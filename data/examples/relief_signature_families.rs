//! The relief signature (`photomat_data::relief_signature`) of the simulator's families: each
//! family's ground-truth maps rendered under the signature's two lights, once as they are and
//! once with their relief removed (normal map +z, or height flat), for comparison with what
//! `photomat eval-gan` reports for a model's relighting (`docs/benchmarks/relief.md`, "Does M's
//! relighting show relief?").
//!
//! ```text
//! cargo run --release -p photomat-data --example relief_signature_families -- [SIZE] [SEEDS]
//! ```
//! Defaults: 256, 4. Prints, per family, the mean R² with the texture, along and across.

use candle_core::Device;
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_core::image_io::PlanarImage;
use photomat_core::{lookup, render};
use photomat_data::procedural::families;
use photomat_data::relief_signature::{
    ReliefSignature, relief_signature, signature_lights, without_relief,
};

fn main() -> photomat_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let size: usize = args
        .first()
        .map_or(Ok(256), |s| s.parse())
        .expect("SIZE: a number");
    let seeds: u64 = args
        .get(1)
        .map_or(Ok(4), |s| s.parse())
        .expect("SEEDS: a number");
    let device = Device::Cpu;
    // The unit square: the lights at (0, ±0.3).
    let lights = signature_lights(1.0);
    println!(
        "{:<14} {:>28}   {:>28}",
        "", "as simulated", "relief removed"
    );
    println!(
        "{:<14} {:>8} {:>9} {:>9}   {:>8} {:>9} {:>9}",
        "family", "texture", "along", "across", "texture", "along", "across"
    );
    for family in families() {
        let brdf = lookup(&family.brdf())?;
        let mut sums = [ReliefSignature::default(); 2];
        for seed in 0..seeds {
            let maps = family.generate(size, seed, &device)?;
            for (sum, maps) in sums.iter_mut().zip([maps.clone(), without_relief(&maps)?]) {
                let images = render(brdf.as_ref(), &maps, &lights)?;
                let tiles = PlanarImage::batch_from_tensor(&images)?;
                let s = relief_signature(&tiles[0], &tiles[1])?;
                sum.texture += s.texture / seeds as f64;
                sum.along += s.along / seeds as f64;
                sum.across += s.across / seeds as f64;
            }
        }
        let [a, b] = sums;
        println!(
            "{:<14} {:>8.3} {:>9.3} {:>9.3}   {:>8.3} {:>9.3} {:>9.3}",
            family.name(),
            a.texture,
            a.along,
            a.across,
            b.texture,
            b.along,
            b.across
        );
    }
    Ok(())
}
