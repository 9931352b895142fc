//! Glazed ceramic tiles with grout: a square grid of glossy tiles, each with its own glaze
//! colour, bevelled edges and faint waviness, set in rough, recessed grout.
//!
//! Maps for `height(ggx)`: diffuse, specular, roughness, height. Exactly periodic on the unit
//! square (integer tile count, periodic noise), so the material tiles seamlessly.

use candle_core::{Device, Tensor};
use photomat_core::{MaterialMaps, Result};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::Family;
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

/// Hermite smoothstep on [e0, e1].
fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl Family for GlazedTiles {
    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn generate(&self, size: usize, seed: u64, device: &Device) -> Result<MaterialMaps> {
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
                base.map(|c: f64| (c * k).clamp(0.0, 1.0))
            })
            .collect();
        let grout_grey: f64 = rng.random_range(0.25..0.6);
        let noise = PeriodicNoise::new(seed.wrapping_mul(0x9E37_79B9));

        let plane = size * size;
        let (mut diffuse, mut specular) = (vec![0f32; 3 * plane], vec![0f32; 3 * plane]);
        let (mut roughness, mut height) = (vec![0f32; plane], vec![0f32; plane]);
        for row in 0..size {
            for col in 0..size {
                // Texture coordinates of the texel centre, u right, v down, in [0, 1).
                let (u, v) = (
                    (col as f64 + 0.5) / size as f64,
                    (row as f64 + 0.5) / size as f64,
                );
                let (tu, tv) = (u * n as f64, v * n as f64);
                let (ti, tj) = (tv.floor() as usize % n, tu.floor() as usize % n);
                let (fu, fv) = (tu.fract(), tv.fract());
                let edge = fu.min(1.0 - fu).min(fv).min(1.0 - fv); // distance to the tile border
                let half_grout = self.grout_width / 2.0;
                let on_tile = smoothstep(half_grout, half_grout + self.bevel_width, edge);
                let grain = noise.fbm(u, v, 8, 4);
                let wave = noise.fbm(u, v, 2, 2);
                let t = row * size + col;
                let colour = tile_colour[ti * n + tj];
                for c in 0..3 {
                    let tile = colour[c] * (1.0 + 0.08 * grain);
                    let grout = grout_grey * (1.0 + 0.25 * grain);
                    diffuse[c * plane + t] =
                        (grout + (tile - grout) * on_tile).clamp(0.0, 1.0) as f32;
                    specular[c * plane + t] = (0.02 + 0.03 * on_tile) as f32;
                }
                roughness[t] =
                    (0.85 + (0.15 + 0.05 * grain - 0.85) * on_tile).clamp(0.0, 1.0) as f32;
                let h = 0.3 + 0.05 * grain + on_tile * (0.55 + 0.05 * wave);
                height[t] = h.clamp(0.0, 1.0) as f32;
            }
        }
        let map = |data: Vec<f32>, c: usize| Tensor::from_vec(data, (1, c, size, size), device);
        Ok(MaterialMaps::new()
            .with("diffuse", map(diffuse, 3)?)
            .with("specular", map(specular, 3)?)
            .with("roughness", map(roughness, 1)?)
            .with("height", map(height, 1)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photomat_brdfs as _;

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
        let brdf = photomat_core::lookup(&family.brdf()).unwrap();
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
