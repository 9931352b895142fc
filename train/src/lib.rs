//! # photomat-train
//!
//! The training utilities that the GAN trainer (`photomat-generator`) and the estimator
//! trainer (`photomat-estimator`) share, one concept per module:
//!
//! - [`adam`]: Adam (Kingma & Ba 2015, PyTorch's update) over named variables, with its state
//!   in a [`candle_nn::VarMap`] so that resumed runs are bit-identical, and StyleGAN2's
//!   lazy-regularisation correction;
//! - [`nan_guard`]: skipping updates whose loss or gradient is not finite, and stopping a run
//!   after repeated skips with an error naming the step and the loss;
//! - [`roll`]: per-sample wrap-around rolls of NCHW tensors and material maps (tileable
//!   training, the estimator's fine-tune);
//! - [`run_folder`]: the fresh-or-resumed check every trainer makes of its run folder;
//! - [`run_log`]: a run's `log.csv`, appended row by row and cut back to the checkpoint when
//!   the run resumes;
//! - [`settings`]: the one rule by which a trainer's given settings meet its defaults (fresh
//!   run) or its saved `train.json` (resumed run: fixed settings refused, the others noted);
//! - [`varmap`]: the [`candle_nn::VarMap`] plumbing both trainers need to gather their
//!   variables into one training-state file.
//!
//! The seeded random generator both trainers draw from is not here but in `photomat-core`
//! ([`photomat_core::rng`]): the data, export and kernels crates use it too, and none of them
//! trains anything; core is the crate they all already depend on.

pub mod adam;
pub mod nan_guard;
pub mod roll;
pub mod run_folder;
pub mod run_log;
pub mod settings;
pub mod varmap;

pub use adam::{Adam, AdamConfig};
pub use nan_guard::{NanGuard, gradients_finite};
pub use roll::{roll_maps, roll_offsets, roll_per_sample, window_per_sample};
pub use run_folder::check_run_folder;
pub use run_log::RunLog;
pub use settings::{Merged, OnResume, Setting, merge};
