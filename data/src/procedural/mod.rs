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
//!
//! A family is one file: a configuration struct, the member a seed draws (a [`Pattern`] of
//! texture coordinates, [`common`]) and one `PatternFamily` impl giving its name, its BRDF and
//! how a seed draws a member; [`Family`] follows from that impl, and the family's entry in
//! [`families`] makes it known to the simulator and the CLI.

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

use common::Pattern;

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

    /// What material number `seed` is, when the family can say more than its seed (a
    /// material library's family: which material, seen how), for the photo's record.
    fn describe(&self, _seed: u64) -> Option<String> {
        None
    }
}

/// A family whose members are [`Pattern`]s drawn from a seed, which is how every built-in
/// family is written: [`Family`] follows from it, its maps being the member sampled at the
/// texel centres ([`common::sample_maps`]).
pub(crate) trait PatternFamily: Send + Sync {
    /// The family's name ([`Family::name`]).
    const NAME: &'static str;
    /// What one seed draws: a material as a function of texture coordinates.
    type Member: Pattern;

    /// Canonical BRDF specification the maps are made for ([`Family::brdf`]).
    fn brdf(&self) -> String;

    /// Member number `seed` of the family (colours, scales, orientation).
    fn member(&self, seed: u64) -> Self::Member;
}

impl<F: PatternFamily> Family for F {
    fn name(&self) -> &'static str {
        F::NAME
    }

    fn brdf(&self) -> String {
        PatternFamily::brdf(self)
    }

    fn generate(&self, size: usize, seed: u64, device: &Device) -> Result<MaterialMaps> {
        common::sample_maps(&self.member(seed), size, device)
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use common::testing::assert_periodic;

    /// Members of `family` for seeds 0..8 are periodic with period 1 in u and v.
    fn assert_members_periodic<F: PatternFamily>(family: F) {
        for seed in 0..8 {
            assert_periodic(&family.member(seed));
        }
    }

    #[test]
    fn every_family_is_periodic() {
        assert_members_periodic(BrushedMetal::default());
        assert_members_periodic(CarPaint::default());
        assert_members_periodic(Fabric::default());
        assert_members_periodic(Leather::default());
        assert_members_periodic(Paint::default());
        assert_members_periodic(Stone::default());
        assert_members_periodic(GlazedTiles::default());
        assert_members_periodic(Wood::default());
    }
}
