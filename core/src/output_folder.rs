//! The one rule for a command that writes its result into a folder (`photomat capture`,
//! `sample`, `trade`, `simulate`, `library import`, `rank-snapshots --best-to`): the folder
//! holds one result, whole, or nothing (docs/robustness.md, "Output folders").
//!
//! - A folder that already holds a result of the command is refused, naming it, unless the
//!   caller allows overwriting; a folder holding files the command does not write is refused
//!   always (naming them), so that `--overwrite` never removes what a user put there.
//! - The new result is written into a staging folder beside the output,
//!   `.<name>.photomat-new`, locked ([`FolderLock`]) so that a second process on the same
//!   output fails at once naming the first. [`OutputFolder::commit`] then marks it complete and
//!   puts it in the output's place: the old result is renamed to `.<name>.photomat-old`, the
//!   staging folder to the output, and the old one removed.
//! - A process killed at any point leaves the old result whole (in place, or renamed aside
//!   with the new one incomplete) or the new one whole (in place, or complete in staging with
//!   the old one aside): the next [`OutputFolder::claim`] of the output finishes or undoes the
//!   interrupted commit before anything else ([`recover`]). A killed writer's incomplete
//!   staging folder is removed by the next claim.
//!
//! Inputs of a command that lie inside its output would be replaced by the result they feed:
//! [`refuse_input_inside`] refuses them.

use std::path::{Path, PathBuf};

use crate::folder_lock::{FolderLock, LOCK_FILE};
use crate::{Error, Result};

/// The marker a staging folder holds once its result is complete.
const COMPLETE_MARKER: &str = ".photomat-complete";

/// What a command's result folder holds.
#[derive(Debug, Clone, Copy)]
pub struct ResultKind {
    /// What the result is, for messages ("a capture", "samples").
    pub what: &'static str,
    /// The command, for messages and the lock (`photomat capture`).
    pub command: &'static str,
    /// The names of the entries the command writes; a trailing `*` matches any rest
    /// (`seed-*`). The lock file is always one of them.
    pub entries: &'static [&'static str],
    /// Entries (among `entries`) that a new result takes over from the old one instead of
    /// replacing, e.g. a cache of trained models that later runs reuse: a claim moves them into
    /// the staging folder, and a claim after a killed run moves them back first.
    pub kept: &'static [&'static str],
}

impl ResultKind {
    /// Whether the entry `name` of an output folder is one the command writes.
    pub fn writes(&self, name: &str) -> bool {
        name == LOCK_FILE
            || name == COMPLETE_MARKER
            || self
                .entries
                .iter()
                .any(|pattern| match pattern.strip_suffix('*') {
                    Some(prefix) => name.starts_with(prefix),
                    None => name == *pattern,
                })
    }
}

/// A result being written: the staging folder to write into, and where it goes.
#[derive(Debug)]
pub struct OutputFolder {
    output: PathBuf,
    staging: PathBuf,
    kind: ResultKind,
    lock: Option<FolderLock>,
    /// Whether `output` held a result that the commit replaces.
    replaces: bool,
}

/// The staging folder beside `output`.
fn staging_of(output: &Path) -> Result<PathBuf> {
    sibling(output, "photomat-new")
}

/// Where `output`'s old result waits during a commit.
fn old_of(output: &Path) -> Result<PathBuf> {
    sibling(output, "photomat-old")
}

/// `.<name>.<tag>` beside `output`.
fn sibling(output: &Path, tag: &str) -> Result<PathBuf> {
    let name = output
        .file_name()
        .ok_or_else(|| Error::file(output, "an output folder needs a name (not / or ..)"))?;
    let parent = output.parent().unwrap_or(Path::new(""));
    Ok(parent.join(format!(".{}.{tag}", name.to_string_lossy())))
}

/// The entries of `dir` (none when it does not exist).
fn entries(dir: &Path) -> Result<Vec<String>> {
    match std::fs::read_dir(dir) {
        Ok(list) => {
            let mut names = Vec::new();
            for entry in list {
                let entry =
                    entry.map_err(|e| Error::file(dir, format!("cannot list the folder: {e}")))?;
                names.push(entry.file_name().to_string_lossy().into_owned());
            }
            names.sort();
            Ok(names)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Vec::new()),
        Err(e) if e.kind() == std::io::ErrorKind::NotADirectory => Err(Error::file(
            dir,
            "is a file, not a folder: choose a folder for the output",
        )),
        Err(e) => Err(Error::file(dir, format!("cannot list the folder: {e}"))),
    }
}

