//! `run_candle_elementwise_inline` sets candle's thread count only when the user has not. One
//! test in its own binary: it edits the process environment, which no other test thread may
//! read at the same time.

use photomat_kernels::threads::{CANDLE_THREADS_VAR, run_candle_elementwise_inline};

#[test]
fn candle_runs_inline_unless_the_user_chose_a_thread_count() {
    // SAFETY: the only test of this binary; nothing else reads the environment meanwhile.
    unsafe { std::env::remove_var(CANDLE_THREADS_VAR) };
    assert!(unsafe { run_candle_elementwise_inline() });
    assert_eq!(std::env::var(CANDLE_THREADS_VAR).as_deref(), Ok("1"));

    // SAFETY: as above.
    unsafe { std::env::set_var(CANDLE_THREADS_VAR, "3") };
    assert!(!unsafe { run_candle_elementwise_inline() });
    assert_eq!(std::env::var(CANDLE_THREADS_VAR).as_deref(), Ok("3"));
}
