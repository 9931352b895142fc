//! Procedural SVBRDF families: deterministic, tileable material maps generated from a seed.
//!
//! Each family writes the maps of one built-in model (named by [`Family::brdf`]) at any
//! resolution; all are exactly periodic on the unit square so they can be tiled and rolled.
//! A seed picks one member of the family (colours, scales, orientation); the same seed gives
//! the same material at every resolution, sampled at texel centres.
//!
//! | name            | model                       | imitates                                      |
//! |-----------------|-----------------------------|-----------------------------------------------|
//! | `brushed_metal` | `height(ggx, scale=0.01)`   | brushed aluminium, steel, titanium, brass, …  |
//! | `car_paint`     | `coated`                    | metallic, pearl and solid automotive paint    |
//! | `fabric`        | `height(ggx, scale=0.006)`  | plain, twill and satin weaves, denim          |
//! | `leather`       | `height(ggx, scale=0.004)`  | pebbled, dyed and finished leather            |
//! | `paint`         | `height(ggx, scale=0.006)`  | brushed house paint, matte to gloss           |
//! | `stone`         | `height(ggx, scale=0.01)`   | polished marble, granite, rough sandstone     |
//! | `tiles`         | `height(ggx, scale=0.01)`   | glazed ceramic tiles with grout               |
//! | `wood`          | `height(ggx, scale=0.003)`  | varnished boards and planks                   |
//!
//! (Scales are the defaults of each family's configuration.) [`families`] lists them all,
//! [`family`] finds one by name.

mod brushed_metal;
mod car_paint;
mod cellular;
mod common;
mod fabric;
mod leather;
pub(crate) mod noise;
mod paint;
mod stone;
mod tiles;
mod wood;

pub use brushed_metal::BrushedMetal;
pub use car_paint::CarPaint;
pub use cellular::{CellSample, PeriodicCells};
pub use fabric::Fabric;
pub use leather::Leather;
pub use noise::PeriodicNoise;
pub use paint::Paint;
pub use stone::Stone;
pub use tiles::GlazedTiles;
pub use wood::Wood;

use candle_core::Device;
use photomat_core::{Error, MaterialMaps, Result};

/// A family of procedural materials.
///
/// `Send + Sync` so a simulator can generate members on several threads.
pub trait Family: Send + Sync {
    /// The family's name, the stem of its source file (`wood`, `car_paint`, …).
    fn name(&self) -> &'static str;

    /// Canonical BRDF specification the maps are made for (e.g. `height(ggx, scale=0.02)`).
    fn brdf(&self) -> String;

    /// Maps (1, C, size, size), f32, for material number `seed` of the family.
    fn generate(&self, size: usize, seed: u64, device: &Device) -> Result<MaterialMaps>;
}

/// Every family with its default configuration, sorted by name.
pub fn families() -> Vec<Box<dyn Family>> {
    vec![
        Box::new(BrushedMetal::default()),
        Box::new(CarPaint::default()),
        Box::new(Fabric::default()),
        Box::new(Leather::default()),
        Box::new(Paint::default()),
        Box::new(Stone::default()),
        Box::new(GlazedTiles::default()),
        Box::new(Wood::default()),
    ]
}

/// Names of all families, sorted.
pub fn family_names() -> Vec<&'static str> {
    families().iter().map(|f| f.name()).collect()
}

/// The family called `name` with its default configuration, or an error listing the names.
pub fn family(name: &str) -> Result<Box<dyn Family>> {
    families()
        .into_iter()
        .find(|f| f.name() == name)
        .ok_or_else(|| {
            Error::Invalid(format!(
                "unknown material family '{name}'; families: {}",
                family_names().join(", ")
            ))
        })
}
