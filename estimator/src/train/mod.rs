//! Training of the map estimator E against a frozen relightable generator (PhotoMat §3
//! "Material map estimator", §4 "Implementation"; reference facts in `docs/neural-models.md`,
//! "Training E").
//!
//! - [`config`]: [`TrainConfig`] (stages, Adam, loss weights, seeds) and [`Stage`];
//! - [`draws`]: the seeded per-step materials, lights and rolls ([`StepDraws`]);
//! - [`objective`]: the loss of one batch (render of E's maps vs M's relighting);
//! - [`settings`]: [`EstimatorSettings`], the flags of a run, and how they merge with the
//!   defaults or a resumed run's `train.json`;
//! - [`state`]: the run folder's resumable state and the GAN copy;
//! - [`trainer`]: [`EstimatorTrainer`], one run step by step, checkpoint and resume.
//!
//! Adam, the NaN guard, the fine-tune's per-sample rolls and the state-map helpers are the
//! training layer shared with the GAN trainer (`photomat-train`).

pub mod config;
pub mod draws;
pub mod driver;
pub mod objective;
pub mod settings;
pub mod state;
pub mod trainer;

pub use config::{Cadence, Stage, TrainConfig};
pub use draws::StepDraws;
pub use driver::{EstimatorOutcome, EstimatorTraining, LOG_FILE};
pub use objective::{LossTerms, Objective};
pub use settings::EstimatorSettings;
pub use state::{TRAIN_MANIFEST_FILE, TRAIN_STATE_FILE, TrainManifest, copy_gan_model};
pub use trainer::{EstimatorTrainer, Preview, StepReport};
