//! Paths recorded in run manifests (`train.json` of `photomat train-gan` and
//! `photomat train-estimator`): made absolute so a later `--resume` from another working
//! directory finds the same data set, GAN folder or weights file.

use std::path::{Path, PathBuf};

/// `path` made absolute (symbolic links resolved) when it exists; unchanged otherwise, so that
/// opening it later reports the missing file or folder by the name the user gave.
pub fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn existing_paths_become_absolute_and_missing_ones_stay() {
        let dir = tempfile::tempdir().unwrap();
        let resolved = absolute(dir.path());
        assert!(resolved.is_absolute());
        assert_eq!(resolved, std::fs::canonicalize(dir.path()).unwrap());
        let missing = Path::new("no/such/folder");
        assert_eq!(absolute(missing), missing);
    }
}
