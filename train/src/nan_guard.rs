//! Protection against non-finite updates: a phase (G's step, D's step, D's R1 step) whose loss
//! or gradient is NaN or infinite is skipped — the weights and the optimiser's moments stay as
//! they were — and reported; after `limit` consecutive steps with a skipped phase, training
//! stops with an error naming the step and the loss (a diverged run, not a glitch).

use candle_core::backprop::GradStore;
use candle_core::{Result, Var, bail};

/// Whether every gradient of `vars` present in `grads` is finite (the sum of each gradient
/// propagates NaN and ±∞; a finite gradient's sum cannot overflow at these sizes).
pub fn gradients_finite<'a>(
    grads: &GradStore,
    vars: impl IntoIterator<Item = &'a Var>,
) -> Result<bool> {
    for v in vars {
        if let Some(g) = grads.get(v.as_tensor()) {
            let s = g
                .sum_all()?
                .to_dtype(candle_core::DType::F64)?
                .to_scalar::<f64>()?;
            if !s.is_finite() {
                return Ok(false);
            }
        }
    }
    Ok(true)
}

/// Counts skipped phases per step and consecutive steps with a skip.
#[derive(Debug, Clone)]
pub struct NanGuard {
    limit: usize,
    streak: usize,
    skipped_this_step: Vec<String>,
    total: u64,
}

impl NanGuard {
    /// A guard that stops after `limit` consecutive steps with a skipped phase.
    pub fn new(limit: usize) -> Self {
        Self {
            // A limit of 0 would stop before any skip could be reported; 1 is the strictest.
            limit: limit.max(1),
            streak: 0,
            skipped_this_step: Vec::new(),
            total: 0,
        }
    }

    /// Whether the update of `phase` may be applied: false (and the skip recorded) when its
    /// loss value is not finite or `grads_ok` is false.
    pub fn allow(&mut self, phase: &str, loss: f64, grads_ok: bool) -> bool {
        if loss.is_finite() && grads_ok {
            return true;
        }
        let what = if loss.is_finite() {
            "gradient is non-finite".to_string()
        } else {
            format!("loss is {loss}")
        };
        self.skipped_this_step.push(format!("{phase} {what}"));
        self.total += 1;
        false
    }

    /// Closes step number `step` (1-based, as in `log.csv`: the steps done once it ends):
    /// returns the skip messages of the step, or an error once `limit` consecutive steps had
    /// a skip.
    pub fn end_step(&mut self, step: u64) -> Result<Vec<String>> {
        let skipped = std::mem::take(&mut self.skipped_this_step);
        if skipped.is_empty() {
            self.streak = 0;
            return Ok(skipped);
        }
        self.streak += 1;
        if self.streak >= self.limit {
            bail!(
                "training stopped at step {step}: {} consecutive steps skipped because of \
                 non-finite values (last: {}); the run has diverged — resume from the last \
                 checkpoint with a lower --lr",
                self.streak,
                skipped.join(", ")
            );
        }
        Ok(skipped)
    }

    /// Consecutive steps with a skip so far (saved with the training state).
    pub fn streak(&self) -> usize {
        self.streak
    }

    /// Restores the streak of a resumed run.
    pub fn set_streak(&mut self, streak: usize) {
        self.streak = streak;
    }

    /// Phases skipped since this guard was made.
    pub fn total_skipped(&self) -> u64 {
        self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skips_and_stops_after_the_limit() {
        let mut g = NanGuard::new(3);
        assert!(g.allow("G", 0.5, true));
        assert!(g.end_step(0).unwrap().is_empty());
        assert!(!g.allow("D", f64::NAN, true));
        assert_eq!(g.end_step(1).unwrap(), ["D loss is NaN"]);
        assert!(!g.allow("D", 1.0, false));
        assert_eq!(g.end_step(2).unwrap(), ["D gradient is non-finite"]);
        // A clean step resets the streak.
        assert!(g.allow("D", 1.0, true));
        g.end_step(3).unwrap();
        assert_eq!(g.streak(), 0);
        for s in 4..6 {
            g.allow("R1", f64::INFINITY, true);
            g.end_step(s).unwrap();
        }
        g.allow("R1", f64::INFINITY, true);
        let err = g.end_step(6).unwrap_err().to_string();
        assert!(
            err.contains("step 6") && err.contains("R1 loss is inf"),
            "{err}"
        );
        assert_eq!(g.total_skipped(), 5);
    }
}
