//! Procedural SVBRDF families: deterministic, tileable material maps generated from a seed.
//!
//! Each family writes the maps of one built-in model (named by [`Family::brdf`]) at any
//! resolution; all are exactly periodic on the unit square so they can be tiled and rolled.

mod noise;
mod tiles;

pub use noise::PeriodicNoise;
pub use tiles::GlazedTiles;

use candle_core::Device;
use photomat_core::{MaterialMaps, Result};

/// A family of procedural materials.
pub trait Family {
    /// Canonical BRDF specification the maps are made for (e.g. `height(ggx, scale=0.02)`).
    fn brdf(&self) -> String;

    /// Maps (1, C, size, size), f32, for material number `seed` of the family.
    fn generate(&self, size: usize, seed: u64, device: &Device) -> Result<MaterialMaps>;
}
