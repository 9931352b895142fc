//! GAN training of G, M and D (PhotoMat §3–4, StyleGAN2-ADA's training loop; docs/conventions.md), one
//! concept per module:
//!
//! - [`config`]: [`TrainConfig`], the run's `train.json`, with the reference defaults;
//! - [`settings`]: [`GanSettings`], the flags of a run, and how they merge with the defaults
//!   or a resumed run's `train.json`;
//! - [`streams`]: per-step seeds of every random draw (reproducible, resumable runs);
//! - [`data`]: [`TrainingData`], the real crops or patches and the fakes' light placements
//!   (implemented over a prepared data set by the data crate);
//! - [`loss`]: non-saturating logistic losses and the lazy R1 penalty;
//! - [`path_length`]: StyleGAN2's optional path-length regularisation of G;
//! - [`ema`]: the moving average G_ema of G;
//! - [`state`]: `train_state.safetensors` + `train.json`, atomic saves and checked resumes;
//! - [`trainer`]: [`Trainer`], one training step;
//! - [`samples`]: the progress sample grids;
//! - [`log`]: the columns of the run's `log.csv`.
//!
//! Adam, the NaN guard, the per-sample rolls and the state-map helpers are the training layer
//! shared with the estimator (`photomat-train`).

pub mod config;
pub mod data;
pub mod driver;
pub mod ema;
pub mod log;
pub mod loss;
pub mod path_length;
pub mod samples;
pub mod settings;
pub mod state;
pub mod streams;
pub mod trainer;

pub use config::{Cadence, PatchTraining, TrainConfig};
pub use data::{FlashPlacement, RealBatch, TrainingData};
pub use driver::{
    GanEvent, GanOutcome, GanTraining, RunLength, RunPlan, SNAPSHOTS_DIR, snapshot_folder,
    snapshot_folders,
};
pub use settings::{GanSettings, Lobes};
pub use trainer::{PhaseSeconds, StepStats, Trainer, fresh_discriminator};
