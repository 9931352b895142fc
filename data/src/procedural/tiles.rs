//! Glazed ceramic tiles with grout: a square grid of glossy tiles, each with its own glaze
//! colour, bevelled edges and faint waviness, set in rough, recessed grout.
//!
//! Maps for `height(ggx)`: diffuse, specular, roughness, height. Exactly periodic on the unit
//! square (integer tile count, periodic noise), so the material tiles seamlessly.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::common::{GgxTexel, Pattern, smoothstep, wrap01};
use super::noise::PeriodicNoise;

/// Configuration of the tile family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct GlazedTiles {
    /// Tiles along each side of the material square (default 4).
    pub tiles_per_side: u32,
    /// Grout width as a fraction of one tile (default 0.08).
    pub grout_width: f64,
    /// Width of the bevel at each tile edge, fraction of a tile (default 0.05).
    pub bevel_width: f64,
    /// World-space height of the height map's full range (default 0.01 = 1 % of the width).
    pub relief: f64,
}

impl Default for GlazedTiles {
    fn default() -> Self {
        Self {
            tiles_per_side: 4,
            grout_width: 0.08,
            bevel_width: 0.05,
            relief: 0.01,
        }
    }
}

/// One member of the family.
pub(crate) struct Tiling {
    config: GlazedTiles,
    n: usize,
    tile_colour: Vec<[f64; 3]>,
    grout_grey: f64,
    noise: PeriodicNoise,
}

impl PatternFamily for GlazedTiles {
    const NAME: &'static str = "tiles";
    type Member = Tiling;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Tiling {
        let n = self.tiles_per_side.max(1) as usize;
        let mut rng = StdRng::seed_from_u64(seed);
        // One glaze per family member, jittered per tile.
        let base = [
            rng.random_range(0.05..0.8),
            rng.random_range(0.05..0.8),
            rng.random_range(0.05..0.8),
        ];
        let tile_colour: Vec<[f64; 3]> = (0..n * n)
            .map(|_| {
                let k: f64 = rng.random_range(0.8..1.2);
                // 0.8 · 1.2 < 1: the clamp never binds, it documents the albedo range.
                base.map(|c: f64| (c * k).clamp(0.0, 1.0))
            })
            .collect();
        let grout_grey: f64 = rng.random_range(0.25..0.6);
        Tiling {
            config: self.clone(),
            n,
            tile_colour,
            grout_grey,
            noise: PeriodicNoise::new(seed.wrapping_mul(0x9E37_79B9)),
        }
    }
}

impl Pattern for Tiling {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        let n = self.n;
        let (tu, tv) = (u * n as f64, v * n as f64);
        let (ti, tj) = (
            tv.floor().rem_euclid(n as f64) as usize,
            tu.floor().rem_euclid(n as f64) as usize,
        );
        let (fu, fv) = (wrap01(tu), wrap01(tv));
        let edge = fu.min(1.0 - fu).min(fv).min(1.0 - fv); // distance to the tile border
        let half_grout = self.config.grout_width / 2.0;
        let on_tile = smoothstep(half_grout, half_grout + self.config.bevel_width, edge);
        let grain = self.noise.fbm(u, v, 8, 4);
        let wave = self.noise.fbm(u, v, 2, 2);
        let colour = self.tile_colour[ti * n + tj];
        let grout = self.grout_grey * (1.0 + 0.25 * grain);
        let diffuse = colour.map(|c| {
            let tile = c * (1.0 + 0.08 * grain);
            grout + (tile - grout) * on_tile
        });
        GgxTexel {
            diffuse,
            specular: [0.02 + 0.03 * on_tile; 3],
            roughness: 0.85 + (0.15 + 0.05 * grain - 0.85) * on_tile,
            height: 0.3 + 0.05 * grain + on_tile * (0.55 + 0.05 * wave),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::Family;
    use candle_core::{Device, Tensor};
    use photomat_brdfs as _;
    use photomat_core::MaterialMaps;

    fn maps(seed: u64) -> MaterialMaps {
        GlazedTiles::default()
            .generate(64, seed, &Device::Cpu)
            .unwrap()
    }

    fn flat(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1().unwrap()
    }

    #[test]
    fn tiles_validate_for_their_brdf_and_are_deterministic() {
        let family = GlazedTiles::default();
        let brdf = photomat_core::lookup(&Family::brdf(&family)).unwrap();
        let a = maps(3);
        a.validate(&brdf.name(), brdf.params()).unwrap();
        for (name, t) in a.iter() {
            assert_eq!(
                flat(t),
                flat(maps(3).get(name).unwrap()),
                "{name} not deterministic"
            );
        }
        assert_ne!(
            flat(a.get("diffuse").unwrap()),
            flat(maps(4).get("diffuse").unwrap())
        );
    }

    #[test]
    fn tiles_are_seamless_across_the_wrap() {
        // The jump between the last and first column/row is no larger than the largest jump
        // between neighbouring interior columns/rows: no seam.
        for (name, t) in maps(5).iter() {
            let t = t.squeeze(0).unwrap();
            for dim in [1, 2] {
                let len = t.dim(dim).unwrap();
                let step = |a: usize, b: usize| {
                    let d = (t.narrow(dim, a, 1).unwrap() - t.narrow(dim, b, 1).unwrap()).unwrap();
                    flat(&d.abs().unwrap()).into_iter().fold(0f32, f32::max)
                };
                let interior = (0..len - 1).map(|i| step(i, i + 1)).fold(0f32, f32::max);
                assert!(
                    step(len - 1, 0) <= interior + 1e-6,
                    "{name}: seam along dim {dim}"
                );
            }
        }
    }
}
