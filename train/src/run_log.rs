//! A training run's `log.csv`: one row per step, appended and flushed as the run goes (a row is
//! on disk as soon as its step ends), so a live or interrupted run can always be plotted.
//!
//! Every trainer writes its rows through [`RunLog`]: the trainer owns its columns (a header
//! line and one text line per step whose first cell is the step number, counted from 1), the
//! log owns the file. Resuming at S steps keeps the rows of steps up to S and drops the later
//! ones, which were written after the checkpoint the run resumes from and are trained again, so
//! the log reads as one uninterrupted run (docs/robustness.md, "Interrupted training").

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use photomat_core::image_io::write_atomic;
use photomat_core::{Error, Result};

/// An open `log.csv`.
pub struct RunLog {
    path: PathBuf,
    file: File,
}

impl RunLog {
    /// A new log at `path` (replacing any) holding only `header`.
    pub fn create(path: &Path, header: &str) -> Result<Self> {
        Self::rewrite(path, header, "")
    }

    /// Reopens `path` for a run resumed at `steps_done` steps: the rows of later steps are
    /// dropped and the header is `header` (a log from before a trainer added columns keeps its
    /// shorter rows under the longer header); a missing log starts afresh.
    pub fn resume(path: &Path, header: &str, steps_done: u64) -> Result<Self> {
        let old = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
            Err(e) => return Err(Error::file(path, format!("cannot read the log: {e}"))),
        };
        Self::rewrite(path, header, &rows_up_to(&old, steps_done))
    }

    /// Writes `header` and `rows` (whole lines) atomically, then opens the file for appending.
    fn rewrite(path: &Path, header: &str, rows: &str) -> Result<Self> {
        write_atomic(path, format!("{header}\n{rows}").as_bytes())?;
        let file = OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| Error::file(path, format!("cannot open the log: {e}")))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Appends one row (`line` without its newline) and flushes it to the file.
    pub fn append(&mut self, line: &str) -> Result<()> {
        writeln!(self.file, "{line}")
            .and_then(|()| self.file.flush())
            .map_err(|e| Error::file(&self.path, format!("cannot append to the log: {e}")))
    }

    /// The log's file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// The data rows of the log text `old` (its header skipped) whose step, the first cell, is at
/// most `steps_done`, each ending in a newline.
fn rows_up_to(old: &str, steps_done: u64) -> String {
    let mut kept = String::new();
    for line in old.lines().skip(1) {
        let step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
        if step.is_some_and(|s| s <= steps_done) {
            kept.push_str(line);
            kept.push('\n');
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resuming_keeps_the_rows_up_to_the_checkpoint_under_the_new_header() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.csv");
        let mut log = RunLog::create(&path, "step,loss").unwrap();
        for step in 1..=5 {
            log.append(&format!("{step},0.{step}")).unwrap();
        }
        drop(log);
        let mut log = RunLog::resume(&path, "step,loss,lr", 3).unwrap();
        log.append("4,0.44,0.1").unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "step,loss,lr\n1,0.1\n2,0.2\n3,0.3\n4,0.44,0.1\n");
    }

    #[test]
    fn resuming_without_a_log_starts_one_and_a_bad_first_cell_is_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.csv");
        RunLog::resume(&path, "step,loss", 7).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "step,loss\n");
        std::fs::write(&path, "step,loss\n1,0.5\nnot a step,0.1\n9,0.2\n").unwrap();
        RunLog::resume(&path, "step,loss", 7).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "step,loss\n1,0.5\n"
        );
    }
}
