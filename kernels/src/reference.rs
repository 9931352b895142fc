//! A per-thread switch that sends every op of this crate to its candle reference composition.
//!
//! Each op here has a reference written with candle's own ops (e.g. [`crate::conv2d_reference`]:
//! `narrow` + `cat` padding and candle's `conv2d`), which is also its path on other devices.
//! Inside [`with_reference_ops`] the ops take that path on the CPU too, so that a caller can
//! build the *same* network twice — once on these kernels, once on plain candle — and compare
//! values and gradients (the generator's equivalence tests) or time both in one process
//! (`generator/examples/gan_timing.rs --baseline`).
//!
//! The switch is thread-local: it is read when an op is applied (the graph records which
//! implementation ran, so the backward pass follows the forward's choice), and tests running
//! in parallel threads do not see each other's setting. Work that rayon spreads over its pool
//! is dispatched from the calling thread, so the pool's threads never need the flag.

use std::cell::Cell;

thread_local! {
    static REFERENCE: Cell<bool> = const { Cell::new(false) };
}

/// Whether ops applied on this thread now take their candle reference path.
pub fn reference_ops() -> bool {
    REFERENCE.with(Cell::get)
}

/// Runs `f` with this crate's ops on their candle reference path on this thread, then
/// restores the previous setting (also when `f` panics).
pub fn with_reference_ops<R>(f: impl FnOnce() -> R) -> R {
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            REFERENCE.with(|r| r.set(self.0));
        }
    }
    let _restore = Restore(REFERENCE.with(|r| r.replace(true)));
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_switch_is_scoped_and_per_thread() {
        assert!(!reference_ops());
        with_reference_ops(|| {
            assert!(reference_ops());
            // Another thread keeps the default.
            assert!(!std::thread::spawn(reference_ops).join().expect("thread"));
            with_reference_ops(|| assert!(reference_ops()));
            assert!(reference_ops(), "a nested scope restores the outer setting");
        });
        assert!(!reference_ops());
        let caught = std::panic::catch_unwind(|| with_reference_ops(|| panic!("inside")));
        assert!(caught.is_err());
        assert!(!reference_ops(), "restored after a panic");
    }
}
