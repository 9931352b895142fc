//! How photomat's binaries use the CPU's threads: candle's element-wise ops run on the
//! calling thread, the heavy ops (GEMM, this crate's kernels) on rayon's pool.
//!
//! candle 0.11 runs its element-wise ops on a barrier pool of its own (`CANDLE_NUM_THREADS`
//! threads, by default one per core) whose idle workers spin 25 000 times before they park,
//! and whose caller spins until every worker has finished its share. On a machine with
//! nothing else running that costs nothing; with one other busy process on the 2-core build
//! machine, a worker that the OS has descheduled keeps the caller spinning for a whole time
//! slice at every op: 82 % of a photo capture's profile was those two spin loops, and the
//! capture took 5–6× as long as with one candle thread. One candle thread was as fast as
//! the default on the idle machine for every measured step (`docs/benchmarks.md`, "candle's
//! spinning element-wise pool"), because the time is in GEMMs and fused kernels, which keep
//! `RAYON_NUM_THREADS` threads.

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
