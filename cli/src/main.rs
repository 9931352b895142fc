//! The `photomat` binary: the built-in plugins plus the command line of `photomat-cli`.
//!
//! It runs on mimalloc instead of the system allocator: candle allocates a buffer per op and
//! glibc's malloc makes those passes page-fault bound (`photomat_kernels::alloc`, measured in
//! docs/benchmarks/threads-and-allocator.md, "Global allocator"), keeping freed pages mapped
//! (`keep_freed_pages`). Threads: `RAYON_NUM_THREADS`, else one per physical core, for GEMMs and
//! the fused kernels; candle's element-wise ops run on the calling thread unless
//! `CANDLE_NUM_THREADS` says otherwise (`photomat_kernels::threads`: candle's spinning pool slows
//! every step on a busy machine).

#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn main() -> std::process::ExitCode {
    // SAFETY: nothing has started a thread yet: this is the first statement of `main`.
    unsafe { photomat_kernels::threads::set_up_like_the_binary() };
    photomat_kernels::alloc::keep_freed_pages();
    photomat_cli::run()
}
