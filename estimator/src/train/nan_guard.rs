//! The NaN guard of the estimator's training: a step whose loss is not finite is skipped (no
//! optimiser update, so one bad batch cannot poison E's weights or Adam's moments), and
//! training stops with an error naming the step and the non-finite terms after a number of
//! consecutive bad steps (something is broken, not unlucky).

use photomat_core::{Error, Result};

/// Counts consecutive non-finite steps.
#[derive(Debug, Clone)]
pub struct NanGuard {
    limit: u32,
    streak: u32,
}

impl NanGuard {
    /// A guard that fails at the `limit`-th consecutive non-finite step (`limit` ≥ 1).
    pub fn new(limit: u32) -> Self {
        Self {
            limit: limit.max(1),
            streak: 0,
        }
    }

    /// Checks the named loss terms of (1-based) step `step`: `Ok(true)` to apply the update,
    /// `Ok(false)` to skip it, an error once the limit of consecutive skips is reached.
    pub fn check(&mut self, step: u64, terms: &[(&str, f64)]) -> Result<bool> {
        let bad: Vec<String> = terms
            .iter()
            .filter(|(_, v)| !v.is_finite())
            .map(|(n, v)| format!("{n} = {v}"))
            .collect();
        if bad.is_empty() {
            self.streak = 0;
            return Ok(true);
        }
        self.streak += 1;
        if self.streak >= self.limit {
            return Err(Error::Invalid(format!(
                "training stopped at step {step}: the loss was not finite for {} consecutive \
                 steps ({}); lower the learning rate or check the GAN model",
                self.streak,
                bad.join(", ")
            )));
        }
        Ok(false)
    }

    /// Consecutive non-finite steps so far.
    pub fn streak(&self) -> u32 {
        self.streak
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skips_then_stops_naming_the_loss() {
        let mut guard = NanGuard::new(3);
        assert!(guard.check(1, &[("l1", 0.5), ("gram", 0.1)]).unwrap());
        assert!(!guard.check(2, &[("l1", 0.5), ("gram", f64::NAN)]).unwrap());
        assert!(
            !guard
                .check(3, &[("l1", f64::INFINITY), ("gram", 0.1)])
                .unwrap()
        );
        let err = guard
            .check(4, &[("l1", 0.5), ("gram", f64::NAN)])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("step 4") && err.contains("gram = NaN"),
            "{err}"
        );
        // A finite step resets the streak.
        let mut guard = NanGuard::new(2);
        assert!(!guard.check(1, &[("gram", f64::NAN)]).unwrap());
        assert!(guard.check(2, &[("gram", 1.0)]).unwrap());
        assert!(!guard.check(3, &[("gram", f64::NAN)]).unwrap());
        assert_eq!(guard.streak(), 1);
    }
}
