//! The resumable state of a training run, in the run folder:
//!
//! - [`STATE_FILE`] (`train_state.safetensors`): every variable a step reads or writes — G and
//!   M (`g.*`, `m.*`, including the `g.mapping.w_avg` buffer), G_ema (`g_ema.*`), D (`d.*`),
//!   both optimisers' moments and step counts (`opt_g.*`, `opt_d.*`,
//!   [`photomat_train::adam`]) and the trainer's counters (`trainer.counters` = [steps done,
//!   consecutive skipped steps]) — saved atomically with
//!   [`photomat_core::checkpoint::save_vars_atomic`];
//! - [`CONFIG_FILE`] (`train.json`): the full [`TrainConfig`].
//!
//! Every random draw of a step is a function of the run seed and the step
//! ([`super::streams`]), so these two files are all a run needs to continue bit-identically.
//! Loading refuses a state of another configuration naming the differing fields, and a state
//! file of another architecture naming the mismatching tensor
//! ([`photomat_core::checkpoint::load_vars_allowing_absent`]); nothing is modified when it
//! fails.
//!
//! A state may also be kept without the optimisers' moments ([`write_without_optimiser`]):
//! 45 % of the file, what a run committed to a repository to be continued elsewhere needs.
//! Resuming from it restores the networks and counters exactly and restarts both Adam
//! optimisers from zero moments, which is no longer bit-identical to the uninterrupted run.

use std::path::{Path, PathBuf};

use candle_core::Result;
use candle_nn::VarMap;
use photomat_core::image_io::write_atomic;

use super::config::{TrainConfig, config_differences};

/// The state file in a run folder.
pub const STATE_FILE: &str = "train_state.safetensors";
/// The configuration file in a run folder.
pub const CONFIG_FILE: &str = "train.json";

/// Name prefixes of the optimisers' tensors in [`STATE_FILE`].
pub const OPTIMISER_PREFIXES: [&str; 2] = ["opt_g.", "opt_d."];

/// What names M's relief projection in [`STATE_FILE`] (`m.relief.weight` and its moments).
const RELIEF_PARAMETER: &str = "m.relief.";

fn is_optimiser(name: &str) -> bool {
    OPTIMISER_PREFIXES.iter().any(|p| name.starts_with(p))
}

/// How [`load_state`] restored a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Restored {
    /// Every tensor, the optimisers' moments included: the run continues bit-identically.
    Exactly,
    /// The networks and counters; the state held no optimiser, so both restart from zero
    /// moments ([`write_without_optimiser`]).
    WithFreshOptimisers,
}

/// The per-step log in a run folder.
pub const LOG_FILE: &str = "log.csv";

/// Writes the run folder `run`'s state into `out` (created) without the optimisers' moments:
/// `train.json`, the state file less every `opt_g.*` / `opt_d.*` tensor, and the run's
/// `log.csv` as it is (when there is one). The model files (`gan.json`, `gan.safetensors`)
/// are left out: G_ema and M are in the state, and the resumed run's first checkpoint writes
/// them again. `photomat train-gan --out OUT --resume` continues it with fresh optimisers
/// ([`Restored::WithFreshOptimisers`]). Returns the bytes of the state file written.
pub fn write_without_optimiser(run: &Path, out: &Path) -> anyhow::Result<u64> {
    use anyhow::Context;
    read_config(run)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    photomat_core::checkpoint::copy_checkpoint_where(
        &run.join(STATE_FILE),
        &out.join(STATE_FILE),
        |name| !is_optimiser(name),
    )?;
    let copy = |name: &str| {
        let from = run.join(name);
        std::fs::copy(&from, out.join(name))
            .with_context(|| format!("cannot copy {} into {}", from.display(), out.display()))
    };
    copy(CONFIG_FILE)?;
    if run.join(LOG_FILE).exists() {
        copy(LOG_FILE)?;
    }
    Ok(std::fs::metadata(out.join(STATE_FILE))?.len())
}

/// Reads `dir/train.json`; errors name the file.
pub fn read_config(dir: &Path) -> Result<TrainConfig> {
    let path = dir.join(CONFIG_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| {
        candle_core::Error::msg(format!(
            "{}: cannot read the training configuration ({e}); is {} a `photomat train-gan` run folder?",
            path.display(),
            dir.display()
        ))
    })?;
    serde_json::from_str(&text).map_err(|e| {
        candle_core::Error::msg(format!(
            "{}: not a training configuration: {e}",
            path.display()
        ))
    })
}

