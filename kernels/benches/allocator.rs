//! System allocator vs mimalloc on candle element-wise backward passes, in one process.
//!
//! Run (docs/benchmarks/threads-and-allocator.md, "Global allocator", records the numbers):
//!
//! ```text
//! cargo bench -p photomat-kernels --features mimalloc --bench allocator
//! RAYON_NUM_THREADS=1 cargo bench -p photomat-kernels --features mimalloc --bench allocator
//! ```
//!
//! The process allocator is fixed at link time, so this bench installs a *switching*
//! allocator: each block is served by glibc's malloc or by mimalloc according to a flag, and
//! a one-byte tag in front of the block sends its `free` to the allocator that served it
//! (16 bytes of header per block; `realloc` is alloc + copy + free). The two allocators are
//! timed in alternating order, round after round, on the same inputs, so machine load hits
//! both alike; the bench prints the median time per pass and the median of the per-round
//! ratios system ÷ mimalloc.
//!
//! Workload (StyleGAN2's activation path, `docs/neural-models.md`, "Relightable generator G", as
//! plain candle ops): for a Var x and constant bias b, `y = √2 · max(x + b, 0.2·(x + b))`,
//! loss `Σ y²`, then `loss.backward()`: ≈ 15 element-wise ops of the input's size, each
//! allocating its output.

mod common;
use common::{alternate, median};

use std::alloc::{GlobalAlloc, Layout, System};
use std::hint::black_box;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use candle_core::{DType, Device, Result, Tensor, Var};
use mimalloc::MiMalloc;
use photomat_core::rng::pseudo_random;

/// Serve new blocks from mimalloc (true) or the system allocator (false).
static USE_MIMALLOC: AtomicBool = AtomicBool::new(false);

/// Room for the tag in front of each block; a multiple of every alignment ≤ 16.
const HEADER: usize = 16;

struct Switching;

impl Switching {
    /// The layout actually requested from the inner allocator, and the offset of the user
    /// block within it (≥ 1 byte for the tag, keeping the user alignment).
    fn inner(layout: Layout) -> (Layout, usize) {
        let pad = layout.align().max(HEADER);
        let inner = Layout::from_size_align(layout.size() + pad, pad).expect("layout overflow");
        (inner, pad)
    }

    unsafe fn tagged(&self, layout: Layout, zeroed: bool) -> *mut u8 {
        let (inner, pad) = Self::inner(layout);
        let mi = USE_MIMALLOC.load(Ordering::Relaxed);
        // SAFETY: `inner` has a non-zero size (it includes the header).
        let base = unsafe {
            match (mi, zeroed) {
                (true, false) => MiMalloc.alloc(inner),
                (true, true) => MiMalloc.alloc_zeroed(inner),
                (false, false) => System.alloc(inner),
                (false, true) => System.alloc_zeroed(inner),
            }
        };
        if base.is_null() {
            return base;
        }
        // SAFETY: `pad` ≥ 16 bytes lie in front of the user block inside the allocation.
        unsafe {
            let user = base.add(pad);
            *user.sub(1) = u8::from(mi);
            user
        }
    }
}

// SAFETY: every block is freed by the allocator that served it (the tag), with the layout it
// was served with (`Switching::inner` is deterministic in the user layout).
unsafe impl GlobalAlloc for Switching {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        unsafe { self.tagged(layout, false) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        unsafe { self.tagged(layout, true) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        let (inner, pad) = Self::inner(layout);
        // SAFETY: `ptr` came from `tagged` with this layout, so the tag and base are valid.
        unsafe {
            let mi = *ptr.sub(1) == 1;
            let base = ptr.sub(pad);
            if mi {
                MiMalloc.dealloc(base, inner)
            } else {
                System.dealloc(base, inner)
            }
        }
    }
}

#[global_allocator]
static GLOBAL: Switching = Switching;

/// One forward + backward pass of the module docs' workload.
fn pass(x: &Var, bias: &Tensor) -> Result<()> {
    let z = x.as_tensor().broadcast_add(bias)?;
    let y = (z.maximum(&(&z * 0.2)?)? * std::f64::consts::SQRT_2)?;
    let grads = y.sqr()?.sum_all()?.backward()?;
    black_box(grads.get(x.as_tensor()).expect("x has a gradient"));
    Ok(())
}

fn main() -> Result<()> {
    const ROUNDS: usize = 7;
    const PASSES: usize = 5;
    println!(
        "threads: candle/rayon {} (RAYON_NUM_THREADS={:?}, CANDLE_NUM_THREADS={:?})",
        photomat_kernels::alloc::thread_count(),
        std::env::var("RAYON_NUM_THREADS").ok(),
        std::env::var("CANDLE_NUM_THREADS").ok()
    );
    println!("| shape | elements | system (ms) | mimalloc (ms) | system ÷ mimalloc |");
    println!("|-------|---------:|------------:|--------------:|------------------:|");
    for shape in [(4, 64, 128, 128), (4, 32, 64, 64), (4, 128, 32, 32)] {
        let (b, c, h, w) = shape;
        let x = Var::from_tensor(&pseudo_random(shape, 1, DType::F32, &Device::Cpu)?)?;
        let bias = pseudo_random((1, c, 1, 1), 2, DType::F32, &Device::Cpu)?;
        pass(&x, &bias)?; // warm-up: thread pools, page tables
        let (mut sys, mut mi, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
        for round in 0..ROUNDS {
            let time = |use_mi: bool| -> Result<f64> {
                USE_MIMALLOC.store(use_mi, Ordering::Relaxed);
                pass(&x, &bias)?; // warm this allocator's free lists
                let mut t = Vec::with_capacity(PASSES);
                for _ in 0..PASSES {
                    let start = Instant::now();
                    pass(&x, &bias)?;
                    t.push(start.elapsed().as_secs_f64() * 1e3);
                }
                Ok(median(t))
            };
            let (s, m) = alternate(round, || time(false), || time(true))?;
            sys.push(s);
            mi.push(m);
            ratios.push(s / m);
        }
        USE_MIMALLOC.store(false, Ordering::Relaxed);
        println!(
            "| ({b}, {c}, {h}, {w}) | {} | {:.2} | {:.2} | {:.2}× (rounds {:.2}–{:.2}) |",
            b * c * h * w,
            median(sys),
            median(mi),
            median(ratios.clone()),
            ratios.iter().copied().fold(f64::INFINITY, f64::min),
            ratios.iter().copied().fold(0.0, f64::max),
        );
    }
    Ok(())
}
