//! Picking a GAN run's model among its snapshots, by measuring them.
//!
//! A GAN trained on these CPUs does not improve steadily: the bundled recipe's SWD swings by
//! ±25 % between snapshots a thousand steps apart, and one `eval-gan` seed is noisy as well
//! (the two seeds of one model differ by up to 40 %; docs/benchmarks.md, "Picking a snapshot").
//! So a run keeps snapshots of G_ema + M (`train-gan --snapshot-every`,
//! [`Cadence::snapshot_every`](photomat_generator::train::Cadence)) and this module scores
//! each on several seeds of the SWD against the run's data set ([`model_swd`], the figure
//! `eval-gan` reports for a seed: relit native-scale windows against real patches, ProGAN's
//! sliced Wasserstein distance), then ranks them by the mean over the seeds.
//!
//! Each measurement is kept in the model folder ([`SCORES_FILE`], keyed by data set, count and
//! seed, and valid while the folder's weights file is unchanged), so ranking again as a run
//! adds snapshots, with more seeds, or after an interruption measures only what is new.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use candle_core::{Device, Result, bail};
use photomat_core::image_io::write_atomic;
use photomat_core::paths::absolute;
use photomat_generator::GanModel;
use photomat_generator::model_files::{GAN_MANIFEST_FILE, GAN_WEIGHTS_FILE, read_gan_manifest};
use photomat_generator::swd::{FakeWindows, SwdConfig, model_swd};
use photomat_generator::train::SNAPSHOTS_DIR;
use serde::{Deserialize, Serialize};

use crate::source::DatasetSource;

/// The file in a model folder that keeps the SWDs measured of it.
pub const SCORES_FILE: &str = "swd_scores.json";

/// The measurements kept in a model folder: SWD ×10³ by [`score_key`], for the weights file
/// whose [`weights_fingerprint`] is `weights`.
#[derive(Debug, Default, Serialize, Deserialize)]
struct KeptScores {
    weights: String,
    swd: BTreeMap<String, f64>,
}

/// The key of one measurement: the data set (as an absolute path), the count and the seed.
fn score_key(data: &Path, count: usize, seed: u64) -> String {
    format!("{}|count={count}|seed={seed}", absolute(data).display())
}

/// Length and modification time of the folder's weights file: a rewritten snapshot (a run
/// resumed from an earlier checkpoint with other settings) invalidates what was kept.
fn weights_fingerprint(folder: &Path) -> Result<String> {
    let path = folder.join(GAN_WEIGHTS_FILE);
    let meta = std::fs::metadata(&path)
        .map_err(|e| candle_core::Error::msg(format!("{}: {e}", path.display())))?;
    let modified = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    Ok(format!("{} bytes, modified {modified} ns", meta.len()))
}

/// What `folder` keeps for its current weights (nothing if the file is missing, unreadable or
/// for other weights).
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

/// The snapshot folders of the run folder `run` (`snapshots/step-NNNNNN/` holding a
/// gan.json), in the order of their steps.
pub fn run_snapshots(run: &Path) -> Result<Vec<PathBuf>> {
    let dir = run.join(SNAPSHOTS_DIR);
    let entries = std::fs::read_dir(&dir).map_err(|e| {
        candle_core::Error::msg(format!(
            "{}: cannot list the run's snapshots ({e}); train with --snapshot-every N to keep \
             them",
            dir.display()
        ))
    })?;
    let mut found = Vec::new();
    for entry in entries {
        let path = entry.map_err(candle_core::Error::wrap)?.path();
        let step = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("step-"))
            .and_then(|n| n.parse::<u64>().ok());
        if let Some(step) = step
            && path.join(GAN_MANIFEST_FILE).is_file()
        {
            found.push((step, path));
        }
    }
    if found.is_empty() {
        bail!(
            "{}: no snapshot folders (step-NNNNNN/gan.json)",
            dir.display()
        );
    }
    found.sort();
    Ok(found.into_iter().map(|(_, path)| path).collect())
}

/// Scores every model folder of `folders` on every seed of `settings`; `progress` hears
/// (model index, seeds done of that model) after each measurement.
pub fn score_models(
    folders: &[PathBuf],
    settings: &ScoreSettings,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<SnapshotScore>> {
    if settings.seeds.is_empty() || settings.count == 0 {
        bail!("scoring snapshots needs at least one seed and one image per seed");
    }
    let device = Device::Cpu;
    folders
        .iter()
        .enumerate()
        .map(|(index, folder)| {
            let in_folder = |e: candle_core::Error| e.context(format!("{}", folder.display()));
            let model = GanModel::load(folder, &device).map_err(in_folder)?;
            let provenance = read_gan_manifest(folder).map_err(in_folder)?.provenance;
            let data = DatasetSource::for_model(&settings.data, model.config())?;
            let weights = weights_fingerprint(folder)?;
            let mut kept = kept_scores(folder, &weights);
            let mut swd_per_seed = Vec::with_capacity(settings.seeds.len());
            for (done, &seed) in settings.seeds.iter().enumerate() {
                let key = score_key(&settings.data, settings.count, seed);
                let swd = match kept.swd.get(&key) {
                    Some(&swd) => swd,
                    None => {
                        let swd = model_swd(
                            &model,
                            &data,
                            settings.count,
                            seed,
                            FakeWindows::Native,
                            &SwdConfig::default(),
                            &mut |_, _| {},
                        )
                        .map_err(in_folder)?
                        .mean;
                        kept.swd.insert(key, swd);
                        let text = serde_json::to_string_pretty(&kept)
                            .map_err(candle_core::Error::wrap)?;
                        let path = folder.join(SCORES_FILE);
                        write_atomic(&path, text.as_bytes()).map_err(|e| {
                            candle_core::Error::msg(format!("cannot write {}: {e}", path.display()))
                        })?;
                        swd
                    }
                };
                swd_per_seed.push(swd);
                progress(index, done + 1);
            }
            let mean = swd_per_seed.iter().sum::<f64>() / swd_per_seed.len() as f64;
            Ok(SnapshotScore {
                folder: folder.clone(),
                step: provenance["step"].as_u64(),
                kimg: provenance["kimg"].as_f64(),
                swd_per_seed,
                mean,
            })
        })
        .collect()
}

/// The scores from the lowest mean SWD (the closest to the photos) to the highest.
pub fn ranked(mut scores: Vec<SnapshotScore>) -> Vec<SnapshotScore> {
    scores.sort_by(|a, b| a.mean.total_cmp(&b.mean));
    scores
}
