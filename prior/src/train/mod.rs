//! Training of the relief prior on photos of the material library rendered on the fly
//! (docs/neural-models.md, "Relief prior"):
//!
//! - [`settings`]: [`PriorSettings`], the flags, and `train.json`;
//! - [`draws`]: the examples, library materials photographed by the simulator's phone;
//! - [`objective`]: the per-map, normal and rendering losses;
//! - [`trainer`]: [`PriorTrainer`], one step, the validation score, the resumable state;
//! - [`driver`]: [`PriorTraining`], the run folder and its cadence of outputs.
//!
//! Adam, the NaN guard, the run log and the settings' merge rule are the training layer all
//! trainers share (`photomat-train`).

pub mod draws;
pub mod driver;
pub mod objective;
pub mod settings;
pub mod trainer;

pub use driver::{PriorEvent, PriorOutcome, PriorTraining};
pub use settings::{PriorSettings, PriorTrainConfig};
pub use trainer::{PriorTrainer, StepReport, ValidationScore};
