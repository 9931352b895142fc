//! The estimator's circular conv layers (`docs/neural-models.md`, "Map estimator E"; E at 256²,
//! batch 4), forward + backward: its previous path against [`photomat_kernels::conv2d`], paired in
//! one process.
//!
//! Run (docs/benchmarks/conv-kernels.md, "Estimator layers", records the numbers):
//!
//! ```text
//! cargo bench -p photomat-kernels --features mimalloc --bench estimator_layers
//! ```
//!
//! - *previous*: what `photomat-estimator`'s `CircularConv2d` did before it moved to the kernels
//!   crate: wrap-around padding by `narrow` + `cat` (its `circular_pad`), then
//!   [`photomat_kernels::conv2d_fast_backward`] (candle's `conv2d` forward, polyphase `conv2d`
//!   input gradient, candle's weight gradient);
//! - *new*: `conv2d(x, w, Conv2dSpec::circular(s, (k − s)/2))`, wrap-around inside im2col.
//!
//! One pass: forward on `Var`s, `Σ y ⊙ g`, `backward()` to input and weight. 5 rounds, the
//! order alternating; medians of the times and of the per-round ratios.

mod common;
use common::{alternate, median, setup};

use std::hint::black_box;
use std::time::Instant;

use candle_core::{DType, Device, Result, Tensor, Var};
use photomat_core::rng::pseudo_random;
use photomat_kernels::{Conv2dSpec, conv2d, conv2d_fast_backward};

#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn pass(new: bool, x: &Var, w: &Var, g: &Tensor, k: usize, s: usize) -> Result<()> {
    let p = (k - s) / 2;
    let y = if new {
        conv2d(x.as_tensor(), w.as_tensor(), Conv2dSpec::circular(s, p))?
    } else {
        conv2d_fast_backward(
            &photomat_kernels::circular_pad(x.as_tensor(), p)?,
            w.as_tensor(),
            s,
        )?
    };
    let grads = (y * g)?.sum_all()?.backward()?;
    black_box((grads.get(x.as_tensor()), grads.get(w.as_tensor())));
    Ok(())
}

fn main() -> Result<()> {
    let dev = Device::Cpu;
    println!("{}", setup());
    println!("| layer | previous (ms) | new (ms) | previous ÷ new |");
    println!("|-------|--------------:|---------:|---------------:|");
    // (name, (B, C_in, H = W), C_out, k, stride): E's first encoder block (4×4 s2 and 3×3 at
    // 32 channels), its last decoder conv on the 32+32-channel concat, and a deep 3×3.
    let layers = [
        ("4×4 s2 32→32, 256² b4", (4, 32, 256), 32, 4, 2),
        ("3×3 32→32, 128² b4", (4, 32, 128), 32, 3, 1),
        ("3×3 64→32, 256² b4", (4, 64, 256), 32, 3, 1),
        ("3×3 512→256, 16² b4", (4, 512, 16), 256, 3, 1),
    ];
    for (name, (b, ci, h), co, k, s) in layers {
        let x = Var::from_tensor(&pseudo_random((b, ci, h, h), 1, DType::F32, &dev)?)?;
        let w = Var::from_tensor(&pseudo_random((co, ci, k, k), 2, DType::F32, &dev)?)?;
        let g = pseudo_random((b, co, h / s, h / s), 3, DType::F32, &dev)?;
        pass(true, &x, &w, &g, k, s)?;
        pass(false, &x, &w, &g, k, s)?;
        let (mut prev, mut new, mut ratio) = (Vec::new(), Vec::new(), Vec::new());
        for round in 0..5 {
            let time = |use_new: bool| -> Result<f64> {
                let start = Instant::now();
                pass(use_new, &x, &w, &g, k, s)?;
                Ok(start.elapsed().as_secs_f64() * 1e3)
            };
            let (p, n) = alternate(round, || time(false), || time(true))?;
            prev.push(p);
            new.push(n);
            ratio.push(p / n);
        }
        println!(
            "| {name} | {:.1} | {:.1} | {:.2}× |",
            median(prev),
            median(new),
            median(ratio)
        );
    }
    Ok(())
}
