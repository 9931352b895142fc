//! What an estimator training run keeps on disk, besides the model folder itself
//! ([`crate::EstimatorModel`] + the copied GAN files): the resumable training state.
//!
//! - [`TRAIN_STATE_FILE`] (`train_state.safetensors`): E's parameters under `e.`, the Adam
//!   state under `adam.` (`adam.step`, `adam.m.<name>`, `adam.v.<name>`; see
//!   `photomat_train::adam`), the number of steps done `train.step` and the stage
//!   whose optimiser the moments belong to `train.adam_stage` (0 aligned, 1 fine-tune), in
//!   one file written atomically, so weights, moments and counters always agree;
//! - [`TRAIN_MANIFEST_FILE`] (`train.json`): the [`TrainConfig`], BRDF, architecture and the
//!   GAN folder the run was started with, checked by `--resume`.
//!
//! A run folder is also a complete model folder at all times: the GAN's `gan.json` and
//! `gan.safetensors` are copied in at the start ([`copy_gan_model`]) and E is saved at every
//! checkpoint.

use std::path::{Path, PathBuf};

use photomat_core::image_io::write_atomic;
use photomat_core::{Error, Result};
pub use photomat_generator::model_files::copy_gan_model;
use serde::{Deserialize, Serialize};

use super::config::TrainConfig;
use crate::EstimatorConfig;

/// Resumable training state of a run folder.
pub const TRAIN_STATE_FILE: &str = "train_state.safetensors";
/// Settings of a run folder.
pub const TRAIN_MANIFEST_FILE: &str = "train.json";

/// Contents of `train.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainManifest {
    /// Canonical spec of the BRDF model E decodes into.
    pub brdf: String,
    /// E's architecture.
    pub architecture: EstimatorConfig,
    /// The training settings.
    pub config: TrainConfig,
    /// The GAN model folder the run was started from.
    pub gan: PathBuf,
    /// Steps done when the state was saved (informative: the state file is authoritative).
    pub step: u64,
}

impl TrainManifest {
    /// Writes `dir/train.json` atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let json = serde_json::to_vec_pretty(self)
            .map_err(|e| Error::Invalid(format!("training manifest: {e}")))?;
        write_atomic(&dir.join(TRAIN_MANIFEST_FILE), &json)
    }

    /// Reads `dir/train.json`; errors name the file.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join(TRAIN_MANIFEST_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            Error::file(
                &path,
                format!("cannot read the training manifest ({e}); nothing to resume here"),
            )
        })?;
        serde_json::from_str(&text)
            .map_err(|e| Error::file(&path, format!("not a training manifest: {e}")))
    }
}
