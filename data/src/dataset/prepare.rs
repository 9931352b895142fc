//! `photomat prepare`: a folder of flash photos → a dataset folder (`docs/datasets.md`).
//!
//! Per photo (in parallel with rayon, a progress bar on stderr): decode JPEG/PNG with its EXIF
//! orientation, centre-crop to a square (or reject non-square photos on request), resize to the
//! working size in linear light, detect the flash highlight (paper §"Dataset collection";
//! [`crate::highlight`]) and write the image. Then `index.json` and `report.txt` are written.
//!
//! - Every file directly inside the photo folder is considered (hidden files, sub-folders and
//!   the simulator's `simulation.json` are not). A file that cannot be used — corrupt,
//!   truncated, too small, CMYK, not an image, unsupported format — is listed in the index's
//!   `rejected` list and the report with its reason; it never stops the run. Errors that are not
//!   a photo's fault (the output cannot be written) do stop it.
//! - Re-running on the same folder only processes files whose (path, bytes, modification time)
//!   is not in the index yet, rejected ones included; a changed file replaces its old entry.
//! - The index is saved after every chunk of [`CHUNK`] photos, so an interrupted run keeps
//!   what it finished; every write is atomic.
//! - When the simulator's `simulation.json` is beside or above the photos, each photo's true
//!   highlight goes through the same orientation, crop and resize into `truth_highlight_px`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Instant, UNIX_EPOCH};

use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::image_io::{PngBits, write_atomic, write_png};
use photomat_core::{Error, Result};
use rayon::prelude::*;

use super::photo::{Framing, prepare_photo};
use super::simulation::{SIMULATION_FILE, SimulationTruth};
use super::{
    DatasetIndex, IMAGES_DIR, INDEX_FILE, PhotoEntry, REPORT_FILE, RejectedEntry, plane_of,
};
use crate::highlight::{DetectionStatus, DetectorKind, HighlightDetector};

/// Photos processed between two saves of the index: enough to keep every core busy, few
/// enough that an interruption loses under a minute of work.
pub const CHUNK: usize = 64;

/// Smallest and largest working size: below 16 pixels there is no highlight to find; 8192
/// bounds one image to 800 MB of f32 while resizing.
pub const SIZE_RANGE: (usize, usize) = (16, 8192);

/// Options of [`prepare`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PrepareOptions {
    /// Side of the prepared images (default 512).
    pub size: usize,
    /// Highlight detector; `None` keeps the one of an existing dataset, else the default.
    pub detector: Option<DetectorKind>,
    /// Reject non-square photos instead of centre-cropping them (default false).
    pub reject_non_square: bool,
    /// Draw a progress bar on stderr (default true; it hides itself when stderr is not a
    /// terminal).
    pub progress: bool,
}

impl Default for PrepareOptions {
    fn default() -> Self {
        Self {
            size: 512,
            detector: None,
            reject_non_square: false,
            progress: true,
        }
    }
}

/// What one run did.
#[derive(Debug, Clone, PartialEq)]
pub struct PrepareSummary {
    /// Detector of the dataset.
    pub detector: DetectorKind,
    /// Files considered in the photo folder.
    pub files: usize,
    /// Files already in the index, unchanged, and skipped.
    pub unchanged: usize,
    /// Photos added (or replaced) by this run.
    pub added: usize,
    /// Of those, how many fell back to the centre.
    pub added_fallbacks: usize,
    /// Files rejected by this run.
    pub rejected: usize,
    /// Photos in the dataset after the run.
    pub total_photos: usize,
    /// Rejected files in the index after the run.
    pub total_rejected: usize,
    /// Wall-clock seconds spent on processing the new files.
    pub seconds: f64,
}

/// One file of the photo folder with the key that identifies its version.
#[derive(Debug, Clone)]
struct SourceFile {
    path: PathBuf,
    key: String,
    bytes: u64,
    modified: i64,
}

/// Result of one file: an entry, or a rejection.
enum Outcome {
    Photo(PhotoEntry),
    Rejected(RejectedEntry),
}

