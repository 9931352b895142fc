//! The global allocator and thread count that photomat's binaries run with.
//!
//! **Allocator.** candle 0.11 allocates a fresh output buffer for every op. With glibc's
//! malloc, buffers above the dynamic mmap threshold (≤ 32 MiB) are mapped and unmapped per
//! call or trimmed off the heap top, so element-wise passes spend much of their time in page
//! faults (`docs/benchmarks/brdf-eval.md`, "BRDF evaluation throughput"; `docs/candle-notes.md`,
//! "Speed"). mimalloc (Leijen, Zorn & de Moura, "Mimalloc: free list sharding in action", APLAS
//! 2019) keeps freed pages mapped and reuses them. Measured here on element-wise backward passes it
//! is faster by the ratios in `docs/benchmarks/threads-and-allocator.md` ("Global allocator"),
//! bench `kernels/benches/allocator.rs`.
//!
//! A library must not pick the process allocator, so this is an opt-in for binaries: enable
//! the `mimalloc` feature of `photomat-kernels` and add
//!
//! ```text
//! #[global_allocator]
//! static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;
//! ```
//!
//! to the binary's `main.rs` (the `photomat` CLI does). Without the feature the system
//! allocator stays in place and every op still works.
//!
//! **Threads.** candle's CPU kernels and this crate share one default: the number of
//! *physical* cores (candle's `get_num_threads`), overridden by `RAYON_NUM_THREADS` (and, for
//! candle's element-wise pool only, `CANDLE_NUM_THREADS`). [`thread_count`] reports it. Keep
//! the default on a dedicated machine; on a machine shared with other jobs, set
//! `RAYON_NUM_THREADS` to the cores you may use: candle's element-wise pool spin-waits, so
//! more threads than free cores is slower than fewer (`docs/benchmarks/threads-and-allocator.md`,
//! "Global allocator").

/// The fast global allocator for binaries: mimalloc (see the module docs).
#[cfg(feature = "mimalloc")]
pub use mimalloc::MiMalloc as FastAllocator;

/// Index of `mi_option_purge_delay` in the `mi_option_e` enum of `mimalloc.h` (15 in both v2
/// and v3; libmimalloc-sys 0.1.49 builds v3 by default; the default-value test guards it).
#[cfg(feature = "mimalloc")]
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Tells mimalloc never to return freed pages to the OS. By default it purges them a second
/// after they are freed (v3's default delay), and candle's next op faults them back in, zero-filled by the kernel: 29 % of
/// a one-thread G step was `clear_page_erms`, and no purging cut the step's page faults from
/// 37 254 to 1 085 and its CPU time by 27 % (`docs/benchmarks/pytorch.md`, "photomat vs PyTorch
/// CPU, whole steps and ops"). The price is a resident size that stays at the peak, which training
/// processes reach anyway. Call it first thing in `main` of a binary that uses [`FastAllocator`].
#[cfg(feature = "mimalloc")]
pub fn keep_freed_pages() {
    // SAFETY: mi_option_set only stores an integer in mimalloc's option table.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) }
}

/// A buffer of `len` elements for an op's output that the op writes whole before anything
/// reads it: allocated without the zero-fill that `vec![0; len]` pays for. With mimalloc
/// keeping freed pages ([`keep_freed_pages`]) that fill was a memset of every output, 8–9 % of
/// a training step's samples (`docs/benchmarks/fused-ops.md`, "Outputs without a zero-fill").
/// candle's own CPU ops get their outputs the same way (`alloc_uninit` of its CPU device). Builds
/// with debug assertions (the test profile) fill the buffer with NaN instead, so that an element an
/// op forgets to write fails the equivalence tests rather than reading stale memory.
///
/// # Safety
/// The caller writes every element before reading any, and `T` is f32 or f64 (checked in
/// debug builds): `Copy`, nothing to drop. Strictly, `Vec::set_len` asks for initialised
/// elements and these are not until the caller writes them; this is the same contract as
/// candle's `alloc_uninit`, kept sound in practice by no element being read before it is
/// written (which the NaN fill of debug builds lets the equivalence tests check).
pub(crate) unsafe fn output_buffer<T: candle_core::WithDType>(len: usize) -> Vec<T> {
    debug_assert!(
        matches!(T::DTYPE, candle_core::DType::F32 | candle_core::DType::F64),
        "output_buffer is for f32 and f64 outputs, got {:?}",
        T::DTYPE
    );
    if cfg!(debug_assertions) {
        return vec![T::from_f64(f64::NAN); len];
    }
    let mut v = Vec::with_capacity(len);
    // SAFETY: capacity `len` was just reserved; the contract above makes the caller write the
    // elements before any is read.
    #[allow(clippy::uninit_vec)]
    unsafe {
        v.set_len(len)
    };
    v
}

/// Threads the kernels of this crate and candle's CPU ops use: `RAYON_NUM_THREADS` when set
/// to a positive integer, else the number of physical cores (candle's rule).
pub fn thread_count() -> usize {
    candle_core::utils::get_num_threads()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_count_is_positive_and_follows_rayon_num_threads() {
        let n = thread_count();
        assert!(n >= 1);
        match std::env::var("RAYON_NUM_THREADS")
            .ok()
            .and_then(|s| s.parse::<usize>().ok())
        {
            Some(t) if t > 0 => assert_eq!(n, t),
            _ => assert!(n <= std::thread::available_parallelism().map_or(n, |p| p.get())),
        }
    }

    #[cfg(feature = "mimalloc")]
    #[test]
    fn keep_freed_pages_sets_mimallocs_purge_delay() {
        // SAFETY: reads an integer from mimalloc's option table.
        let get = || unsafe { libmimalloc_sys::mi_option_get(MI_OPTION_PURGE_DELAY) };
        // v3's default purge_delay is 1000 ms (options.c): a wrong index reads another option.
        assert_eq!(get(), 1000);
        keep_freed_pages();
        assert_eq!(get(), -1);
    }
}
