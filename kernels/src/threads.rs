//! How photomat's binaries use the CPU's threads: candle's element-wise ops run on the
//! calling thread, the heavy ops (GEMM, this crate's kernels) on rayon's pool.
//!
//! candle 0.11 runs its element-wise ops on a barrier pool of its own (`CANDLE_NUM_THREADS`
//! threads, by default one per core) whose idle workers spin 25 000 times before they park,
//! and whose caller spins until every worker has finished its share. On a machine with
//! nothing else running that costs nothing; with one other busy process on the 2-core build
//! machine, a worker that the OS has descheduled keeps the caller spinning for a whole time
//! slice at every op: 82 % of a photo capture's profile was those two spin loops, and the
//! capture took 5–6× as long as with one candle thread. On the idle machine one candle
//! thread costs 0–7 % per step (`docs/benchmarks/threads-and-allocator.md`, "candle's spinning
//! element-wise pool" and "`train-gan` step time"), because the time is in GEMMs and fused kernels,
//! which keep `RAYON_NUM_THREADS` threads, which [`fix_rayon_thread_count`] writes down once; a run
//! that has the machine to itself may set `CANDLE_NUM_THREADS=2`.

/// Elements from which this crate's element-wise passes split over rayon tasks of this size;
/// smaller tensors run on the calling thread. candle splits its own element-wise ops from the
/// same size (65,536 elements, one 256² plane).
pub(crate) const ELEMENTWISE_CHUNK: usize = 1 << 16;

/// The variable rayon's global pool and candle's GEMMs read for their thread count.
pub const RAYON_THREADS_VAR: &str = "RAYON_NUM_THREADS";

/// The environment variable candle reads, once, when it starts its element-wise pool.
pub const CANDLE_THREADS_VAR: &str = "CANDLE_NUM_THREADS";

/// Makes candle run its element-wise ops on the calling thread (`CANDLE_NUM_THREADS=1`)
/// unless the user has set `CANDLE_NUM_THREADS`; returns whether it set it. Call it first thing
/// in `main`, before candle runs any op (its pool reads the variable once).
///
/// # Safety
/// It edits the process environment, which is only sound while no other thread can read or
/// write it: call it before the program starts any thread.
pub unsafe fn run_candle_elementwise_inline() -> bool {
    if std::env::var_os(CANDLE_THREADS_VAR).is_some() {
        return false;
    }
    // SAFETY: the caller guarantees that no other thread exists yet.
    unsafe { std::env::set_var(CANDLE_THREADS_VAR, "1") };
    true
}

/// Writes candle's default thread count (the physical cores) into `RAYON_NUM_THREADS` unless
/// the user has set it; returns the count it wrote. Without the variable candle counts the
/// physical cores by reading `/proc/cpuinfo` at every matrix product (0.9 % of a GAN step's
/// profile, in the kernel's `show_cpuinfo`); with it, rayon's pool and candle's GEMMs also
/// agree on one count. Call it first thing in `main`, like [`run_candle_elementwise_inline`].
///
/// # Safety
/// As for [`run_candle_elementwise_inline`]: no other thread may exist yet.
pub unsafe fn fix_rayon_thread_count() -> Option<usize> {
    if std::env::var_os(RAYON_THREADS_VAR).is_some() {
        return None;
    }
    let count = candle_core::utils::get_num_threads();
    // SAFETY: the caller guarantees that no other thread exists yet.
    unsafe { std::env::set_var(RAYON_THREADS_VAR, count.to_string()) };
    Some(count)
}

/// The binary's thread set-up, for programs (examples, benchmarks) whose timings should be
/// the `photomat` binary's: [`run_candle_elementwise_inline`], then
/// [`fix_rayon_thread_count`].
///
/// # Safety
/// As for [`run_candle_elementwise_inline`]: no other thread may exist yet.
pub unsafe fn set_up_like_the_binary() {
    // SAFETY: the caller guarantees that no other thread exists yet.
    unsafe {
        run_candle_elementwise_inline();
        fix_rayon_thread_count();
    }
}
