//! Protection against non-finite updates, shared by the GAN and the estimator trainers: an
//! update (a phase of a step: G's, D's, R1's; or the estimator's one step) whose loss or
//! gradient is NaN or infinite is skipped — the caller leaves the weights and the optimiser's
//! moments as they were, so one bad batch cannot poison them — and reported; after `limit`
//! consecutive steps with a skipped update, training stops with an error naming the step and
//! the non-finite loss (a diverged run, not a glitch).
//!
//! A step is reported as a list of skip messages: `"<phase> loss is NaN"` and
//! `"<phase> gradient is non-finite"` from [`NanGuard::allow`], `"<term> = <value>"` from
//! [`NanGuard::allow_terms`].

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

/// Counts skipped updates per step and consecutive steps with a skip.
#[derive(Debug, Clone)]
pub struct NanGuard {
    limit: usize,
    advice: String,
    streak: usize,
    skipped_this_step: Vec<String>,
    total: u64,
}

impl NanGuard {
    /// A guard that stops after `limit` consecutive steps with a skipped update; `advice`
    /// ends the error message (what the user should do about a diverged run).
    pub fn new(limit: usize, advice: impl Into<String>) -> Self {
        Self {
            // A limit of 0 would stop before any skip could be reported; 1 is the strictest.
            limit: limit.max(1),
            advice: advice.into(),
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
        self.skip(format!("{phase} {what}"));
        false
    }

    /// Whether an update whose loss is made of the named `terms` may be applied: false (and
    /// one skip recorded, naming every non-finite term as `name = value`) when any is not
    /// finite.
    pub fn allow_terms(&mut self, terms: &[(&str, f64)]) -> bool {
        let bad: Vec<String> = terms
            .iter()
            .filter(|(_, v)| !v.is_finite())
            .map(|(n, v)| format!("{n} = {v}"))
            .collect();
        if bad.is_empty() {
            return true;
        }
        self.skip(bad.join(", "));
        false
    }

    fn skip(&mut self, message: String) {
        self.skipped_this_step.push(message);
        self.total += 1;
    }

    /// Closes step number `step` (1-based: the steps done once it ends, as logs number them):
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
                 non-finite values (last: {}); {}",
                self.streak,
                skipped.join(", "),
                self.advice
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

    /// Updates skipped since this guard was made.
    pub fn total_skipped(&self) -> u64 {
        self.total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor};

    #[test]
    fn skips_and_stops_after_the_limit() {
        let mut g = NanGuard::new(3, "lower the learning rate");
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
            err.contains("step 6")
                && err.contains("R1 loss is inf")
                && err.contains("3 consecutive")
                && err.contains("inf); lower the learning rate"),
            "{err}"
        );
        assert_eq!(g.total_skipped(), 5);
    }

    #[test]
    fn terms_skip_then_stop_naming_the_loss() {
        let mut guard = NanGuard::new(3, "");
        assert!(guard.allow_terms(&[("l1", 0.5), ("gram", 0.1)]));
        assert!(guard.end_step(1).unwrap().is_empty());
        assert!(!guard.allow_terms(&[("l1", 0.5), ("gram", f64::NAN)]));
        assert_eq!(guard.end_step(2).unwrap(), ["gram = NaN"]);
        assert!(!guard.allow_terms(&[("l1", f64::INFINITY), ("gram", f64::NAN)]));
        assert_eq!(guard.end_step(3).unwrap(), ["l1 = inf, gram = NaN"]);
        assert!(!guard.allow_terms(&[("l1", 0.5), ("gram", f64::NAN)]));
        let err = guard.end_step(4).unwrap_err().to_string();
        assert!(
            err.contains("step 4") && err.contains("gram = NaN"),
            "{err}"
        );
        // A finite step resets the streak.
        let mut guard = NanGuard::new(2, "");
        assert!(!guard.allow_terms(&[("gram", f64::NAN)]));
        guard.end_step(1).unwrap();
        assert!(guard.allow_terms(&[("gram", 1.0)]));
        guard.end_step(2).unwrap();
        assert!(!guard.allow_terms(&[("gram", f64::NAN)]));
        guard.end_step(3).unwrap();
        assert_eq!(guard.streak(), 1);
    }

    #[test]
    fn gradients_finite_sees_nan_and_inf() -> Result<()> {
        let a = Var::new(&[1f32, 2.0], &Device::Cpu)?;
        let b = Var::new(&[3f32], &Device::Cpu)?;
        let finite = (a.as_tensor().sqr()?.sum_all()? + b.as_tensor().sum_all()?)?;
        assert!(gradients_finite(&finite.backward()?, [&a, &b])?);
        // d/da of a·∞ is ∞; b is untouched by this loss and has no gradient (not an error).
        let inf = Tensor::new(&[f32::INFINITY, 0.0], &Device::Cpu)?;
        let loss = a.as_tensor().mul(&inf)?.sum_all()?;
        assert!(!gradients_finite(&loss.backward()?, [&a, &b])?);
        Ok(())
    }
}
