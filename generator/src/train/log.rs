//! The run's `log.csv`: one row per training step, appended as the run goes (a row is on disk
//! as soon as its step ends), so a plot of a live run or of an interrupted one is always
//! possible. Columns: [`LOG_HEADER`]; empty cells where a value was not computed that step
//! (R1 every 16 steps, SWD every `--swd-every` steps, path length every 4 steps when on,
//! `light_gap` when the light-mismatch term is off; `skipped` lists the phases whose update a
//! non-finite value skipped, `;`-separated). `lr` is the base learning rate of the step, which
//! a resume may change. Logs of runs from before the later columns existed keep their shorter
//! rows under the longer header.
//!
//! Resuming at S steps drops the rows of steps after S (written after the checkpoint the run
//! resumes from), so the log reads as one uninterrupted run.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use candle_core::Result;
use photomat_core::image_io::write_atomic;

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

/// An open `log.csv`.
pub struct TrainLog {
    path: PathBuf,
    file: File,
}

fn io_error(path: &Path, e: impl std::fmt::Display) -> candle_core::Error {
    candle_core::Error::msg(format!("{}: {e}", path.display()))
}

impl TrainLog {
    /// A new log at `path` (replacing any), header only.
    pub fn create(path: &Path) -> Result<Self> {
        Self::rewrite(path, &[])
    }

    /// Reopens `path` for a run resumed at `steps_done` steps: rows of later steps are
    /// dropped; a missing log is started afresh.
    pub fn resume(path: &Path, steps_done: u64) -> Result<Self> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => return Err(io_error(path, e)),
        };
        let kept: Vec<&str> = text
            .lines()
            .skip(1)
            .filter(|l| {
                l.split(',')
                    .next()
                    .and_then(|s| s.parse::<u64>().ok())
                    .is_some_and(|s| s <= steps_done)
            })
            .collect();
        Self::rewrite(path, &kept)
    }

    fn rewrite(path: &Path, rows: &[&str]) -> Result<Self> {
        let mut text = String::from(LOG_HEADER);
        text.push('\n');
        for r in rows {
            text.push_str(r);
            text.push('\n');
        }
        write_atomic(path, text.as_bytes()).map_err(candle_core::Error::wrap)?;
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| io_error(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Appends one row and flushes it to the file.
    pub fn append(&mut self, row: &LogRow) -> Result<()> {
        writeln!(self.file, "{}", row.line())
            .and_then(|()| self.file.flush())
            .map_err(|e| io_error(&self.path, e))
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
    fn resume_drops_later_rows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.csv");
        let mut log = TrainLog::create(&path).unwrap();
        for s in 1..=5 {
            log.append(&row(s)).unwrap();
        }
        drop(log);
        let mut log = TrainLog::resume(&path, 3).unwrap();
        log.append(&row(4)).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], LOG_HEADER);
        assert_eq!(lines.len(), 5, "{text}");
        assert!(
            lines[4].starts_with("4,0.016,0.7,1.3,0.5,-0.25,0.75,0.01,1.500,"),
            "{text}"
        );
        assert_eq!(lines[3].split(',').nth(7), Some(""));
        assert!(
            lines[2].ends_with(",0.0025,D loss is NaN;R1 gradient is not finite"),
            "{text}"
        );
        assert_eq!(lines[0].split(',').count(), lines[1].split(',').count());
    }
}
