//! A training run's folder, fresh or resumed: the check every trainer makes before it opens one
//! (docs/robustness.md, "Interrupted training"). A fresh run refuses a folder that already
//! holds a run's state (continue it with `--resume`, or choose another folder); a resume
//! needs one.

use std::path::Path;

use anyhow::bail;

/// Checks that the folder `run` holds the state file `state` (relative to it) exactly when
/// `resume`; `what` names the run in messages (`a GAN training run`).
pub fn check_run_folder(run: &Path, state: &str, resume: bool, what: &str) -> anyhow::Result<()> {
    let path = run.join(state);
    match (resume, path.exists()) {
        (true, false) => bail!(
            "cannot resume: {} does not exist (start the run without --resume)",
            path.display()
        ),
        (false, true) => bail!(
            "{} already holds {what}; continue it with --resume or choose another --out",
            run.display()
        ),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fresh_run_needs_an_empty_folder_and_a_resume_a_state() {
        let dir = tempfile::tempdir().unwrap();
        let err = check_run_folder(dir.path(), "state", true, "a run").unwrap_err();
        assert!(err.to_string().contains("cannot resume"), "{err}");
        check_run_folder(dir.path(), "state", false, "a run").unwrap();
        std::fs::write(dir.path().join("state"), b"").unwrap();
        let err = check_run_folder(dir.path(), "state", false, "a run").unwrap_err();
        assert!(
            err.to_string()
                .contains("already holds a run; continue it with --resume"),
            "{err}"
        );
        check_run_folder(dir.path(), "state", true, "a run").unwrap();
    }
}
