//! Varnished wood: flat-sawn boards with growth rings and pore grain under a clear varnish,
//! one solid board or several planks with V-grooved joints.
//!
//! Imitates a sanded, varnished board or plank floor seen from above. Growth rings are
//! iso-lines of the distance across the grain, wobbled by low-frequency periodic noise into
//! the arches of flat-sawn figure; each ring is light earlywood that darkens gradually into
//! latewood and ends abruptly at the next ring. Pores are fine dark dashes along the grain
//! that sit slightly below the surface, over faint fibre streaks. The varnish is the specular lobe: a grey dielectric
//! F0 ≈ 0.04 (n ≈ 1.5) from satin to gloss, rougher in pores and joints.
//!
//! Maps for `height(ggx, scale=relief)`: diffuse, specular, roughness, height.
//! Per seed: species colours (pine, oak, ash, maple, cherry, walnut, teak, mahogany, each
//! jittered), 1 to `max_planks` planks with their own ring phase and tint, ring density,
//! ring waviness, pore density and strength, varnish gloss, grain direction (one of the 8
//! symmetries of the square).

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::common::{
    GgxTexel, Pattern, Symmetry, counts, jitter, mix, scale, smoothstep, srgb, wrap01,
};
use super::noise::{PeriodicNoise, mix64, unit_f64};

/// Configuration of the wood family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct Wood {
    /// World-space height of the height map's full range (default 0.003: under varnish the
    /// relief is shallow, pores and plank joints only).
    pub relief: f64,
    /// Most planks across the grain (default 4); a member has 1 (one solid board, no joint)
    /// up to this many.
    pub max_planks: u32,
    /// Growth rings per unit across the grain, least and most (default 10 and 36).
    pub rings: (u32, u32),
}

impl Default for Wood {
    fn default() -> Self {
        Self {
            relief: 0.003,
            max_planks: 4,
            rings: (10, 36),
        }
    }
}

/// sRGB earlywood and latewood colours of common species (unfinished, as photographed).
const SPECIES: [([f64; 3], [f64; 3]); 8] = [
    ([0.87, 0.72, 0.50], [0.70, 0.47, 0.26]), // pine
    ([0.78, 0.62, 0.42], [0.55, 0.38, 0.22]), // oak
    ([0.88, 0.80, 0.66], [0.66, 0.55, 0.40]), // ash
    ([0.92, 0.82, 0.66], [0.80, 0.66, 0.48]), // maple
    ([0.74, 0.46, 0.30], [0.52, 0.27, 0.15]), // cherry
    ([0.50, 0.35, 0.24], [0.28, 0.17, 0.11]), // walnut
    ([0.70, 0.50, 0.28], [0.48, 0.31, 0.16]), // teak
    ([0.60, 0.30, 0.20], [0.40, 0.17, 0.10]), // mahogany
];

/// Width of a plank joint's V-groove on each side of the joint, unit-square units.
const JOINT_WIDTH: f64 = 0.005;

/// One member of the family.
pub(crate) struct Board {
    symmetry: Symmetry,
    early: [f64; 3],
    late: [f64; 3],
    planks: u32,
    /// Per plank: ring noise, ring phase (rings), colour tint, seed of per-ring contrasts.
    plank: Vec<(PeriodicNoise, f64, f64, u64)>,
    rings: u32,
    /// Ring wobble amplitude, in rings.
    waviness: f64,
    /// Fraction of a ring that is latewood.
    latewood: f64,
    /// Pore streaks per unit across the grain.
    pore_period: u32,
    /// How much pores darken the wood.
    pore_strength: f64,
    /// Varnish F0 and base roughness.
    varnish_f0: f64,
    gloss: f64,
    noise: PeriodicNoise,
}

impl PatternFamily for Wood {
    const NAME: &'static str = "wood";
    type Member = Board;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Board {
        let mut rng = StdRng::seed_from_u64(seed);
        let (early, late) = SPECIES[rng.random_range(0..SPECIES.len())];
        let k = rng.random_range(0.8..1.15); // lighter or darker stock of the species
        let planks = rng.random_range(counts((1, self.max_planks), 1));
        let plank = (0..planks)
            .map(|_| {
                (
                    PeriodicNoise::new(rng.random()),
                    rng.random_range(0.0..1.0),
                    rng.random_range(0.88..1.12),
                    rng.random(),
                )
            })
            .collect();
        Board {
            symmetry: Symmetry::random(&mut rng),
            early: srgb(jitter(&mut rng, scale(early, k), 0.04)),
            late: srgb(jitter(&mut rng, scale(late, k), 0.04)),
            planks,
            plank,
            rings: rng.random_range(counts(self.rings, 1)),
            waviness: rng.random_range(0.5..3.0),
            latewood: rng.random_range(0.1..0.25),
            pore_period: rng.random_range(24..48),
            pore_strength: rng.random_range(0.2..0.5),
            varnish_f0: rng.random_range(0.035..0.05),
            gloss: rng.random_range(0.12..0.42),
            noise: PeriodicNoise::new(rng.random()),
        }
    }
}

