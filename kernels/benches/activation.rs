//! StyleGAN2's `lrelu` (slope 0.2, gain √2), without and with the per-channel bias add,
//! forward + backward: the fused [`photomat_kernels::leaky_relu_gain`] /
//! [`photomat_kernels::bias_leaky_relu_gain`] against `broadcast_add` and the composite
//! `g·(1 − a)·relu(x) + g·a·x` of candle ops (the form measured fastest among candle
//! compositions, `docs/candle-notes.md`, "Speed"), paired in one process.
//!
//! Run (docs/benchmarks/conv-kernels.md, "Fused LeakyReLU", records the numbers):
//!
//! ```text
//! cargo bench -p photomat-kernels --features mimalloc --bench activation
//! ```
//!
//! One pass: `y = lrelu(x [+ b])` on `Var`s, `Σ y ⊙ g`, `backward()` to x (and b). 7 rounds of 5 passes per
//! variant, the order alternating; medians of the per-round medians and of the per-round
//! ratios.

mod common;
use common::{alternate, median, setup};

use std::hint::black_box;
use std::time::Instant;

use candle_core::{DType, Device, Result, Tensor, Var};
use photomat_core::rng::pseudo_random;
use photomat_kernels::{bias_leaky_relu_gain, leaky_relu_gain};

#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

const SLOPE: f64 = 0.2;
const GAIN: f64 = std::f64::consts::SQRT_2;

/// One pass; with `bias`, the bias add (a `Var` of C values) is part of the activation.
fn pass(fused: bool, x: &Var, bias: Option<&Var>, g: &Tensor) -> Result<()> {
    let t = x.as_tensor();
    let y = match (fused, bias) {
        (true, None) => leaky_relu_gain(t, SLOPE, GAIN)?,
        (true, Some(b)) => bias_leaky_relu_gain(t, b.as_tensor(), SLOPE, GAIN)?,
        (false, bias) => {
            let z = match bias {
                Some(b) => t.broadcast_add(&b.as_tensor().reshape((1, (), 1, 1))?)?,
                None => t.clone(),
            };
            (z.relu()?.affine(GAIN * (1.0 - SLOPE), 0.0)? + z.affine(GAIN * SLOPE, 0.0)?)?
        }
    };
    let grads = (y * g)?.sum_all()?.backward()?;
    black_box(grads.get(t));
    Ok(())
}

fn main() -> Result<()> {
    println!("{}", setup());
    println!("| x shape | bias | composite (ms) | fused (ms) | composite ÷ fused |");
    println!("|---------|------|---------------:|-----------:|------------------:|");
    // G's activations at 128² (128 channels) and 256² (64 channels), batch 4; M's hidden
    // layer for one 256² image (64 features per texel).
    let shapes = [(4, 128, 128, 128), (4, 64, 256, 256), (1, 64, 256, 256)];
    for (shape, with_bias) in shapes.into_iter().flat_map(|s| [(s, false), (s, true)]) {
        let x = Var::from_tensor(&pseudo_random(shape, 1, DType::F32, &Device::Cpu)?)?;
        let b = Var::from_tensor(&pseudo_random(shape.1, 3, DType::F32, &Device::Cpu)?)?;
        let bias = with_bias.then_some(&b);
        let g = pseudo_random(shape, 2, DType::F32, &Device::Cpu)?;
        pass(true, &x, bias, &g)?;
        pass(false, &x, bias, &g)?;
        let (mut comp, mut fused, mut ratio) = (Vec::new(), Vec::new(), Vec::new());
        for round in 0..7 {
            let time = |use_fused: bool| -> Result<f64> {
                let mut t = Vec::new();
                for _ in 0..5 {
                    let start = Instant::now();
                    pass(use_fused, &x, bias, &g)?;
                    t.push(start.elapsed().as_secs_f64() * 1e3);
                }
                Ok(median(t))
            };
            let (c, f) = alternate(round, || time(false), || time(true))?;
            comp.push(c);
            fused.push(f);
            ratio.push(c / f);
        }
        println!(
            "| {shape:?} | {} | {:.1} | {:.1} | {:.2}× |",
            if with_bias { "yes" } else { "no" },
            median(comp),
            median(fused),
            median(ratio)
        );
    }
    Ok(())
}
