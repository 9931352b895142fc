//! Wall time of `swd::sliced_wasserstein` at `photomat eval-gan`'s default size (256 images
//! per set) for a given side, on pseudo-random images, printed as JSON so that a script can
//! set it beside the reference NumPy/SciPy implementation run on sets of the same size.
//!
//! ```text
//! cargo run --release -p photomat-generator --example swd_timing -- 64 256 3
//! ```
//! Arguments: side (default 64), images per set (default 256), repetitions (default 3).

use std::time::Instant;

use candle_core::{DType, Device};
use photomat_core::rng::pseudo_random;
use photomat_generator::swd::{SwdConfig, sliced_wasserstein};

fn main() -> candle_core::Result<()> {
    let arg = |i: usize, default: usize| {
        std::env::args()
            .nth(i)
            .map(|a| a.parse().expect("a number"))
            .unwrap_or(default)
    };
    let (side, count, reps) = (arg(1, 64), arg(2, 256), arg(3, 3));
    let real = pseudo_random((count, 3, side, side), 1, DType::F32, &Device::Cpu)?;
    let fake = pseudo_random((count, 3, side, side), 2, DType::F32, &Device::Cpu)?;
    let mut seconds = Vec::with_capacity(reps);
    let mut mean = 0.0;
    for rep in 0..reps {
        let start = Instant::now();
        mean = sliced_wasserstein(&real, &fake, &SwdConfig::default(), rep as u64)?.mean;
        seconds.push(start.elapsed().as_secs_f64());
    }
    println!(
        "{{\"side\": {side}, \"count\": {count}, \"seconds\": {seconds:?}, \"swd_mean_x1e3\": {mean}}}"
    );
    Ok(())
}
