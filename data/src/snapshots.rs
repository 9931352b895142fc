//! Picking a GAN run's model among its snapshots, by measuring them.
//!
//! A GAN trained on these CPUs does not improve steadily: the bundled recipe's SWD moves by
//! a quarter to a half between snapshots a thousand steps apart, and one `eval-gan` seed is
//! noisy as well (two seeds of one model differ by up to half at 64 images;
//! docs/benchmarks/gan-training.md, "Picking a snapshot"). So a run keeps snapshots of G_ema + M
//! (`train-gan --snapshot-every`, [`Cadence::snapshot_every`](photomat_generator::train::Cadence))
//! and this module scores each on several seeds of the SWD against the run's data set
//! ([`model_swd`], the figure `eval-gan` reports for a seed: relit native-scale windows against
//! real patches, ProGAN's sliced Wasserstein distance), then ranks them by the mean over the seeds.
//!
//! Each measurement is kept in the model folder ([`SCORES_FILE`]) under a key naming the
//! data set (its path and a hash of its index), the count, the seed and the metric's
//! settings, for the weights file whose content hash it records: ranking again as a run adds
//! snapshots, with more seeds, or after an interruption measures only what is new, and a
//! rewritten snapshot or a re-prepared data set is measured afresh.

use std::collections::BTreeMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

use candle_core::{Device, Result, bail};
use photomat_core::image_io::write_atomic;
use photomat_core::paths::absolute;
use photomat_generator::GanModel;
use photomat_generator::model_files::{GAN_MANIFEST_FILE, GAN_WEIGHTS_FILE, read_gan_manifest};
use photomat_generator::swd::{FakeWindows, SwdConfig, model_swd};
use photomat_generator::train::{SNAPSHOTS_DIR, snapshot_folders};
use serde::{Deserialize, Serialize};

use crate::dataset::INDEX_FILE;
use crate::source::DatasetSource;

/// The file in a model folder that keeps the SWDs measured of it.
pub const SCORES_FILE: &str = "swd_scores.json";

/// One model folder's SWD on every seed.
#[derive(Debug, Clone, Serialize)]
pub struct SnapshotScore {
    /// The model folder.
    pub folder: PathBuf,
    /// Training step of the snapshot (its provenance), when recorded.
    pub step: Option<u64>,
    /// Thousands of images the run had shown D by then, when recorded.
    pub kimg: Option<f64>,
    /// SWD ×10³ (mean over the pyramid levels) per seed, in the order of the seeds.
    pub swd_per_seed: Vec<f64>,
    /// Mean of `swd_per_seed`: the ranking's key.
    pub mean: f64,
}

/// A model folder that could not be scored, and why.
#[derive(Debug, Clone, Serialize)]
pub struct UnscoredFolder {
    /// The model folder.
    pub folder: PathBuf,
    /// The error, with its causes.
    pub error: String,
}

/// What to measure each snapshot with.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoreSettings {
    /// The prepared data set the run trained on (its patches are the reference).
    pub data: PathBuf,
    /// Fakes and real patches per seed.
    pub count: usize,
    /// The seeds of the samples, lights and patches (one SWD each).
    pub seeds: Vec<u64>,
}

/// The scores of the folders that could be measured, and the folders that could not.
#[derive(Debug, Clone, Serialize)]
pub struct Scores {
    /// One per measured folder, in the order given.
    pub scored: Vec<SnapshotScore>,
    /// One per folder whose model or data could not be read or measured.
    pub unscored: Vec<UnscoredFolder>,
}

/// The measurements kept in a model folder: SWD ×10³ by key ([`Scorer::key`]), for the
/// weights whose [`content_hash`] is `weights`.
#[derive(Debug, Default, Serialize, Deserialize)]
struct KeptScores {
    weights: String,
    swd: BTreeMap<String, f64>,
}

/// A hash of `bytes` as hexadecimal text: identifies a weights file's or an index's content
/// (std's SipHash; a toolchain that changes it only makes kept scores be measured again).
fn content_hash(bytes: &[u8]) -> String {
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    bytes.hash(&mut hasher);
    format!("{:016x}", hasher.finish())
}

