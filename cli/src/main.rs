//! The `photomat` binary: the built-in plugins plus the command line of `photomat-cli`.
//!
//! It runs on mimalloc instead of the system allocator: candle allocates a buffer per op and
//! glibc's malloc makes those passes page-fault bound (`photomat_kernels::alloc`, measured in
//! docs/benchmarks.md), keeping freed pages mapped (`keep_freed_pages`). Threads: `RAYON_NUM_THREADS`, else one per physical core.

#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn main() -> std::process::ExitCode {
    photomat_kernels::alloc::keep_freed_pages();
    photomat_cli::run()
}
