//! `photomat eval-detector`: highlight detectors measured against the simulator's truth.
//!
//! Re-runs each chosen detector on the prepared images of a dataset (what the GAN trains on)
//! and compares with `truth_highlight_px`, the true highlight moved through the same crop and
//! resize (`docs/datasets.md`). Errors are Euclidean distances in pixels of the prepared image
//! and in % of its width, overall and per material family when the source photo's
//! `simulation.json` names it. Fallbacks to the centre count as detections at the centre.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::{Error, Result};
use rayon::prelude::*;

use super::FlashDataset;
use super::simulation::SimulationTruth;
use crate::highlight::{DetectionStatus, DetectorKind};

/// Error statistics of one detector over a group of photos.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ErrorStats {
    /// Photos in the group.
    pub photos: usize,
    /// Photos where the detector fell back to the centre.
    pub fallbacks: usize,
    /// Mean error in pixels of the prepared image.
    pub mean_px: f64,
    /// Largest error in pixels.
    pub max_px: f64,
    /// Mean error in % of the image width.
    pub mean_percent: f64,
    /// Largest error in % of the image width.
    pub max_percent: f64,
}

impl ErrorStats {
    fn from_errors(errors: &[(f64, bool)], width: usize) -> Self {
        let n = errors.len();
        let mean_px = errors.iter().map(|e| e.0).sum::<f64>() / n.max(1) as f64;
        let max_px = errors.iter().map(|e| e.0).fold(0.0, f64::max);
        let to_percent = 100.0 / width as f64;
        Self {
            photos: n,
            fallbacks: errors.iter().filter(|e| e.1).count(),
            mean_px,
            max_px,
            mean_percent: mean_px * to_percent,
            max_percent: max_px * to_percent,
        }
    }
}

/// One detector's errors: over all photos with truth and per family.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DetectorEvaluation {
    pub detector: DetectorKind,
    pub all: ErrorStats,
    /// Per family name, sorted; photos whose family is unknown are under "unknown".
    pub families: BTreeMap<String, ErrorStats>,
}

/// The result of [`evaluate`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Evaluation {
    /// Side of the dataset's images.
    pub size: usize,
    /// Photos of the dataset.
    pub photos: usize,
    /// Photos with a true highlight (the ones measured).
    pub with_truth: usize,
    pub detectors: Vec<DetectorEvaluation>,
}

/// Family label of photos whose source has no family in a simulation record.
pub const UNKNOWN_FAMILY: &str = "unknown";

/// Measure `detectors` on every photo of `dataset` that has a true highlight. Errors when no
/// photo has one, or an image cannot be read.
pub fn evaluate(
    dataset: &FlashDataset,
    detectors: &[DetectorKind],
    progress: bool,
) -> Result<Evaluation> {
    let with_truth: Vec<usize> = (0..dataset.len())
        .filter(|&i| dataset.photos()[i].truth_highlight_px.is_some())
        .collect();
    if with_truth.is_empty() {
        return Err(Error::file(
            dataset.root().join(super::INDEX_FILE),
            "no photo has a true highlight (truth_highlight_px): eval-detector needs a dataset \
             prepared from `photomat simulate` output",
        ));
    }
    let families = families_of(dataset, &with_truth);
    let built: Vec<_> = detectors.iter().map(|k| k.build()).collect();
    let bar = if progress {
        ProgressBar::new(with_truth.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} detecting [{bar:30}] {pos}/{len} photos, eta {eta}",
        )
        .expect("static template")
        .progress_chars("=> "),
    );
    // Per photo: per detector (error px, fell back).
    let errors: Vec<Vec<(f64, bool)>> = with_truth
        .par_iter()
        .map(|&i| {
            let image = dataset.load_image(i)?;
            let [row, col] = dataset.photos()[i]
                .truth_highlight_px
                .expect("filtered on truth");
            let per_detector = built
                .iter()
                .map(|d| {
                    let detection = d
                        .detect(&image)
                        .map_err(|e| Error::file(dataset.image_path(i), e))?;
                    Ok((
                        detection.error_px(row, col),
                        detection.status == DetectionStatus::FallbackCentre,
                    ))
                })
                .collect::<Result<Vec<_>>>();
            bar.inc(1);
            per_detector
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();

    let size = dataset.size();
    let evaluations = detectors
        .iter()
        .enumerate()
        .map(|(k, &detector)| {
            let all: Vec<(f64, bool)> = errors.iter().map(|e| e[k]).collect();
            let mut by_family: BTreeMap<String, Vec<(f64, bool)>> = BTreeMap::new();
            for (e, family) in errors.iter().zip(&families) {
                by_family.entry(family.clone()).or_default().push(e[k]);
            }
            DetectorEvaluation {
                detector,
                all: ErrorStats::from_errors(&all, size),
                families: by_family
                    .into_iter()
                    .map(|(f, e)| (f, ErrorStats::from_errors(&e, size)))
                    .collect(),
            }
        })
        .collect();
    Ok(Evaluation {
        size,
        photos: dataset.len(),
        with_truth: with_truth.len(),
        detectors: evaluations,
    })
}

/// Family of each photo, from the simulation record beside or above its source file
/// (records are read once per folder; unreadable or missing ones give "unknown").
fn families_of(dataset: &FlashDataset, photos: &[usize]) -> Vec<String> {
    let mut records: HashMap<PathBuf, Option<SimulationTruth>> = HashMap::new();
    photos
        .iter()
        .map(|&i| {
            let source = Path::new(&dataset.photos()[i].source);
            let family = source.parent().and_then(|dir| {
                let record = records
                    .entry(dir.to_path_buf())
                    .or_insert_with(|| SimulationTruth::find(dir).ok());
                let canonical = source.canonicalize().ok()?;
                record.as_ref()?.get(&canonical)?.family.clone()
            });
            family.unwrap_or_else(|| UNKNOWN_FAMILY.to_string())
        })
        .collect()
}

impl Evaluation {
    /// A fixed-width table: one row per detector and family, then the detector's total.
    pub fn table(&self) -> String {
        let mut out = format!(
            "{:<8} {:<16} {:>6} {:>9} {:>8} {:>8} {:>8} {:>9}\n",
            "detector", "family", "photos", "mean px", "max px", "mean %w", "max %w", "fallbacks"
        );
        for d in &self.detectors {
            let rows = d
                .families
                .iter()
                .map(|(f, s)| (f.as_str(), s))
                .chain(std::iter::once(("all", &d.all)));
            for (family, s) in rows {
                out.push_str(&format!(
                    "{:<8} {:<16} {:>6} {:>9.2} {:>8.2} {:>8.3} {:>8.3} {:>9}\n",
                    d.detector.name(),
                    family,
                    s.photos,
                    s.mean_px,
                    s.max_px,
                    s.mean_percent,
                    s.max_percent,
                    s.fallbacks
                ));
            }
        }
        out
    }
}