/// What `folder` keeps for the weights hashed `weights` (nothing if the file is missing,
/// unreadable or for other weights).
fn kept_scores(folder: &Path, weights: &str) -> KeptScores {
    std::fs::read(folder.join(SCORES_FILE))
        .ok()
        .and_then(|bytes| serde_json::from_slice::<KeptScores>(&bytes).ok())
        .filter(|kept| kept.weights == weights)
        .unwrap_or_else(|| KeptScores {
            weights: weights.to_string(),
            swd: BTreeMap::new(),
        })
}

/// The snapshot folders of the run folder `run` (`snapshots/step-NNNNNN/` holding a
/// gan.json), in the order of their steps.
pub fn run_snapshots(run: &Path) -> Result<Vec<PathBuf>> {
    let dir = run.join(SNAPSHOTS_DIR);
    let found: Vec<PathBuf> = snapshot_folders(run)
        .map_err(|e| {
            candle_core::Error::msg(format!(
                "{}: cannot list the run's snapshots ({e})",
                dir.display()
            ))
        })?
        .into_iter()
        .map(|(_, path)| path)
        .filter(|path| path.join(GAN_MANIFEST_FILE).is_file())
        .collect();
    if found.is_empty() {
        bail!(
            "{}: no snapshot folders (step-NNNNNN/gan.json); train with --snapshot-every N to \
             keep them",
            dir.display()
        );
    }
    Ok(found)
}

/// The measurement of one folder on the settings' seeds.
struct Scorer<'a> {
    settings: &'a ScoreSettings,
    /// The part of every key that does not depend on the seed.
    key_prefix: String,
}

impl<'a> Scorer<'a> {
    fn new(settings: &'a ScoreSettings) -> Result<Self> {
        let index = settings.data.join(INDEX_FILE);
        let bytes = std::fs::read(&index).map_err(|e| {
            candle_core::Error::msg(format!(
                "{}: cannot read the data set's index ({e}); is {} a prepared data set?",
                index.display(),
                settings.data.display()
            ))
        })?;
        Ok(Self {
            settings,
            key_prefix: format!(
                "{} (index {})|count={}|{:?}|native windows",
                absolute(&settings.data).display(),
                content_hash(&bytes),
                settings.count,
                SwdConfig::default()
            ),
        })
    }

    /// The key of the measurement on `seed`.
    fn key(&self, seed: u64) -> String {
        format!("{}|seed={seed}", self.key_prefix)
    }

    /// `folder`'s SWD per seed, from what it keeps where it can; `progress` hears the seeds
    /// done. Measured values are kept as soon as they are known (non-finite ones are not).
    fn score(&self, folder: &Path, progress: &mut dyn FnMut(usize)) -> Result<SnapshotScore> {
        let weights_path = folder.join(GAN_WEIGHTS_FILE);
        let weights = std::fs::read(&weights_path)
            .map_err(|e| candle_core::Error::msg(format!("{}: {e}", weights_path.display())))?;
        let mut kept = kept_scores(folder, &content_hash(&weights));
        let provenance = read_gan_manifest(folder)?.provenance;
        // Loaded only when a seed is not kept.
        let mut measured: Option<(GanModel, DatasetSource)> = None;
        let mut swd_per_seed = Vec::with_capacity(self.settings.seeds.len());
        for (done, &seed) in self.settings.seeds.iter().enumerate() {
            let key = self.key(seed);
            let swd = match kept.swd.get(&key) {
                Some(&swd) => swd,
                None => {
                    if measured.is_none() {
                        let model = GanModel::load(folder, &Device::Cpu)?;
                        let data = DatasetSource::for_model(&self.settings.data, model.config())?;
                        measured = Some((model, data));
                    }
                    let (model, data) = measured.as_ref().expect("loaded just above");
                    let swd = model_swd(
                        model,
                        data,
                        self.settings.count,
                        seed,
                        FakeWindows::Native,
                        &SwdConfig::default(),
                        &mut |_, _| {},
                    )?
                    .mean;
                    if swd.is_finite() {
                        kept.swd.insert(key, swd);
                        let path = folder.join(SCORES_FILE);
                        let text = serde_json::to_string_pretty(&kept)
                            .map_err(candle_core::Error::wrap)?;
                        write_atomic(&path, text.as_bytes()).map_err(|e| {
                            candle_core::Error::msg(format!("cannot write {}: {e}", path.display()))
                        })?;
                    }
                    swd
                }
            };
            swd_per_seed.push(swd);
            progress(done + 1);
        }
        let mean = swd_per_seed.iter().sum::<f64>() / swd_per_seed.len() as f64;
        Ok(SnapshotScore {
            folder: folder.to_path_buf(),
            step: provenance["step"].as_u64(),
            kimg: provenance["kimg"].as_f64(),
            swd_per_seed,
            mean,
        })
    }
}

