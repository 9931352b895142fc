//! Flash-photo datasets: `photomat prepare`'s output and its reader (`docs/datasets.md`).
//!
//! A dataset folder holds the photos resized to a square working size, their detected flash
//! highlights and a report of the files that were rejected (paper §"Dataset collection": photos
//! with the flash roughly centred, the light position found by a highlight detector):
//!
//! ```text
//! DATASET/
//!   images/<stem>-<8 hex of a hash of the source path>.png   size×size 8-bit, gamma 2.2
//!   index.json                                              DatasetIndex
//!   report.txt                                              every rejected file and why
//! ```
//!
//! - [`DatasetIndex`] is `index.json` (read, validated, written atomically);
//! - [`FlashDataset`] is an opened dataset folder: the index plus image loading, what the
//!   training crop sampler reads;
//! - [`prepare`](prepare::prepare) builds or extends a dataset from a folder of photos;
//! - [`evaluate`](evaluate::evaluate) measures detectors against simulated ground truth;
//! - [`lens`] reads (and, for the simulator, writes) the field of view a photo's EXIF records.

pub mod evaluate;
pub mod lens;
pub mod photo;
pub mod prepare;
pub mod simulation;

use std::path::{Component, Path, PathBuf};

use photomat_core::image_io::{PlanarImage, read_png, write_atomic};
use photomat_core::{Error, Highlight, Result};

use crate::highlight::{DetectionStatus, DetectorKind, PHOTO_SIDE};

pub use evaluate::{Evaluation, evaluate};
pub use prepare::{PrepareOptions, PrepareSummary, prepare};

/// `format` field of `index.json`.
pub const INDEX_FORMAT: &str = "photomat-dataset";
/// `version` field of `index.json` this code reads and writes.
pub const INDEX_VERSION: u32 = 1;
/// File name of the index inside a dataset folder.
pub const INDEX_FILE: &str = "index.json";
/// File name of the human-readable report inside a dataset folder.
pub const REPORT_FILE: &str = "report.txt";
/// Folder of the prepared images inside a dataset folder.
pub const IMAGES_DIR: &str = "images";

/// `index.json`: the dataset's photos and rejected files.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DatasetIndex {
    /// Always [`INDEX_FORMAT`].
    pub format: String,
    /// Always [`INDEX_VERSION`].
    pub version: u32,
    /// Side of every prepared image, in pixels.
    pub size: usize,
    /// Detector that found the highlights.
    pub detector: DetectorKind,
    /// Prepared photos, sorted by source path.
    pub photos: Vec<PhotoEntry>,
    /// Files that could not be prepared, sorted by source path.
    pub rejected: Vec<RejectedEntry>,
}

/// One prepared photo.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotoEntry {
    /// The prepared image, relative to the dataset folder (`images/…png`).
    pub image: String,
    /// Absolute path of the source photo.
    pub source: String,
    /// Size of the source file in bytes.
    pub source_bytes: u64,
    /// Modification time of the source file, seconds since the Unix epoch.
    pub source_modified: i64,
    /// `[width, height]` of the source photo after EXIF orientation, before cropping.
    pub source_size: [usize; 2],
    /// Detected highlight, continuous `(row, col)` pixel coordinates of the prepared image.
    pub highlight_px: [f64; 2],
    /// The same highlight in plane coordinates `(x, y)` of the photo's side-2 square.
    pub highlight: [f64; 2],
    /// Whether the detector trusted its result.
    pub status: DetectionStatus,
    /// Why the detector fell back to the centre.
    pub reason: Option<String>,
    /// True highlight `(row, col)` in the prepared image, from the simulator's
    /// `simulation.json`, transformed by the same orientation, crop and resize.
    pub truth_highlight_px: Option<[f64; 2]>,
}

/// One file that could not be prepared.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RejectedEntry {
    /// Absolute path of the file.
    pub source: String,
    /// Why it was rejected.
    pub reason: String,
    /// Size in bytes when it was rejected (so an unchanged file is not retried).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_bytes: Option<u64>,
    /// Modification time when it was rejected, seconds since the Unix epoch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_modified: Option<i64>,
}

impl PhotoEntry {
    /// The detected highlight in plane coordinates of the photo's side-2 square.
    pub fn highlight(&self) -> Highlight {
        Highlight::new(self.highlight[0], self.highlight[1])
    }
}

impl DatasetIndex {
    /// An empty index for images of `size`² found with `detector`.
    pub fn new(size: usize, detector: DetectorKind) -> Self {
        Self {
            format: INDEX_FORMAT.into(),
            version: INDEX_VERSION,
            size,
            detector,
            photos: Vec::new(),
            rejected: Vec::new(),
        }
    }