fn remove_dir(path: &Path) -> Result<()> {
    match std::fs::remove_dir_all(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(Error::file(path, format!("cannot remove: {e}"))),
    }
}

fn rename(from: &Path, to: &Path) -> Result<()> {
    std::fs::rename(from, to)
        .map_err(|e| Error::file(from, format!("cannot rename to {}: {e}", to.display())))
}

/// Finishes or undoes a commit of `output` that a killed process left half done (module
/// docs); the caller holds the staging folder's lock. Returns what it did, if anything.
pub fn recover(output: &Path) -> Result<Option<String>> {
    let (staging, old) = (staging_of(output)?, old_of(output)?);
    if !old.exists() {
        return Ok(None);
    }
    if output.exists() {
        // Killed after the new result was in place: only the old one's removal was left.
        remove_dir(&old)?;
        return Ok(Some(format!(
            "removed {}, the previous result an interrupted commit left",
            old.display()
        )));
    }
    if staging.join(COMPLETE_MARKER).exists() {
        rename(&staging, output)?;
        std::fs::remove_file(output.join(COMPLETE_MARKER)).ok();
        remove_dir(&old)?;
        Ok(Some(format!(
            "finished an interrupted commit: {} holds the newer result",
            output.display()
        )))
    } else {
        rename(&old, output)?;
        Ok(Some(format!(
            "undid an interrupted commit: {} holds its previous result again",
            output.display()
        )))
    }
}

impl OutputFolder {
    /// Claims `output` for a new result of `kind` (module docs): refuses a folder holding files
    /// the command does not write, and one holding an earlier result unless `overwrite`; then
    /// locks and empties the staging folder. Errors name the folder and what it holds.
    pub fn claim(output: &Path, kind: ResultKind, overwrite: bool) -> Result<Self> {
        let staging = staging_of(output)?;
        let mut lock = FolderLock::acquire(&staging, kind.command)?;
        if recover(output)?.is_some() && !staging.exists() {
            // The recovery put a complete staging folder in the output's place, its lock file
            // with it: lock a new, empty one.
            drop(lock);
            lock = FolderLock::acquire(&staging, kind.command)?;
        }
        // A process that locked the output itself (a run writing there) holds it too.
        if output.join(LOCK_FILE).exists() {
            drop(FolderLock::acquire(output, kind.command)?);
        }
        let held = entries(output)?;
        let foreign: Vec<&String> = held.iter().filter(|n| !kind.writes(n)).collect();
        if !foreign.is_empty() {
            let shown: Vec<&str> = foreign.iter().take(5).map(|s| s.as_str()).collect();
            return Err(Error::file(
                output,
                format!(
                    "holds files that {} does not write ({}{}); choose an empty or new folder \
                     for {}",
                    kind.command,
                    shown.join(", "),
                    if foreign.len() > 5 { ", …" } else { "" },
                    kind.what
                ),
            ));
        }
        // A kept entry alone (a cache of an interrupted first run) is not a result.
        let results: Vec<&String> = held
            .iter()
            .filter(|n| {
                *n != LOCK_FILE && *n != COMPLETE_MARKER && !kind.kept.contains(&n.as_str())
            })
            .collect();
        let replaces = !results.is_empty();
        if replaces && !overwrite {
            let shown: Vec<&str> = results.iter().take(5).map(|s| s.as_str()).collect();
            return Err(Error::file(
                output,
                format!(
                    "already holds {} ({}{}); add --overwrite to replace it whole, or choose \
                     another folder",
                    kind.what,
                    shown.join(", "),
                    if results.len() > 5 { ", …" } else { "" }
                ),
            ));
        }
        // A killed writer's kept entries go back to the output first (they are the previous
        // result's), then its leftovers go: the staging folder starts empty but for its lock.
        for name in kind.kept {
            let (inside, back) = (staging.join(name), output.join(name));
            if inside.exists() && !back.exists() {
                std::fs::create_dir_all(output)
                    .map_err(|e| Error::file(output, format!("cannot create: {e}")))?;
                rename(&inside, &back)?;
            }
        }
        for name in entries(&staging)? {
            if name == LOCK_FILE {
                continue;
            }
            let path = staging.join(&name);
            let removed = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            removed.map_err(|e| Error::file(&path, format!("cannot remove a stale file: {e}")))?;
        }
        for name in kind.kept {
            let from = output.join(name);
            if from.exists() {
                rename(&from, &staging.join(name))?;
            }
        }
        Ok(Self {
            output: output.to_path_buf(),
            staging,
            kind,
            lock: Some(lock),
            replaces,
        })
    }