impl Pattern for Board {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        // Pattern coordinates: grain along x, rings and planks stacked along y.
        let (x, y) = self.symmetry.apply(u, v);
        let n = self.planks as f64;
        let k = (y * n).floor().rem_euclid(n) as usize;
        let (noise, phase, tint, ring_seed) = &self.plank[k];
        // Distance to the nearer joint (none on a single board).
        let joint = if self.planks > 1 {
            let f = wrap01(y * n);
            f.min(1.0 - f) / n
        } else {
            f64::INFINITY
        };
        let groove = 1.0 - smoothstep(0.0, JOINT_WIDTH, joint);

        // Rings: gentle arches from a wobble that is slow along the grain (1 cell per unit)
        // and a little faster across it (2), in units of rings. Where the wobble outgrows
        // the ring spacing, rings close into the ellipses of flat-sawn cathedral figure.
        let wobble = noise.fbm_xy(x, y, (1, 2), 3);
        let r = self.rings as f64 * y + phase + self.waviness * wobble;
        // Every year's latewood is a little different (ring index wrapped: periodic).
        let year = r.floor().rem_euclid(self.rings as f64) as u64;
        let contrast = 0.6 + 0.4 * unit_f64(mix64(ring_seed ^ year));
        // Earlywood darkens into latewood, which ends abruptly at the next ring (t = 1 → 0).
        let t = wrap01(r);
        let late = contrast * smoothstep(1.0 - self.latewood - 0.25, 1.0 - self.latewood, t);
        // Pores: thin lines along the grain, the zero set of noise that is long along the
        // grain (4 cells) and fine across it, broken up by a second noise.
        let line = self.noise.fbm_xy(x, y, (4, self.pore_period), 2).abs();
        let broken = smoothstep(-0.2, 0.3, noise.fbm_xy(x, y, (12, 24), 2));
        let pore = (1.0 - smoothstep(0.0, 0.06, line)) * broken;
        let mottle = self.noise.fbm(x, y, 3, 3);
        // Fibres: fine streaks along the grain everywhere.
        let fibre = noise.fbm_xy(x, y, (6, 96), 2);

        let shade = tint * (1.0 + 0.12 * mottle + 0.08 * fibre) * (1.0 - self.pore_strength * pore);
        let diffuse = scale(
            mix(self.early, self.late, late),
            shade * (1.0 - 0.6 * groove),
        );
        GgxTexel {
            diffuse,
            specular: [self.varnish_f0; 3],
            roughness: self.gloss + 0.04 * mottle + 0.12 * pore + (0.75 - self.gloss) * groove,
            // Latewood is harder and stands a little proud of sanded earlywood.
            height: 0.75 + 0.04 * late - 0.25 * pore - 0.5 * groove,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::channel_stats;

    #[test]
    fn wood_is_varnished_dielectric_with_wood_colours() {
        for seed in 0..12 {
            let s = channel_stats(&Wood::default().member(seed));
            for f0 in &s[3..6] {
                assert!((0.03..=0.05).contains(&f0.1), "seed {seed}: F0 {f0:?}");
            }
            // Wood is warm: mean red above mean green above mean blue.
            assert!(s[0].1 > s[1].1 && s[1].1 > s[2].1, "seed {seed}: {s:?}");
            assert!(
                (0.1..0.5).contains(&s[6].1),
                "seed {seed}: roughness {:?}",
                s[6]
            );
        }
    }

    #[test]
    fn wood_rings_show_in_the_albedo() {
        // Across the grain the albedo alternates between earlywood and latewood: its range
        // along one line across the grain is a sizeable fraction of its mean.
        let board = Wood::default().member(2);
        let line: Vec<f64> = (0..400)
            .map(|k| {
                let t = (k as f64 + 0.5) / 400.0;
                // Pattern y varies along u or v depending on the member's symmetry.
                let (u, v) = if board.symmetry.apply(0.0, t).1 != 0.0 {
                    (0.3, t)
                } else {
                    (t, 0.3)
                };
                board.sample(u, v).diffuse[1]
            })
            .collect();
        let (lo, hi) = line
            .iter()
            .fold((f64::MAX, 0f64), |(a, b), &x| (a.min(x), b.max(x)));
        let mean = line.iter().sum::<f64>() / line.len() as f64;
        assert!(hi - lo > 0.3 * mean, "{lo} {hi} {mean}");
    }
}
