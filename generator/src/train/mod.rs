//! GAN training of G, M and D (PhotoMat §3–4, StyleGAN2-ADA's training loop; DESIGN §4), one
//! concept per module:
//!
//! - [`adam`]: Adam over named variables with checkpointable state and the
//!   lazy-regularisation correction (also used by the estimator's trainer);
//! - [`config`]: [`TrainConfig`], the run's `train.json`, with the reference defaults;
//! - [`streams`]: per-step seeds of every random draw (reproducible, resumable runs);
//! - [`data`]: [`TrainingData`], the real crops and fake lights, over a prepared data set;
//! - [`loss`]: non-saturating logistic losses and the lazy R1 penalty;
//! - [`path_length`]: StyleGAN2's optional path-length regularisation of G;
//! - [`roll`]: random per-sample roll of F in tileable mode;
//! - [`ema`]: the moving average G_ema of G;
//! - [`nan_guard`]: skipping non-finite updates, stopping a diverged run;
//! - [`state`]: `train_state.safetensors` + `train.json`, atomic saves and checked resumes;
//! - [`trainer`]: [`Trainer`], one training step;
//! - [`samples`]: the progress sample grids;
//! - [`log`]: the run's `log.csv`.

pub mod adam;
pub mod config;
pub mod data;
pub mod driver;
pub mod ema;
pub mod log;
pub mod loss;
pub mod nan_guard;
pub mod path_length;
pub mod roll;
pub mod samples;
pub mod state;
pub mod streams;
pub mod trainer;

pub use adam::{Adam, AdamConfig};
pub use config::TrainConfig;
pub use data::{DatasetSource, RealBatch, TrainingData};
pub use driver::{Cadence, GanEvent, GanOutcome, GanSettings, GanTraining, RunLength, RunPlan};
pub use trainer::{PhaseSeconds, StepStats, Trainer, enable_second_order_gradients};
