//! The global allocator and thread count that photomat's binaries run with.
//!
//! **Allocator.** candle 0.11 allocates a fresh output buffer for every op. With glibc's
//! malloc, buffers above the dynamic mmap threshold (≤ 32 MiB) are mapped and unmapped per
//! call or trimmed off the heap top, so element-wise passes spend much of their time in page
//! faults (`docs/benchmarks.md`, "BRDF evaluation throughput"; DESIGN §6). mimalloc
//! (Leijen, Zorn & de Moura, "Mimalloc: free list sharding in action", APLAS 2019) keeps
//! freed pages mapped and reuses them. Measured here on element-wise backward passes it is
//! faster by the ratios in `docs/benchmarks.md` ("Global allocator"), bench
//! `kernels/benches/allocator.rs`.
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
//! more threads than free cores is slower than fewer (`docs/benchmarks.md`).

/// The fast global allocator for binaries: mimalloc (see the module docs).
#[cfg(feature = "mimalloc")]
pub use mimalloc::MiMalloc as FastAllocator;

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
}