/// Prepare (or extend) the dataset in `out` from the photos in `photos`.
pub fn prepare(photos: &Path, out: &Path, options: &PrepareOptions) -> Result<PrepareSummary> {
    let (lo, hi) = SIZE_RANGE;
    if !(lo..=hi).contains(&options.size) {
        return Err(Error::Invalid(format!(
            "working size {} is outside [{lo}, {hi}]",
            options.size
        )));
    }
    let photo_dir = photos
        .canonicalize()
        .map_err(|e| Error::file(photos, format!("cannot open the photo folder: {e}")))?;
    if !photo_dir.is_dir() {
        return Err(Error::file(photos, "is not a folder"));
    }
    let images_dir = out.join(IMAGES_DIR);
    std::fs::create_dir_all(&images_dir)
        .map_err(|e| Error::file(&images_dir, format!("cannot create: {e}")))?;

    let mut index = if out.join(INDEX_FILE).exists() {
        let existing = DatasetIndex::read(out)?;
        check_compatible(&existing, out, options)?;
        existing
    } else {
        DatasetIndex::new(options.size, options.detector.unwrap_or_default())
    };
    let detector = index.detector.build();
    let truth = SimulationTruth::find(&photo_dir)?;

    let files = list_files(&photo_dir)?;
    if files.is_empty() {
        return Err(no_files_error(photos, &photo_dir));
    }
    let known = |f: &SourceFile| {
        index.photos.iter().any(|p| {
            p.source == f.key && p.source_bytes == f.bytes && p.source_modified == f.modified
        }) || index.rejected.iter().any(|r| {
            r.source == f.key
                && r.source_bytes == Some(f.bytes)
                && r.source_modified == Some(f.modified)
        })
    };
    let todo: Vec<SourceFile> = files.iter().filter(|f| !known(f)).cloned().collect();
    let mut summary = PrepareSummary {
        detector: index.detector,
        files: files.len(),
        unchanged: files.len() - todo.len(),
        added: 0,
        added_fallbacks: 0,
        rejected: 0,
        total_photos: 0,
        total_rejected: 0,
        seconds: 0.0,
    };

    let bar = if options.progress {
        ProgressBar::new(todo.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} preparing [{bar:30}] {pos}/{len} photos, {per_sec}, eta {eta}",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    let framing = Framing {
        size: index.size,
        reject_non_square: options.reject_non_square,
    };
    let start = Instant::now();
    for chunk in todo.chunks(CHUNK) {
        let outcomes: Vec<Result<Outcome>> = chunk
            .par_iter()
            .map(|file| {
                let outcome = process(file, framing, detector.as_ref(), out, &truth);
                bar.inc(1);
                outcome
            })
            .collect();
        let mut fatal = None;
        for (file, outcome) in chunk.iter().zip(outcomes) {
            match outcome {
                Ok(outcome) => merge(&mut index, file, outcome, out, &mut summary),
                Err(e) => {
                    fatal.get_or_insert(e);
                }
            }
        }
        let saved = index.write(out);
        if let Some(e) = fatal {
            // The photo's write failed first (e.g. a full disk): that is the error to
            // report; the index write that usually fails after it would hide it.
            bar.abandon();
            return Err(e);
        }
        saved?;
    }
    bar.finish_and_clear();
    summary.seconds = start.elapsed().as_secs_f64();
    index.write(out)?;
    summary.total_photos = index.photos.len();
    summary.total_rejected = index.rejected.len();
    write_report(out, &photo_dir, &index, &summary, truth.file.as_deref())?;
    Ok(summary)
}

/// An existing dataset must have the requested size and detector.
fn check_compatible(existing: &DatasetIndex, out: &Path, options: &PrepareOptions) -> Result<()> {
    let path = out.join(INDEX_FILE);
    if existing.size != options.size {
        return Err(Error::file(
            &path,
            format!(
                "the dataset was prepared at size {}, not {}: pass --size {} or choose a new --out",
                existing.size, options.size, existing.size
            ),
        ));
    }
    if let Some(d) = options.detector
        && d != existing.detector
    {
        return Err(Error::file(
            &path,
            format!(
                "the dataset's highlights come from the '{}' detector, not '{d}': pass \
                 --detector {} or choose a new --out",
                existing.detector, existing.detector
            ),
        ));
    }
    Ok(())
}

