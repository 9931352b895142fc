//! Leather: a pebbled grain of rounded cells separated by fine creases, with a few long
//! fold wrinkles, dyed and finished to a semi-gloss.
//!
//! Imitates full-grain and corrected-grain upholstery and bag leather. The grain is periodic
//! Worley noise over slightly warped coordinates: each cell is a dome (height rising with
//! the distance to the cell border), the borders are creases where the dye pools darker and
//! the finish is rougher. Fold wrinkles are thin grooves around the zero set of a
//! low-frequency fBm, elongated along one direction. The finish is a dielectric lacquer,
//! grey F0 0.035-0.05, roughness from glossy patent-like to matte nubuck-like (0.3-0.7).
//!
//! Maps for `height(ggx, scale=relief)`: diffuse, specular, roughness, height.
//! Per seed: dye colour (black, browns, tan, cognac, burgundy, navy, olive, grey; jittered),
//! grain size and irregularity, crease width and depth, wrinkle strength and direction,
//! finish roughness, mottling.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::cellular::{CellSample, PeriodicCells};
use super::common::{GgxTexel, Pattern, Symmetry, counts, jitter, scale, smoothstep, srgb};
use super::noise::PeriodicNoise;

/// Configuration of the leather family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct Leather {
    /// World-space height of the height map's full range (default 0.004: pebbles a fraction
    /// of a millimetre tall on a 10 cm swatch, enough to catch the flash at their rims).
    pub relief: f64,
    /// Grain cells per unit along each side, least and most (default 18, 44).
    pub cells: (u32, u32),
}

impl Default for Leather {
    fn default() -> Self {
        Self {
            relief: 0.004,
            cells: (18, 44),
        }
    }
}

/// sRGB dye colours: black, dark brown, brown, tan, cognac, burgundy, navy, olive, grey.
const DYES: [[f64; 3]; 9] = [
    [0.10, 0.09, 0.09],
    [0.24, 0.15, 0.10],
    [0.40, 0.25, 0.15],
    [0.68, 0.50, 0.33],
    [0.58, 0.32, 0.16],
    [0.36, 0.09, 0.11],
    [0.13, 0.16, 0.27],
    [0.33, 0.34, 0.20],
    [0.45, 0.45, 0.45],
];

/// One member of the family.
pub(crate) struct Hide {
    dye: [f64; 3],
    cells: PeriodicCells,
    period: u32,
    /// Coordinate warp of the grain, in cells (irregular cell shapes).
    warp: f64,
    /// Half-width of a crease, in cells.
    crease: f64,
    /// Wrinkle depth (0: none).
    wrinkles: f64,
    /// Wrinkles run along x in pattern coordinates; the symmetry orients them.
    symmetry: Symmetry,
    gloss: f64,
    f0: f64,
    mottling: f64,
    noise: [PeriodicNoise; 3],
}

impl PatternFamily for Leather {
    const NAME: &'static str = "leather";
    type Member = Hide;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Hide {
        let mut rng = StdRng::seed_from_u64(seed);
        let dye = DYES[rng.random_range(0..DYES.len())];
        Hide {
            dye: srgb(jitter(&mut rng, dye, 0.08)),
            cells: PeriodicCells::new(rng.random(), rng.random_range(0.7..1.0)),
            period: rng.random_range(counts(self.cells, 2)), // warp noise uses period / 2
            warp: rng.random_range(0.2..0.6),
            crease: rng.random_range(0.06..0.14),
            wrinkles: rng.random_range(0.0..0.35),
            symmetry: Symmetry::random(&mut rng),
            gloss: rng.random_range(0.3..0.65),
            f0: rng.random_range(0.035..0.05),
            mottling: rng.random_range(0.03..0.12),
            noise: [(); 3].map(|_| PeriodicNoise::new(rng.random())),
        }
    }
}

impl Hide {
    /// The grain cell at pattern coordinates (x, y): Worley cells over coordinates warped by
    /// up to `warp` cells, so the grain is not a regular Voronoi mosaic.
    fn grain(&self, x: f64, y: f64) -> CellSample {
        let (w, p) = (self.warp / self.period as f64, self.period);
        let [n0, n1, _] = &self.noise;
        let (wx, wy) = (
            x + w * n0.fbm(x, y, p / 2, 2),
            y + w * n1.fbm(x, y, p / 2, 2),
        );
        self.cells.sample(wx, wy, p)
    }
}

impl Pattern for Hide {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        let (x, y) = self.symmetry.apply(u, v);
        let n2 = &self.noise[2];
        let cell = self.grain(x, y);
        let crease = 1.0 - smoothstep(0.0, self.crease, cell.border);
        let dome = smoothstep(0.0, 0.45, cell.border).sqrt(); // rounded, flat-topped pebble
        // Fold wrinkles: long grooves along x (2 cells along, 5 across).
        let fold = n2.fbm_xy(x, y, (2, 5), 3);
        let wrinkle = self.wrinkles * (1.0 - smoothstep(0.0, 0.05, fold.abs()));
        let mottle = n2.fbm(x, y, 6, 3);
        let tone = (1.0 + self.mottling * mottle + 0.1 * (cell.random(0) - 0.5))
            * (1.0 - 0.4 * crease)
            * (1.0 - 0.6 * wrinkle);
        GgxTexel {
            diffuse: scale(self.dye, tone),
            specular: [self.f0; 3],
            roughness: self.gloss + 0.2 * crease + 0.2 * wrinkle + 0.03 * mottle,
            height: 0.3 + 0.55 * dome + 0.05 * cell.random(1) + 0.05 * mottle - 0.4 * wrinkle,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::channel_stats;

    #[test]
    fn leather_is_a_finished_dielectric() {
        for seed in 0..12 {
            let s = channel_stats(&Leather::default().member(seed));
            assert!(
                (0.03..=0.05).contains(&s[3].1),
                "seed {seed}: F0 {:?}",
                s[3]
            );
            assert!(
                (0.3..0.85).contains(&s[6].1),
                "seed {seed}: roughness {:?}",
                s[6]
            );
            assert!(s[0].2 < 0.6, "dyed leather is not white: {:?}", s[0]);
        }
    }

    #[test]
    fn leather_creases_are_low_dark_and_rough() {
        // Compare texels on cell borders with texels deep inside cells.
        let hide = Leather::default().member(3);
        let (mut border, mut inside) = (Vec::new(), Vec::new());
        for k in 0..4000 {
            let (u, v) = ((k % 64) as f64 / 64.0, (k / 64) as f64 / 64.0);
            let (x, y) = hide.symmetry.apply(u, v);
            let b = hide.grain(x, y).border;
            let t = hide.sample(u, v);
            if b < 0.02 {
                border.push(t);
            } else if b > 0.3 {
                inside.push(t);
            }
        }
        let mean = |ts: &[GgxTexel], f: fn(&GgxTexel) -> f64| {
            ts.iter().map(f).sum::<f64>() / ts.len() as f64
        };
        assert!(border.len() > 20 && inside.len() > 20);
        assert!(mean(&border, |t| t.height) < mean(&inside, |t| t.height) - 0.2);
        assert!(mean(&border, |t| t.diffuse[0]) < 0.8 * mean(&inside, |t| t.diffuse[0]));
        assert!(mean(&border, |t| t.roughness) > mean(&inside, |t| t.roughness) + 0.1);
    }
}