    /// The folder to write the result into (the staging folder).
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Where the result goes.
    pub fn output(&self) -> &Path {
        &self.output
    }

    /// Whether the commit replaces an earlier result.
    pub fn replaces(&self) -> bool {
        self.replaces
    }

    /// Puts the complete result in the output's place (module docs) and returns the output.
    /// Every file the staging folder holds must be one the command writes.
    pub fn commit(mut self) -> Result<PathBuf> {
        let stray: Vec<String> = entries(&self.staging)?
            .into_iter()
            .filter(|n| !self.kind.writes(n))
            .collect();
        if !stray.is_empty() {
            return Err(Error::Invalid(format!(
                "{} wrote {} into its result, which it does not declare: a bug",
                self.kind.command,
                stray.join(", ")
            )));
        }
        let marker = self.staging.join(COMPLETE_MARKER);
        std::fs::write(&marker, b"")
            .map_err(|e| Error::file(&marker, format!("cannot mark the result complete: {e}")))?;
        let old = old_of(&self.output)?;
        if self.output.exists() {
            rename(&self.output, &old)?;
        }
        rename(&self.staging, &self.output)?;
        std::fs::remove_file(self.output.join(COMPLETE_MARKER))
            .map_err(|e| Error::file(&self.output, format!("cannot remove the marker: {e}")))?;
        remove_dir(&old)?;
        // The lock file moved with the folder; the lock is released here.
        self.lock.take();
        Ok(self.output.clone())
    }
}

