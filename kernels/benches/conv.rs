//! photomat's im2col + gemm `conv2d` against candle 0.11's `conv2d`, at the project's shapes,
//! in one process.
//!
//! Run (docs/benchmarks/conv-kernels.md, "conv2d: photomat-kernels vs candle", records the
//! numbers):
//!
//! ```text
//! cargo bench -p photomat-kernels --features mimalloc --bench conv
//! cargo bench -p photomat-kernels --features mimalloc --bench conv -- --summary-only
//! ```
//!
//! Criterion measures, per case, group `conv/<case>`: `ours_fwd`, `candle_fwd` (forward only,
//! no graph) and `ours_fwd_bwd`, `candle_fwd_bwd` (forward on `Var`s, then the gradients
//! w.r.t. input and weight of `Σ y ⊙ g`), with throughput in FLOP (criterion's "elem/s" is
//! FLOP/s). Afterwards the bench times each pair again, alternating ours and candle round
//! after round so machine load hits both alike, times the sgemm ceiling (candle `matmul` of
//! two 1024² f32 matrices) in every round too, and prints a markdown table: median times,
//! GFLOP/s, share of the median sgemm ceiling of the same rounds and the median per-round
//! ratio candle ÷ ours (> 1: ours is faster).
//!
//! With `--features mimalloc` the bench runs on mimalloc, as the `photomat` binary does
//! (`photomat_kernels::alloc`); both implementations share the allocator either way.
//!
//! FLOP counts: forward `2·B·C_out·H_out·W_out·C_in·k²`; forward + backward three times that
//! (input and weight gradients cost one forward each). Threads: candle's and ours follow
//! `RAYON_NUM_THREADS`, else the physical core count (`photomat_kernels::alloc`).

mod common;
use common::{alternate, median, setup};

use std::hint::black_box;
use std::time::{Duration, Instant};

use candle_core::{DType, Device, Result, Tensor, Var};
use criterion::{Criterion, Throughput};
use photomat_core::rng::pseudo_random;
use photomat_kernels::{Conv2dSpec, conv2d, conv2d_reference};

#[cfg(feature = "mimalloc")]
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

/// One benchmarked layer: x (B, C_in, H, W), w (C_out, C_in, k, k).
struct Case {
    name: &'static str,
    x: (usize, usize, usize, usize),
    c_out: usize,
    k: usize,
    spec: Conv2dSpec,
}

impl Case {
    fn flops(&self) -> f64 {
        let (b, ci, h, w) = self.x;
        let p = self.spec.padding;
        let ho = (h + 2 * p - self.k) / self.spec.stride + 1;
        let wo = (w + 2 * p - self.k) / self.spec.stride + 1;
        2.0 * (b * self.c_out * ho * wo * ci * self.k * self.k) as f64
    }
}

/// The project's shapes: G's and E's 3×3 layers at 128² (64 channels: G at 256², or E's
/// second level), E's 4×4 stride-2 downsampling, a 1×1 layer (toRGB / per-texel MLP), and
/// the circular 3×3 every tileable layer uses.
const CASES: &[Case] = &[
    Case {
        name: "3x3_64to64_128px_b4",
        x: (4, 64, 128, 128),
        c_out: 64,
        k: 3,
        spec: Conv2dSpec::zeros(1, 1),
    },
    Case {
        name: "3x3_64to64_128px_b4_circular",
        x: (4, 64, 128, 128),
        c_out: 64,
        k: 3,
        spec: Conv2dSpec::circular(1, 1),
    },
    Case {
        name: "4x4s2_64to64_128px_b4",
        x: (4, 64, 128, 128),
        c_out: 64,
        k: 4,
        spec: Conv2dSpec::zeros(2, 1),
    },
    Case {
        name: "1x1_64to64_128px_b4",
        x: (4, 64, 128, 128),
        c_out: 64,
        k: 1,
        spec: Conv2dSpec::zeros(1, 0),
    },
];

type ConvFn = fn(&Tensor, &Tensor, Conv2dSpec) -> Result<Tensor>;

/// Inputs of one case: x and w as `Var`s, and the output weights g of the loss `Σ y ⊙ g`.
fn inputs(case: &Case) -> Result<(Var, Var, Tensor)> {
    let dev = Device::Cpu;
    let (_, ci, _, _) = case.x;
    let x = Var::from_tensor(&pseudo_random(case.x, 1, DType::F32, &dev)?)?;
    let w = Var::from_tensor(&pseudo_random(
        (case.c_out, ci, case.k, case.k),
        2,
        DType::F32,
        &dev,
    )?)?;
    let y = conv2d(x.as_tensor(), w.as_tensor(), case.spec)?;
    let g = pseudo_random(y.shape(), 3, DType::F32, &dev)?;
    Ok((x, w, g))
}

