//! # photomat-data
//!
//! Everything between materials and the training loop: procedural SVBRDF families
//! ([`procedural`]), the ground truth that the phone-flash simulator ([`simulator`]) renders
//! and that the demo command shows without any trained model; prepared data sets
//! ([`dataset`], [`highlight`]); training crops ([`sampler`]) and native-scale patches
//! ([`patch`]); and [`source::DatasetSource`], a data set as the GAN trainer's
//! `TrainingData` (this crate implements the generator's trait); and the measures of a trained
//! GAN against a data set behind `photomat eval-gan` ([`gan_evaluation`]).

pub mod dataset;
pub mod discriminator_probe;
pub mod gan_evaluation;
pub mod highlight;
pub mod light_following;
pub mod patch;
pub mod procedural;
pub mod ranking;
pub mod relief_signature;
pub mod sampler;
pub mod simulator;
pub mod snapshots;
pub mod source;