/// Refuses an input `input` (a file or folder a command reads) inside `output`, which the
/// command's result replaces: `what` names the input for the message (`--known`).
pub fn refuse_input_inside(input: &Path, output: &Path, what: &str) -> Result<()> {
    let absolute =
        |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| crate::paths::absolute(p));
    let (input_abs, output_abs) = (absolute(input), absolute(output));
    if input_abs.starts_with(&output_abs) {
        return Err(Error::file(
            input,
            format!(
                "{what} lies inside the output folder {}, which the result replaces: move it \
                 or choose another output",
                output.display()
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const KIND: ResultKind = ResultKind {
        what: "a capture",
        command: "photomat capture",
        entries: &["capture.json", "material", "seed-*", "cache"],
        kept: &["cache"],
    };

    fn write_result(dir: &Path, tag: &str) {
        std::fs::create_dir_all(dir.join("material")).unwrap();
        std::fs::write(dir.join("capture.json"), tag).unwrap();
        std::fs::write(dir.join("material").join("map.txt"), tag).unwrap();
    }

    fn read(dir: &Path) -> (String, String) {
        (
            std::fs::read_to_string(dir.join("capture.json")).unwrap(),
            std::fs::read_to_string(dir.join("material").join("map.txt")).unwrap(),
        )
    }

    #[test]
    fn an_earlier_result_is_refused_unless_overwritten_and_then_replaced_whole() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("cap");
        let first = OutputFolder::claim(&out, KIND, false).unwrap();
        write_result(first.path(), "old");
        std::fs::create_dir(first.path().join("seed-0001")).unwrap();
        first.commit().unwrap();
        let err = OutputFolder::claim(&out, KIND, false)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("already holds a capture") && err.contains("--overwrite"),
            "{err}"
        );
        let second = OutputFolder::claim(&out, KIND, true).unwrap();
        assert!(second.replaces());
        write_result(second.path(), "new");
        second.commit().unwrap();
        assert_eq!(read(&out), ("new".into(), "new".into()));
        // Nothing of the old result is left: its seed folder went with it.
        assert!(!out.join("seed-0001").exists());
        assert!(!old_of(&out).unwrap().exists() && !staging_of(&out).unwrap().exists());
    }

    #[test]
    fn a_folder_with_files_the_command_does_not_write_is_refused_even_with_overwrite() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("desk");
        std::fs::create_dir(&out).unwrap();
        std::fs::write(out.join("notes.txt"), "mine").unwrap();
        let err = OutputFolder::claim(&out, KIND, true)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("notes.txt") && err.contains("does not write"),
            "{err}"
        );
        assert!(out.join("notes.txt").exists());
    }

    #[test]
    fn a_commit_killed_at_any_point_leaves_the_old_or_the_new_result_whole() {
        // The states a kill can leave between the commit's steps, and what the next claim
        // finds once it has recovered.
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("cap");
        let (staging, old) = (staging_of(&out).unwrap(), old_of(&out).unwrap());
        let reset = || {
            for d in [&out, &staging, &old] {
                let _ = std::fs::remove_dir_all(d);
            }
        };
        // Killed while writing: the old result stays, the partial new one goes.
        reset();
        write_result(&out, "old");
        write_result(&staging, "partial");
        drop(OutputFolder::claim(&out, KIND, true).unwrap());
        assert_eq!(read(&out).0, "old");
        // Killed after marking complete, before any rename: the old result stays.
        reset();
        write_result(&out, "old");
        write_result(&staging, "new");
        std::fs::write(staging.join(COMPLETE_MARKER), b"").unwrap();
        recover(&out).unwrap();
        assert_eq!(read(&out).0, "old");
        // Killed between the renames, new result complete: it is put in place.
        reset();
        write_result(&old, "old");
        write_result(&staging, "new");
        std::fs::write(staging.join(COMPLETE_MARKER), b"").unwrap();
        recover(&out).unwrap();
        assert_eq!(read(&out), ("new".into(), "new".into()));
        assert!(!old.exists() && !out.join(COMPLETE_MARKER).exists());
        // Killed between the renames with an incomplete staging folder: the old one returns.
        reset();
        write_result(&old, "old");
        write_result(&staging, "partial");
        recover(&out).unwrap();
        assert_eq!(read(&out), ("old".into(), "old".into()));
        // Killed before the old one's removal: the new one stays, the old one goes.
        reset();
        write_result(&out, "new");
        write_result(&old, "old");
        recover(&out).unwrap();
        assert_eq!(read(&out).0, "new");
        assert!(!old.exists());
    }

    #[test]
    fn kept_entries_carry_over_and_survive_a_killed_run() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("study");
        // A first run killed mid-way: its cache is in the staging folder.
        let first = OutputFolder::claim(&out, KIND, false).unwrap();
        std::fs::create_dir(first.path().join("cache")).unwrap();
        std::fs::write(first.path().join("cache").join("model"), "trained").unwrap();
        drop(first);
        // The next claim finds it (an unfinished cache is no result: no --overwrite needed),
        // carries it over, and the commit puts it in place with the new result.
        let second = OutputFolder::claim(&out, KIND, false).unwrap();
        assert!(!second.replaces());
        let cached = second.path().join("cache").join("model");
        assert_eq!(std::fs::read_to_string(&cached).unwrap(), "trained");
        write_result(second.path(), "new");
        second.commit().unwrap();
        assert_eq!(
            std::fs::read_to_string(out.join("cache").join("model")).unwrap(),
            "trained"
        );
        // A later run replacing the result keeps the cache too.
        let third = OutputFolder::claim(&out, KIND, true).unwrap();
        assert!(third.path().join("cache").join("model").exists());
    }

    #[test]
    fn inputs_inside_the_output_are_refused() {
        let root = tempfile::tempdir().unwrap();
        let out = root.path().join("cap");
        std::fs::create_dir_all(out.join("material")).unwrap();
        let err = refuse_input_inside(&out.join("material"), &out, "--known")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("--known lies inside the output folder"),
            "{err}"
        );
        refuse_input_inside(&root.path().join("elsewhere"), &out, "--known").unwrap();
    }
}
