//! The columns of a GAN run's `log.csv`, one row per training step: [`LOG_HEADER`]; empty
//! cells where a value was not computed that step (R1 every 16 steps, SWD every `--swd-every` steps, path length every 4 steps when on,
//! `light_gap` when the light-mismatch term is off; `skipped` lists the phases whose update a
//! non-finite value skipped, `;`-separated). `lr` is the base learning rate of the step, which
//! a resume may change. Logs of runs from before the later columns existed keep their shorter
//! rows under the longer header.
//!
//! The file itself, and dropping the rows after the checkpoint when a run resumes, is
//! [`photomat_train::RunLog`]'s.

/// The header line.
pub const LOG_HEADER: &str = "step,kimg,loss_g,loss_d,real_logit,fake_logit,logit_gap,r1,seconds,swd,\
path_length,light_gap,lr,skipped";

/// One row: the state after step `step` (steps done, 1-based).
#[derive(Debug, Clone, PartialEq)]
pub struct LogRow {
    /// Steps done.
    pub step: u64,
    /// Thousands of real images shown.
    pub kimg: f64,
    /// G's loss.
    pub loss_g: f64,
    /// D's loss.
    pub loss_d: f64,
    /// Mean logit on reals.
    pub real_logit: f64,
    /// Mean logit on fakes.
    pub fake_logit: f64,
    /// Mean logit on reals under mismatched lights, when the light-mismatch term is on; the
    /// `light_gap` column is `real_logit` minus it (how much D checks the light).
    pub mismatch_logit: Option<f64>,
    /// R1 penalty, on R1 steps.
    pub r1: Option<f64>,
    /// Wall-clock seconds of the step.
    pub seconds: f64,
    /// Sliced Wasserstein distance, when computed.
    pub swd: Option<f64>,
    /// Mean path length, on path-length steps.
    pub path_length: Option<f64>,
    /// Base learning rate of the step.
    pub lr: f64,
    /// Why phases of the step skipped their update (e.g. `D loss is NaN`).
    pub skipped: Vec<String>,
}

impl LogRow {
    /// The CSV line (no newline).
    pub fn line(&self) -> String {
        let opt = |v: Option<f64>| v.map(|v| format!("{v}")).unwrap_or_default();
        format!(
            "{},{:.3},{},{},{},{},{},{},{:.3},{},{},{},{},{}",
            self.step,
            self.kimg,
            self.loss_g,
            self.loss_d,
            self.real_logit,
            self.fake_logit,
            self.real_logit - self.fake_logit,
            opt(self.r1),
            self.seconds,
            opt(self.swd),
            opt(self.path_length),
            opt(self.mismatch_logit.map(|m| self.real_logit - m)),
            self.lr,
            // Commas would split the cell.
            self.skipped.join(";").replace(',', ";")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(step: u64) -> LogRow {
        LogRow {
            step,
            kimg: step as f64 * 0.004,
            loss_g: 0.7,
            loss_d: 1.3,
            real_logit: 0.5,
            fake_logit: -0.25,
            r1: step.is_multiple_of(2).then_some(0.01),
            seconds: 1.5,
            swd: None,
            mismatch_logit: None,
            path_length: None,
            lr: 0.0025,
            skipped: if step == 2 {
                vec!["D loss is NaN".into(), "R1 gradient is not finite".into()]
            } else {
                Vec::new()
            },
        }
    }

    #[test]
    fn rows_fill_every_column_and_leave_uncomputed_cells_empty() {
        let lines: Vec<String> = (1..=2).map(|s| row(s).line()).collect();
        assert!(
            lines[0].starts_with("1,0.004,0.7,1.3,0.5,-0.25,0.75,,1.500,"),
            "{lines:?}"
        );
        assert!(
            lines[1].ends_with(",0.0025,D loss is NaN;R1 gradient is not finite"),
            "{lines:?}"
        );
        assert_eq!(lines[1].split(',').nth(7), Some("0.01"));
        for line in &lines {
            assert_eq!(line.split(',').count(), LOG_HEADER.split(',').count());
        }
    }
}