/// The error for a photo folder without a file directly inside: naming its sub-folders,
/// which `prepare` does not search, when it has some.
fn no_files_error(photos: &Path, dir: &Path) -> Error {
    let mut folders: Vec<String> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.path().is_dir() && !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    folders.sort();
    if folders.is_empty() {
        return Error::file(photos, "holds no photos");
    }
    const LISTED: usize = 5;
    let more = if folders.len() > LISTED {
        format!(", … ({} in all)", folders.len())
    } else {
        String::new()
    };
    Error::file(
        photos,
        format!(
            "holds no photos directly inside, only sub-folders ({}{more}), which are not \
             searched: pass the folder that holds the photos as --photos",
            folders[..folders.len().min(LISTED)].join(", ")
        ),
    )
}

/// Regular files directly inside `dir`, sorted by name; hidden files and the simulator's
/// record are skipped.
fn list_files(dir: &Path) -> Result<Vec<SourceFile>> {
    let entries =
        std::fs::read_dir(dir).map_err(|e| Error::file(dir, format!("cannot list: {e}")))?;
    let mut files = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| Error::file(dir, format!("cannot list: {e}")))?;
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name.starts_with('.') || name == SIMULATION_FILE {
            continue;
        }
        let path = entry.path();
        // Follows symbolic links; a dangling link is a file we cannot read, reported as such.
        let Ok(meta) = std::fs::metadata(&path) else {
            files.push(SourceFile {
                key: path.to_string_lossy().into_owned(),
                path,
                bytes: 0,
                modified: 0,
            });
            continue;
        };
        if !meta.is_file() {
            continue;
        }
        let modified = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_secs() as i64);
        files.push(SourceFile {
            key: path.to_string_lossy().into_owned(),
            path,
            bytes: meta.len(),
            modified,
        });
    }
    files.sort_by(|a, b| a.key.cmp(&b.key));
    Ok(files)
}