    /// Read and validate `DIR/index.json`.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join(INDEX_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            Error::file(
                &path,
                format!(
                    "cannot read the dataset index ({e}); is this a `photomat prepare` folder?"
                ),
            )
        })?;
        let index: Self = serde_json::from_str(&text)
            .map_err(|e| Error::file(&path, format!("not a valid dataset index: {e}")))?;
        index.validate().map_err(|e| Error::file(&path, e))?;
        Ok(index)
    }

    /// Write `DIR/index.json` atomically (pretty-printed, photos and rejections sorted).
    pub fn write(&self, dir: &Path) -> Result<()> {
        let path = dir.join(INDEX_FILE);
        let mut sorted = self.clone();
        sorted.photos.sort_by(|a, b| a.source.cmp(&b.source));
        sorted.rejected.sort_by(|a, b| a.source.cmp(&b.source));
        let mut text = serde_json::to_string_pretty(&sorted)
            .map_err(|e| Error::file(&path, format!("cannot encode the index: {e}")))?;
        text.push('\n');
        write_atomic(&path, text.as_bytes())
    }

    /// Check the header and every entry; the message says what is wrong.
    fn validate(&self) -> std::result::Result<(), String> {
        if self.format != INDEX_FORMAT {
            return Err(format!(
                "format is '{}', expected '{INDEX_FORMAT}'",
                self.format
            ));
        }
        if self.version != INDEX_VERSION {
            return Err(format!(
                "version {} is not supported (this photomat reads version {INDEX_VERSION})",
                self.version
            ));
        }
        if self.size == 0 {
            return Err("size must be positive".into());
        }
        for (i, p) in self.photos.iter().enumerate() {
            if !is_inside(&p.image) {
                return Err(format!(
                    "photo {i}: image path '{}' must be relative and stay inside the dataset",
                    p.image
                ));
            }
            let finite = p
                .highlight_px
                .iter()
                .chain(&p.highlight)
                .all(|v| v.is_finite())
                && p.truth_highlight_px
                    .is_none_or(|t| t.iter().all(|v| v.is_finite()));
            if !finite {
                return Err(format!(
                    "photo {i} ('{}'): a highlight is not finite",
                    p.image
                ));
            }
        }
        Ok(())
    }
}

/// Whether `relative` is a relative path without `..`, so it cannot leave the dataset folder.
fn is_inside(relative: &str) -> bool {
    let path = Path::new(relative);
    !relative.is_empty()
        && path
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
}

/// An opened dataset folder: its index and its images.
#[derive(Debug, Clone)]
pub struct FlashDataset {
    root: PathBuf,
    index: DatasetIndex,
}

impl FlashDataset {
    /// Open the dataset in `dir` (reads and validates `index.json`).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self> {
        let root = dir.as_ref().to_path_buf();
        let index = DatasetIndex::read(&root)?;
        Ok(Self { root, index })
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The index.
    pub fn index(&self) -> &DatasetIndex {
        &self.index
    }

    /// Side of every image, in pixels.
    pub fn size(&self) -> usize {
        self.index.size
    }

    /// The prepared photos.
    pub fn photos(&self) -> &[PhotoEntry] {
        &self.index.photos
    }

    /// Number of prepared photos.
    pub fn len(&self) -> usize {
        self.index.photos.len()
    }

    /// Whether the dataset holds no photo.
    pub fn is_empty(&self) -> bool {
        self.index.photos.is_empty()
    }

    /// Path of the image of photo `i`.
    pub fn image_path(&self, i: usize) -> PathBuf {
        self.root.join(&self.index.photos[i].image)
    }

    /// Image of photo `i`: (3, size, size), display-encoded (gamma 2.2) values in [0, 1].
    /// Errors name the file: missing, unreadable, or not `size`² RGB.
    pub fn load_image(&self, i: usize) -> Result<PlanarImage> {
        let path = self.image_path(i);
        let (image, _) = read_png(&path)?;
        let size = self.index.size;
        if (image.channels, image.height, image.width) != (3, size, size) {
            return Err(Error::file(
                &path,
                format!(
                    "is {}×{}×{} (C×H×W), the dataset index says 3×{size}×{size}",
                    image.channels, image.height, image.width
                ),
            ));
        }
        Ok(image)
    }

    /// Detected highlight of photo `i` in plane coordinates of the photo's side-2 square
    /// ([`PHOTO_SIDE`]); its H×H crops of the 2H×2H photo are unit squares.
    pub fn highlight(&self, i: usize) -> Highlight {
        self.index.photos[i].highlight()
    }

    /// Highlight of photo `i` in continuous `(row, col)` pixels of its image.
    pub fn highlight_px(&self, i: usize) -> (f64, f64) {
        let [row, col] = self.index.photos[i].highlight_px;
        (row, col)
    }
}

/// Plane coordinates on the side-2 square of continuous pixel `(row, col)` of a `size`² image.
pub(crate) fn plane_of(row: f64, col: f64, size: usize) -> [f64; 2] {
    let h = Highlight::from_pixel_on(row, col, size, PHOTO_SIDE);
    [h.x, h.y]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(image: &str) -> PhotoEntry {
        PhotoEntry {
            image: image.into(),
            source: "/photos/a.jpg".into(),
            source_bytes: 10,
            source_modified: 1,
            source_size: [640, 480],
            highlight_px: [32.0, 30.0],
            highlight: plane_of(32.0, 30.0, 64),
            status: DetectionStatus::Detected,
            reason: None,
            truth_highlight_px: None,
        }
    }

    #[test]
    fn dataset_index_round_trips_and_rejects_escaping_paths() {
        let dir = tempfile::tempdir().unwrap();
        let mut index = DatasetIndex::new(64, DetectorKind::Paper);
        index.photos.push(entry("images/a-00000000.png"));
        index.write(dir.path()).unwrap();
        let text = std::fs::read_to_string(dir.path().join(INDEX_FILE)).unwrap();
        assert!(text.contains("\"detector\": \"paper\"") && text.contains("\"reason\": null"));
        assert_eq!(DatasetIndex::read(dir.path()).unwrap(), index);

        index.photos[0].image = "../escape.png".into();
        index.write(dir.path()).unwrap();
        let err = DatasetIndex::read(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("index.json") && err.contains("inside the dataset"),
            "{err}"
        );

        let err = FlashDataset::open(dir.path().join("nothing"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("index.json") && err.contains("photomat prepare"),
            "{err}"
        );
    }
}
