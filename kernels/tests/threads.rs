//! `run_candle_elementwise_inline` and `fix_rayon_thread_count` set their thread counts only
//! when the user has not. One test in its own binary: it edits the process environment,
//! which no other test thread may read at the same time.

use photomat_kernels::threads::{
    CANDLE_THREADS_VAR, RAYON_THREADS_VAR, fix_rayon_thread_count, run_candle_elementwise_inline,
};

#[test]
fn thread_counts_are_set_only_where_the_user_chose_none() {
    // SAFETY (every environment edit below): the only test of this binary; nothing else reads
    // the environment meanwhile.
    unsafe { std::env::remove_var(CANDLE_THREADS_VAR) };
    assert!(unsafe { run_candle_elementwise_inline() });
    assert_eq!(std::env::var(CANDLE_THREADS_VAR).as_deref(), Ok("1"));
    unsafe { std::env::set_var(CANDLE_THREADS_VAR, "3") };
    assert!(!unsafe { run_candle_elementwise_inline() });
    assert_eq!(std::env::var(CANDLE_THREADS_VAR).as_deref(), Ok("3"));

    unsafe { std::env::remove_var(RAYON_THREADS_VAR) };
    let count = unsafe { fix_rayon_thread_count() }.expect("written when unset");
    assert!(count >= 1);
    assert_eq!(std::env::var(RAYON_THREADS_VAR), Ok(count.to_string()));
    unsafe { std::env::set_var(RAYON_THREADS_VAR, "5") };
    assert_eq!(unsafe { fix_rayon_thread_count() }, None);
    assert_eq!(std::env::var(RAYON_THREADS_VAR).as_deref(), Ok("5"));
}
