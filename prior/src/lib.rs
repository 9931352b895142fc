//! # photomat-prior
//!
//! The relief prior: a network from one flash photo to a model's maps, trained on flash photos
//! of the material library rendered on the fly, so that a capture starts from the relief and
//! colour that artist-made materials have instead of constant maps (docs/neural-models.md,
//! "Relief prior"; docs/capture.md, "Starting from the prior"). It follows the supervised
//! single-image capture of Deschaintre et al. 2018 (a UNet trained with per-map and rendering
//! losses on synthetic photos of artist-made SVBRDFs), with separate decoders for the colour
//! maps and the relief.
//!
//! - [`network`]: [`PriorNet`], one encoder and two decoders (colour, relief);
//! - [`input`]: the photo as the network reads it (linear, exposure divided out, offsets from
//!   the flash);
//! - [`maps`]: its outputs as a model's maps (the relief as a height of fitted scale, or
//!   normals);
//! - [`model_files`]: [`PriorModel`] on disk, and finding a model folder's prior;
//! - [`train`]: the trainer behind `photomat train-prior`.

pub mod input;
pub mod maps;
pub mod model_files;
pub mod network;
pub mod train;

pub use model_files::{PriorMaps, PriorModel, find_prior};
pub use network::{PriorConfig, PriorNet};
