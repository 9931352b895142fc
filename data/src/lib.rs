//! # photomat-data
//!
//! Everything between materials and the training loop. For now: procedural SVBRDF families
//! ([`procedural`]), the ground truth that the phone-flash simulator renders and that the
//! demo command shows without any trained model.

pub mod dataset;
pub mod highlight;
pub mod procedural;
pub mod sampler;
pub mod simulator;