fn forward(conv: ConvFn, case: &Case, x: &Var, w: &Var) -> Result<()> {
    black_box(conv(
        &x.as_tensor().detach(),
        &w.as_tensor().detach(),
        case.spec,
    )?);
    Ok(())
}

fn forward_backward(conv: ConvFn, case: &Case, x: &Var, w: &Var, g: &Tensor) -> Result<()> {
    let y = conv(x.as_tensor(), w.as_tensor(), case.spec)?;
    let grads = (y * g)?.sum_all()?.backward()?;
    black_box((grads.get(x.as_tensor()), grads.get(w.as_tensor())));
    Ok(())
}

fn criterion_runs(c: &mut Criterion) -> Result<()> {
    for case in CASES {
        let (x, w, g) = inputs(case)?;
        let mut group = c.benchmark_group(format!("conv/{}", case.name));
        group.sample_size(10);
        group.warm_up_time(Duration::from_secs(1));
        group.measurement_time(Duration::from_secs(4));
        group.throughput(Throughput::Elements(case.flops() as u64));
        for (id, conv) in [("ours", conv2d as ConvFn), ("candle", conv2d_reference)] {
            group.bench_function(format!("{id}_fwd"), |b| {
                b.iter(|| forward(conv, case, &x, &w).expect("forward"))
            });
        }
        group.throughput(Throughput::Elements(3 * case.flops() as u64));
        for (id, conv) in [("ours", conv2d as ConvFn), ("candle", conv2d_reference)] {
            group.bench_function(format!("{id}_fwd_bwd"), |b| {
                b.iter(|| forward_backward(conv, case, &x, &w, &g).expect("backward"))
            });
        }
        group.finish();
    }
    Ok(())
}

/// Seconds per call of `f`, median of `n` calls.
fn time(n: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut t = Vec::with_capacity(n);
    for _ in 0..n {
        let start = Instant::now();
        f()?;
        t.push(start.elapsed().as_secs_f64());
    }
    Ok(median(t))
}

/// Two 1024² f32 matrices: candle's `matmul` of them is the sgemm ceiling convolutions aim at.
fn sgemm_operands() -> Result<(Tensor, Tensor)> {
    let a = pseudo_random((1024, 1024), 4, DType::F32, &Device::Cpu)?;
    let b = pseudo_random((1024, 1024), 5, DType::F32, &Device::Cpu)?;
    a.matmul(&b)?;
    Ok((a, b))
}

/// GFLOP/s of one `matmul` of the sgemm operands.
fn sgemm_gflops((a, b): &(Tensor, Tensor)) -> Result<f64> {
    let t = time(1, || {
        black_box(a.matmul(b)?);
        Ok(())
    })?;
    Ok(2.0 * 1024f64.powi(3) / t / 1e9)
}

fn summary() -> Result<()> {
    const ROUNDS: usize = 5;
    let sgemm = sgemm_operands()?;
    println!(
        "
{}; sgemm ceiling: 1024² f32 matmul, timed in every round",
        setup()
    );
    println!(
        "| case | pass | ours (ms) | candle (ms) | ours GFLOP/s | candle GFLOP/s | sgemm GFLOP/s | ours % of sgemm | candle ÷ ours |"
    );
    println!(
        "|------|------|----------:|------------:|-------------:|---------------:|--------------:|----------------:|--------------:|"
    );
    for case in CASES {
        let (x, w, g) = inputs(case)?;
        for (pass, flops) in [("fwd", case.flops()), ("fwd+bwd", 3.0 * case.flops())] {
            let run = |conv: ConvFn| -> Result<()> {
                if pass == "fwd" {
                    forward(conv, case, &x, &w)
                } else {
                    forward_backward(conv, case, &x, &w, &g)
                }
            };
            run(conv2d)?;
            run(conv2d_reference)?;
            let (mut ours, mut theirs, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
            let mut ceiling = Vec::new();
            for round in 0..ROUNDS {
                ceiling.push(sgemm_gflops(&sgemm)?);
                let (o, c) = alternate(
                    round,
                    || time(1, || run(conv2d)),
                    || time(1, || run(conv2d_reference)),
                )?;
                ours.push(o);
                theirs.push(c);
                ratios.push(c / o);
            }
            let (o, c, ceiling) = (median(ours), median(theirs), median(ceiling));
            println!(
                "| `{}` | {pass} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.0} % | {:.2}× |",
                case.name,
                o * 1e3,
                c * 1e3,
                flops / o / 1e9,
                flops / c / 1e9,
                ceiling,
                100.0 * flops / o / 1e9 / ceiling,
                median(ratios)
            );
        }
    }
    Ok(())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    // `--summary-only`: skip criterion, print the paired table alone.
    if !args.iter().any(|a| a == "--summary-only") {
        let mut c = Criterion::default().configure_from_args();
        criterion_runs(&mut c)?;
        c.final_summary();
    }
    summary()
}