/// `images/<stem>-<8 hex of FNV-1a of the source path>.png`: unique per source path, stable
/// across runs and platforms (unlike `DefaultHasher`).
pub fn image_name(source: &str) -> String {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for b in source.bytes() {
        hash ^= b as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let stem = Path::new(source)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    // Keep names portable: anything but ASCII alphanumerics, '-' and '_' becomes '_'.
    let stem: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!(
        "{IMAGES_DIR}/{stem}-{:08x}.png",
        (hash ^ (hash >> 32)) as u32
    )
}

/// Decode, prepare, detect and write one photo. `Ok(Rejected)` for a bad file; `Err` only for
/// failures that are not the photo's (writing the output).
fn process(
    file: &SourceFile,
    framing: Framing,
    detector: &dyn HighlightDetector,
    out: &Path,
    truth: &SimulationTruth,
) -> Result<Outcome> {
    let rejected = |reason: String| {
        Ok(Outcome::Rejected(RejectedEntry {
            source: file.key.clone(),
            reason,
            source_bytes: Some(file.bytes),
            source_modified: Some(file.modified),
        }))
    };
    let bytes = match std::fs::read(&file.path) {
        Ok(b) => b,
        Err(e) => return rejected(format!("cannot read: {e}")),
    };
    // A decoder bug on a hostile file must not take the whole run down.
    let prepared = std::panic::catch_unwind(|| prepare_photo(&bytes, framing));
    let prepared = match prepared {
        Ok(Ok(p)) => p,
        Ok(Err(rejection)) => return rejected(rejection.0),
        Err(_) => return rejected("the image decoder crashed on this file".into()),
    };
    let detection = detector
        .detect(&prepared.image)
        .map_err(|e| Error::file(&file.path, e))?;
    let image = image_name(&file.key);
    write_png(&out.join(&image), &prepared.image, PngBits::Eight)?;
    let truth_highlight_px = file
        .path
        .canonicalize()
        .ok()
        .and_then(|p| truth.get(&p))
        .map(|t| {
            let (r, c) = prepared
                .transform
                .apply(t.highlight_px[0], t.highlight_px[1]);
            [r, c]
        });
    let (row, col) = detection.pixel();
    Ok(Outcome::Photo(PhotoEntry {
        image,
        source: file.key.clone(),
        source_bytes: file.bytes,
        source_modified: file.modified,
        source_size: prepared.source_size,
        highlight_px: [row, col],
        highlight: plane_of(row, col, framing.size),
        status: detection.status,
        reason: detection.reason,
        truth_highlight_px,
    }))
}

/// Put one outcome into the index, replacing any older entry of the same source.
fn merge(
    index: &mut DatasetIndex,
    file: &SourceFile,
    outcome: Outcome,
    out: &Path,
    summary: &mut PrepareSummary,
) {
    index.photos.retain(|p| p.source != file.key);
    index.rejected.retain(|r| r.source != file.key);
    match outcome {
        Outcome::Photo(entry) => {
            summary.added += 1;
            if entry.status == DetectionStatus::FallbackCentre {
                summary.added_fallbacks += 1;
            }
            index.photos.push(entry);
        }
        Outcome::Rejected(entry) => {
            // A file that was good before and is bad now leaves no stale image behind.
            let _ = std::fs::remove_file(out.join(image_name(&file.key)));
            summary.rejected += 1;
            index.rejected.push(entry);
        }
    }
}

/// `report.txt`: the run's numbers, every rejected file with its reason, every fallback.
fn write_report(
    out: &Path,
    photo_dir: &Path,
    index: &DatasetIndex,
    summary: &PrepareSummary,
    truth: Option<&Path>,
) -> Result<()> {
    let mut text = String::new();
    let _ = writeln!(text, "photomat prepare report");
    let _ = writeln!(text, "photo folder: {}", photo_dir.display());
    let _ = writeln!(
        text,
        "dataset: {} images of {}², highlight detector '{}'",
        index.photos.len(),
        index.size,
        index.detector
    );
    match truth {
        Some(path) => {
            let _ = writeln!(text, "ground truth: {}", path.display());
        }
        None => {
            let _ = writeln!(text, "ground truth: none (no {SIMULATION_FILE})");
        }
    }
    let _ = writeln!(
        text,
        "last run: {} files, {} unchanged, {} added ({} at the fallback centre), {} rejected, \
         {:.1} s",
        summary.files,
        summary.unchanged,
        summary.added,
        summary.added_fallbacks,
        summary.rejected,
        summary.seconds
    );
    let _ = writeln!(text);
    let _ = writeln!(text, "rejected files ({}):", index.rejected.len());
    let mut rejected = index.rejected.clone();
    rejected.sort_by(|a, b| a.source.cmp(&b.source));
    for r in &rejected {
        let _ = writeln!(text, "  {}: {}", r.source, r.reason);
    }
    let mut fallbacks: Vec<&PhotoEntry> = index
        .photos
        .iter()
        .filter(|p| p.status == DetectionStatus::FallbackCentre)
        .collect();
    fallbacks.sort_by(|a, b| a.source.cmp(&b.source));
    let _ = writeln!(text);
    let _ = writeln!(
        text,
        "highlight set to the image centre ({}):",
        fallbacks.len()
    );
    for p in fallbacks {
        let _ = writeln!(
            text,
            "  {}: {}",
            p.source,
            p.reason.as_deref().unwrap_or("no reason recorded")
        );
    }
    write_atomic(&out.join(REPORT_FILE), text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_names_are_stable_and_portable() {
        let a = image_name("/photos/IMG 0001.JPG");
        assert_eq!(a, image_name("/photos/IMG 0001.JPG"));
        assert!(
            a.starts_with("images/IMG_0001-") && a.ends_with(".png"),
            "{a}"
        );
        assert_ne!(a, image_name("/other/IMG 0001.JPG"));
        assert_eq!(a.len(), "images/IMG_0001-".len() + 8 + 4);
    }
}