/// Scores every model folder of `folders` on every seed of `settings`; a folder that cannot
/// be read or measured is reported in [`Scores::unscored`] and the others are still scored.
/// `progress` hears (folder index, seeds done of that folder) after each seed.
pub fn score_models(
    folders: &[PathBuf],
    settings: &ScoreSettings,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Scores> {
    if settings.seeds.is_empty() || settings.count == 0 {
        bail!("scoring snapshots needs at least one seed and one image per seed");
    }
    let scorer = Scorer::new(settings)?;
    let mut scores = Scores {
        scored: Vec::new(),
        unscored: Vec::new(),
    };
    for (index, folder) in folders.iter().enumerate() {
        match scorer.score(folder, &mut |done| progress(index, done)) {
            Ok(score) => scores.scored.push(score),
            Err(e) => scores.unscored.push(UnscoredFolder {
                folder: folder.clone(),
                error: format!("{e:#}"),
            }),
        }
    }
    Ok(scores)
}

/// The scores from the lowest mean SWD (the closest to the photos) to the highest, those
/// whose mean is not finite (a diverged snapshot) last.
pub fn ranked(mut scores: Vec<SnapshotScore>) -> Vec<SnapshotScore> {
    scores.sort_by(|a, b| {
        (!a.mean.is_finite())
            .cmp(&!b.mean.is_finite())
            .then(a.mean.total_cmp(&b.mean))
    });
    scores
}

#[cfg(test)]
mod tests {
    use super::*;

    fn score(step: u64, mean: f64) -> SnapshotScore {
        SnapshotScore {
            folder: PathBuf::from(format!("step-{step}")),
            step: Some(step),
            kimg: None,
            swd_per_seed: vec![mean],
            mean,
        }
    }

    #[test]
    fn ranked_orders_by_mean_with_non_finite_means_last() {
        let order: Vec<u64> = ranked(vec![
            score(1, f64::NAN),
            score(2, 90.0),
            score(3, -f64::NAN),
            score(4, 80.0),
            score(5, f64::INFINITY),
        ])
        .iter()
        .map(|s| s.step.unwrap())
        .collect();
        assert_eq!(&order[..2], [4, 2]);
        let mut tail = order[2..].to_vec();
        tail.sort();
        assert_eq!(tail, [1, 3, 5]);
    }

    #[test]
    fn kept_scores_are_read_back_only_for_the_same_weights() {
        let dir = tempfile::tempdir().unwrap();
        let mut kept = KeptScores {
            weights: content_hash(b"weights A"),
            swd: BTreeMap::new(),
        };
        kept.swd.insert("k".into(), 81.5);
        std::fs::write(
            dir.path().join(SCORES_FILE),
            serde_json::to_vec(&kept).unwrap(),
        )
        .unwrap();
        assert_eq!(
            kept_scores(dir.path(), &content_hash(b"weights A")).swd["k"],
            81.5
        );
        assert!(
            kept_scores(dir.path(), &content_hash(b"weights B"))
                .swd
                .is_empty()
        );
        // An unreadable file keeps nothing.
        std::fs::write(dir.path().join(SCORES_FILE), b"{not json").unwrap();
        assert!(
            kept_scores(dir.path(), &content_hash(b"weights A"))
                .swd
                .is_empty()
        );
    }
}
