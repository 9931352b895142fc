//! Helpers the crate's benches share: medians, and A/B pairs timed in alternating order so
//! that load from other jobs on the machine hits both sides alike.

/// The middle value (the upper one of the two middle values for an even count).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// `(a(), b())`, with `a` run first in even rounds and `b` first in odd ones.
pub fn alternate<T, E>(
    round: usize,
    mut a: impl FnMut() -> Result<T, E>,
    mut b: impl FnMut() -> Result<T, E>,
) -> Result<(T, T), E> {
    if round.is_multiple_of(2) {
        let first = a()?;
        Ok((first, b()?))
    } else {
        let second = b()?;
        Ok((a()?, second))
    }
}

/// The line a bench prints first: its thread count and global allocator (not the
/// allocator bench's, which switches allocators).
#[allow(dead_code)]
pub fn setup() -> String {
    let allocator = if cfg!(feature = "mimalloc") {
        "mimalloc"
    } else {
        "system"
    };
    format!(
        "threads: {}; allocator: {allocator}",
        photomat_kernels::alloc::thread_count()
    )
}
