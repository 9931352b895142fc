//! The ground truth `photomat simulate` leaves beside its photos (`simulation.json`,
//! `docs/datasets.md`), as far as `prepare` and `eval-detector` need it: per photo file, its
//! true highlight and material family.
//!
//! Only the fields used here are read and unknown ones are ignored, so this reader keeps working
//! when the simulator records more about its cameras. The simulator writes the file into its
//! output folder and the photos into `photos/`, so for a photo folder `DIR` the record is
//! looked for as `DIR/simulation.json` and then `DIR/../simulation.json`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use photomat_core::{Error, Result};

/// File name of the simulator's record.
pub const SIMULATION_FILE: &str = "simulation.json";
/// `format` field of a simulation record.
pub const SIMULATION_FORMAT: &str = "photomat-simulation";

#[derive(serde::Deserialize)]
struct Record {
    format: String,
    version: u32,
    photos: Vec<RecordPhoto>,
}

#[derive(serde::Deserialize)]
struct RecordPhoto {
    photo: String,
    #[serde(default)]
    family: Option<String>,
    highlight_px: [f64; 2],
}

/// Ground truth of one simulated photo.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoTruth {
    /// True highlight, continuous `(row, col)` in the photo as stored.
    pub highlight_px: [f64; 2],
    /// Material family, when the record says it.
    pub family: Option<String>,
}

/// The truth of every photo of one simulation record, by canonical photo path.
#[derive(Debug, Clone, Default)]
pub struct SimulationTruth {
    /// The record file, when one was found.
    pub file: Option<PathBuf>,
    photos: HashMap<PathBuf, PhotoTruth>,
}

impl SimulationTruth {
    /// The record for photos in `photo_dir` (`photo_dir/simulation.json`, else the parent's),
    /// or an empty truth when there is none. A record that exists but cannot be read is an
    /// error naming it.
    pub fn find(photo_dir: &Path) -> Result<Self> {
        let candidates = [Some(photo_dir), photo_dir.parent()];
        for dir in candidates.into_iter().flatten() {
            let path = dir.join(SIMULATION_FILE);
            if path.is_file() {
                return Self::read(&path);
            }
        }
        Ok(Self::default())
    }

    /// Read one record; photo paths are resolved against its folder.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read the simulation record: {e}")))?;
        let record: Record = serde_json::from_str(&text).map_err(|e| {
            Error::file(
                path,
                format!("not a photomat simulation record ({e}); move it away to go without truth"),
            )
        })?;
        if record.format != SIMULATION_FORMAT || record.version != 1 {
            return Err(Error::file(
                path,
                format!(
                    "format '{}' version {} is not '{SIMULATION_FORMAT}' version 1",
                    record.format, record.version
                ),
            ));
        }
        let root = path.parent().unwrap_or(Path::new("."));
        let mut photos = HashMap::new();
        for p in record.photos {
            if !p.highlight_px.iter().all(|v| v.is_finite()) {
                return Err(Error::file(
                    path,
                    format!("photo '{}' has a non-finite highlight", p.photo),
                ));
            }
            // Photos that no longer exist simply have no truth to give.
            if let Ok(canonical) = root.join(&p.photo).canonicalize() {
                photos.insert(
                    canonical,
                    PhotoTruth {
                        highlight_px: p.highlight_px,
                        family: p.family,
                    },
                );
            }
        }
        Ok(Self {
            file: Some(path.to_path_buf()),
            photos,
        })
    }

    /// Truth of the photo at `canonical_path`, if the record lists it.
    pub fn get(&self, canonical_path: &Path) -> Option<&PhotoTruth> {
        self.photos.get(canonical_path)
    }

    /// Number of photos the record lists that exist.
    pub fn len(&self) -> usize {
        self.photos.len()
    }

    /// Whether no photo has truth.
    pub fn is_empty(&self) -> bool {
        self.photos.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simulation_truth_is_found_beside_or_above_the_photos() {
        let dir = tempfile::tempdir().unwrap();
        let photos = dir.path().join("photos");
        std::fs::create_dir(&photos).unwrap();
        std::fs::write(photos.join("000000.png"), b"x").unwrap();
        assert!(SimulationTruth::find(&photos).unwrap().is_empty());
        let record = r#"{ "format": "photomat-simulation", "version": 1, "seed": 7, "size": 64,
            "photos": [ { "photo": "photos/000000.png", "family": "wood",
                          "highlight_px": [30.5, 33.0], "camera": { "exposure": 1.0 } },
                        { "photo": "photos/gone.png", "highlight_px": [1.0, 2.0] } ] }"#;
        std::fs::write(dir.path().join(SIMULATION_FILE), record).unwrap();
        let truth = SimulationTruth::find(&photos).unwrap();
        assert_eq!(truth.len(), 1);
        let key = photos.join("000000.png").canonicalize().unwrap();
        let t = truth.get(&key).unwrap();
        assert_eq!(
            (t.highlight_px, t.family.as_deref()),
            ([30.5, 33.0], Some("wood"))
        );

        std::fs::write(dir.path().join(SIMULATION_FILE), "{ not json").unwrap();
        let err = SimulationTruth::find(&photos).unwrap_err().to_string();
        assert!(err.contains(SIMULATION_FILE), "{err}");
    }
}
