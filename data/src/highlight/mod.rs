//! Flash-highlight detection: where the collocated flash sits above a flash photo.
//!
//! PhotoMat (paper §"Dataset collection", `docs/neural-models.md`, "Light detector") conditions its
//! generator on the flash position of every real photo, found by "a simple highlight detector". Two
//! detectors implement [`HighlightDetector`]:
//!
//! | name     | file        | what it does                                                        |
//! |----------|-------------|---------------------------------------------------------------------|
//! | `paper`  | `paper.rs`  | exactly the paper: centroid of the above-mean min(R,G,B) intensity  |
//! | `robust` | `robust.rs` | fits the collocated-flash falloff, specular lobe, vignetting and ambient light; the paper's centroid as a second opinion (default) |
//!
//! `robust` is the default: its mean error is below the paper's both on photos of photomat's
//! simulator (0.82 % against 1.71 % of the width, 320 photos) and on photos that Mitsuba
//! rendered from real texture photos with a tilted perspective camera and an offset flash
//! (1.76 % against 1.99 %, largest 4.8 %; `validation/`, docs/benchmarks/highlight-detector.md,
//! "Highlight detectors on independent photos"). It takes the paper's centroid as a second
//! opinion when its own fit is far from it and implausible (`robust.rs`, "Second opinion").
//!
//! Both take a display-encoded (gamma 2.2) image in [0, 1] with 1, 3 or 4 channels (alpha is
//! ignored) and return a [`Detection`]: the highlight in continuous pixel coordinates (pixel
//! (i, j) spans [i, i+1)×[j, j+1), so the centre of a 512² photo is (256, 256)), its plane
//! coordinates on the photo's side-2 square (`docs/datasets.md`), and whether the detector
//! trusted its answer or fell back to the image centre, with the reason.

mod intensity;
pub mod paper;
pub mod robust;

use std::fmt;
use std::str::FromStr;

use photomat_core::image_io::PlanarImage;
use photomat_core::{Error, Highlight, Result};

pub use paper::PaperDetector;
pub use robust::RobustDetector;

pub use photomat_core::flash::PHOTO_SIDE;

/// Whether a detector trusted its result.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DetectionStatus {
    /// The detector found a highlight it considers plausible.
    Detected,
    /// Detection failed; the highlight is the image centre (the paper's manual fallback).
    FallbackCentre,
}

impl fmt::Display for DetectionStatus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DetectionStatus::Detected => "detected",
            DetectionStatus::FallbackCentre => "fallback-centre",
        })
    }
}

/// The result of one detection.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Continuous pixel row of the highlight (0 = top edge of the image).
    pub row: f64,
    /// Continuous pixel column of the highlight (0 = left edge).
    pub col: f64,
    /// Width of the image the detection ran on, in pixels (the plane scale).
    pub width: usize,
    /// Height of the image, in pixels.
    pub height: usize,
    pub status: DetectionStatus,
    /// Why the detector fell back to the centre, or (for a detection) which of its estimates
    /// it chose and why when it had to choose; `None` for a plain detection.
    pub reason: Option<String>,
}

impl Detection {
    /// A trusted detection at continuous pixel (`row`, `col`) of a `height`×`width` image.
    pub fn detected(row: f64, col: f64, height: usize, width: usize) -> Self {
        Self {
            row,
            col,
            width,
            height,
            status: DetectionStatus::Detected,
            reason: None,
        }
    }

    /// The image centre, with the reason detection failed.
    pub fn fallback(height: usize, width: usize, reason: impl Into<String>) -> Self {
        Self {
            row: height as f64 / 2.0,
            col: width as f64 / 2.0,
            width,
            height,
            status: DetectionStatus::FallbackCentre,
            reason: Some(reason.into()),
        }
    }

    /// `(row, col)` in continuous pixel coordinates.
    pub fn pixel(&self) -> (f64, f64) {
        (self.row, self.col)
    }

    /// Plane coordinates on the photo's centred square of side [`PHOTO_SIDE`] (x right, y up),
    /// with the image width as the scale; for square photos this is
    /// `Highlight::from_pixel_on(row, col, size, 2.0)`.
    pub fn highlight(&self) -> Highlight {
        let scale = PHOTO_SIDE / self.width as f64;
        Highlight::new(
            (self.col - self.width as f64 / 2.0) * scale,
            (self.height as f64 / 2.0 - self.row) * scale,
        )
    }

    /// Distance to `(row, col)` in pixels.
    pub fn error_px(&self, row: f64, col: f64) -> f64 {
        (self.row - row).hypot(self.col - col)
    }
}

/// A highlight detector.
pub trait HighlightDetector: Send + Sync {
    /// Registered name (`paper`, `robust`).
    fn name(&self) -> &'static str;

    /// Detect the flash highlight of `image` (display-encoded values in [0, 1], 1, 3 or 4
    /// channels). Errors only for images it cannot read (no pixels, 2 channels); a photo in
    /// which it finds no plausible highlight is a [`DetectionStatus::FallbackCentre`] result.
    fn detect(&self, image: &PlanarImage) -> Result<Detection>;
}

/// The detectors selectable by name (`--detector`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetectorKind {
    /// [`RobustDetector`], the default.
    #[default]
    Robust,
    /// [`PaperDetector`].
    Paper,
}

impl DetectorKind {
    /// Every detector, the default first.
    pub const ALL: [DetectorKind; 2] = [DetectorKind::Robust, DetectorKind::Paper];

    /// The name users type.
    pub fn name(self) -> &'static str {
        match self {
            DetectorKind::Robust => "robust",
            DetectorKind::Paper => "paper",
        }
    }

    /// A detector of this kind with its default configuration.
    pub fn build(self) -> Box<dyn HighlightDetector> {
        match self {
            DetectorKind::Robust => Box::new(RobustDetector::default()),
            DetectorKind::Paper => Box::new(PaperDetector::default()),
        }
    }
}

impl fmt::Display for DetectorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DetectorKind {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                let mut known: Vec<_> = Self::ALL.iter().map(|k| k.name()).collect();
                known.sort_unstable();
                Error::Invalid(format!(
                    "unknown highlight detector '{s}'; known detectors: {}",
                    known.join(", ")
                ))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detector_kind_parses_names_and_lists_known_ones() {
        for kind in DetectorKind::ALL {
            assert_eq!(kind.name().parse::<DetectorKind>().unwrap(), kind);
            assert_eq!(kind.build().name(), kind.name());
        }
        let err = "best".parse::<DetectorKind>().unwrap_err().to_string();
        assert!(
            err.contains("'best'") && err.contains("paper, robust"),
            "{err}"
        );
    }

    #[test]
    fn detection_plane_coordinates_follow_the_side_2_photo() {
        let d = Detection::detected(256.0, 256.0, 512, 512);
        assert_eq!(d.highlight(), Highlight::CENTER);
        let d = Detection::detected(0.0, 512.0, 512, 512);
        assert_eq!(d.highlight(), Highlight::new(1.0, 1.0));
        let h = Detection::detected(100.5, 300.25, 512, 512).highlight();
        assert_eq!(h, Highlight::from_pixel_on(100.5, 300.25, 512, PHOTO_SIDE));
        let f = Detection::fallback(512, 512, "why");
        assert_eq!(
            (f.pixel(), f.status),
            ((256.0, 256.0), DetectionStatus::FallbackCentre)
        );
    }
}
