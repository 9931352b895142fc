//! Output folders that one process writes at a time: an advisory lock on a hidden file in the
//! folder, held for as long as the [`FolderLock`] lives, and the clean-up of the temporary
//! files that a killed writer left behind (docs/robustness.md, "Output folders").
//!
//! Every command that writes a run, model or sample folder takes the lock first: a second
//! process on the same folder fails at once with an error naming the folder and the holder's
//! process id and command, instead of interleaving its files with the first one's. The lock
//! is the operating system's (`flock` on Unix, `LockFileEx` on Windows), so it is released when
//! the holder exits, however it exits; the lock file itself stays (removing it would let two
//! processes lock two different files of the same name).
//!
//! Once the lock is held no other photomat process writes into the folder, so the temporary
//! files of atomic writes found there ([`is_temporary_file`]) are garbage from a writer that
//! was killed mid-write: [`FolderLock::acquire`] removes them.
//!
//! A command whose result is one folder (a capture, samples, a study) writes it through
//! [`crate::output_folder::OutputFolder`], which locks its staging folder and refuses to mix
//! two results.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// The lock file's name inside a locked folder.
pub const LOCK_FILE: &str = ".photomat.lock";

/// The exclusive lock on an output folder; released when dropped (or when the process ends).
#[derive(Debug)]
pub struct FolderLock {
    dir: PathBuf,
    // Held open: closing the file releases the lock.
    _file: File,
    removed: Vec<PathBuf>,
}

impl FolderLock {
    /// Creates `dir` if needed and locks it for `command` (e.g. `photomat train-gan`, shown to
    /// a second process that finds the folder locked), then removes the temporary files that
    /// killed writers left in it. Errors name the folder and, when another process holds the
    /// lock, its process id and command.
    pub fn acquire(dir: &Path, command: &str) -> Result<Self> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::file(dir, format!("cannot create the folder: {e}")))?;
        let path = dir.join(LOCK_FILE);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| Error::file(&path, format!("cannot open the folder's lock file: {e}")))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(TryLockError::WouldBlock) => {
                let mut holder = String::new();
                // Best effort: the holder writes its line right after locking.
                let _ = file.read_to_string(&mut holder);
                let holder = holder.trim();
                let who = if holder.is_empty() {
                    "another process".to_string()
                } else {
                    format!("process {holder}")
                };
                return Err(Error::file(
                    dir,
                    format!(
                        "is in use by {who}; wait until it ends or choose another output folder"
                    ),
                ));
            }
            Err(TryLockError::Error(e)) => {
                return Err(Error::file(&path, format!("cannot lock the folder: {e}")));
            }
        }
        let line = format!("{} ({command})\n", std::process::id());
        file.set_len(0)
            .and_then(|()| file.seek(SeekFrom::Start(0)))
            .and_then(|_| file.write_all(line.as_bytes()))
            .and_then(|()| file.flush())
            .map_err(|e| Error::file(&path, format!("cannot write the lock file: {e}")))?;
        let removed = remove_temporary_files(dir)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            _file: file,
            removed,
        })
    }

    /// The locked folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The stale temporary files that [`Self::acquire`] removed.
    pub fn removed(&self) -> &[PathBuf] {
        &self.removed
    }
}

/// Whether `name` is a temporary file of an atomic write: photomat's own
/// `.NAME.PID-N.tmp` ([`crate::image_io::write_atomic`]) or the `.tmpXXXXXX` files of the
/// `tempfile` crate (which some dependencies' writers use).
pub fn is_temporary_file(name: &str) -> bool {
    let own = name.starts_with('.') && name.ends_with(".tmp") && name.len() > ".x.tmp".len();
    let tempfile = name.len() == ".tmp".len() + 6
        && name.starts_with(".tmp")
        && name[4..].chars().all(|c| c.is_ascii_alphanumeric());
    own || tempfile
}

/// Removes the temporary files directly inside `dir` and in its sub-folders (a run folder
/// writes into `samples/` and `panels/` too); returns what it removed.
fn remove_temporary_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut removed = Vec::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        let entries = std::fs::read_dir(&folder)
            .map_err(|e| Error::file(&folder, format!("cannot list the folder: {e}")))?;
        for entry in entries.flatten() {
            let path = entry.path();
            let Ok(kind) = entry.file_type() else {
                continue;
            };
            if kind.is_dir() {
                folders.push(path);
            } else if kind.is_file() && is_temporary_file(&entry.file_name().to_string_lossy()) {
                std::fs::remove_file(&path)
                    .map_err(|e| Error::file(&path, format!("cannot remove a stale file: {e}")))?;
                removed.push(path);
            }
        }
    }
    removed.sort();
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_fails_naming_the_holder_until_the_first_is_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run");
        let first = FolderLock::acquire(&run, "photomat train-gan").unwrap();
        let err = FolderLock::acquire(&run, "photomat sample")
            .unwrap_err()
            .to_string();
        assert!(err.contains(&run.display().to_string()), "{err}");
        assert!(
            err.contains(&format!(
                "process {} (photomat train-gan)",
                std::process::id()
            )),
            "{err}"
        );
        drop(first);
        let again = FolderLock::acquire(&run, "photomat sample").unwrap();
        assert_eq!(again.dir(), run);
    }

    #[test]
    fn acquiring_removes_stale_temporaries_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path();
        std::fs::create_dir(run.join("samples")).unwrap();
        let stale = [
            run.join(".train_state.safetensors.4242-3.tmp"),
            run.join(".tmpAb12Cd"),
            run.join("samples").join(".step-000010.png.77-0.tmp"),
        ];
        let kept = [
            run.join("log.csv"),
            run.join("notes.tmp"),
            run.join(".tmp"),
            run.join(".tmp-not-ours"),
        ];
        for path in stale.iter().chain(&kept) {
            std::fs::write(path, b"x").unwrap();
        }
        let lock = FolderLock::acquire(run, "test").unwrap();
        let mut expected = stale.to_vec();
        expected.sort();
        assert_eq!(lock.removed(), expected);
        assert!(stale.iter().all(|p| !p.exists()));
        assert!(kept.iter().all(|p| p.exists()));
    }
}