/// Writes `dir/train.json` atomically.
pub fn write_config(dir: &Path, config: &TrainConfig) -> Result<()> {
    let json = serde_json::to_vec_pretty(config).map_err(candle_core::Error::wrap)?;
    write_atomic(&dir.join(CONFIG_FILE), &json).map_err(candle_core::Error::wrap)
}

/// Saves `state` and `config` into the run folder `dir` (created if missing): the state
/// file first, then the configuration, each atomically.
pub fn save_state(dir: &Path, state: &VarMap, config: &TrainConfig) -> Result<()> {
    std::fs::create_dir_all(dir)
        .map_err(|e| candle_core::Error::msg(format!("cannot create {}: {e}", dir.display())))?;
    photomat_core::checkpoint::save_vars_atomic(state, &dir.join(STATE_FILE))
        .map_err(candle_core::Error::wrap)?;
    write_config(dir, config)
}

/// Loads the run folder `dir` into `state`, after checking that its configuration is
/// `config` (up to [`TrainConfig::with_resume_changes`]); errors name the file and the
/// differing fields or tensors. A state file without any optimiser tensor loads the rest
/// ([`Restored::WithFreshOptimisers`]); one with only part of them is an error, before
/// anything is loaded.
pub fn load_state(dir: &Path, state: &VarMap, config: &TrainConfig) -> Result<Restored> {
    let saved = read_config(dir)?;
    // The data set's place, the learning rate and the cadence may change on resume.
    let mut relocated = saved.with_resume_changes(config);
    // A spatial run saved before texel sizes were recorded takes the one its data gives
    // (`RunPlan::bind_data` checks it against the data set).
    if let (Some(saved), Some(requested)) = (
        relocated.generator.spatial.as_mut(),
        config.generator.spatial.as_ref(),
    ) && saved.texel_size.is_none()
    {
        saved.texel_size = requested.texel_size;
    }
    let diffs = config_differences(&relocated, config);
    if !diffs.is_empty() {
        candle_core::bail!(
            "{}: the run was made with another configuration (saved ≠ requested): {}",
            dir.join(CONFIG_FILE).display(),
            diffs.join("; ")
        );
    }
    let path: PathBuf = dir.join(STATE_FILE);
    // Relief switched on at this resume: its projection (and its moments) are not in the file
    // and keep their zero start.
    let relief_added = config.generator.relief && !saved.generator.relief;
    let optimisers_absent =
        photomat_core::checkpoint::load_vars_allowing_new(state, &path, is_optimiser, |name| {
            relief_added && name.contains(RELIEF_PARAMETER)
        })
        .map_err(candle_core::Error::wrap)?;
    Ok(if optimisers_absent {
        Restored::WithFreshOptimisers
    } else {
        Restored::Exactly
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{GeneratorConfig, SpatialConfig};

    fn spatial(texel_size: Option<f64>, local_dim: usize) -> TrainConfig {
        let generator = GeneratorConfig {
            resolution: 32,
            tileable: true,
            spatial: Some(SpatialConfig {
                local_dim,
                texel_size,
                ..SpatialConfig::default()
            }),
            ..GeneratorConfig::default()
        };
        TrainConfig::new(generator, PathBuf::from("data"), 4, 1)
    }

    #[test]
    fn a_run_saved_without_texel_size_resumes_with_the_datas() {
        let dir = tempfile::tempdir().unwrap();
        save_state(dir.path(), &VarMap::new(), &spatial(None, 8)).unwrap();
        load_state(dir.path(), &VarMap::new(), &spatial(Some(1.0 / 256.0), 8)).unwrap();
        // Any other difference is still refused.
        let err = load_state(dir.path(), &VarMap::new(), &spatial(Some(1.0 / 256.0), 16))
            .unwrap_err()
            .to_string();
        assert!(err.contains("local_dim"), "{err}");
        // And a recorded texel size must match.
        save_state(dir.path(), &VarMap::new(), &spatial(Some(1.0 / 128.0), 8)).unwrap();
        let err = load_state(dir.path(), &VarMap::new(), &spatial(Some(1.0 / 256.0), 8))
            .unwrap_err()
            .to_string();
        assert!(err.contains("texel_size"), "{err}");
    }
}
