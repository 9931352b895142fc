//! Car paint: a pigmented base coat with metallic or pearlescent flakes under a smooth,
//! glossy clear coat — the `coated` model's two lobes, as in the paper's car-paint data.
//!
//! Imitates automotive paint on a flat panel: metallic (aluminium flakes), pearl (mica
//! flakes whose interference tints the flake lobe towards another hue) and solid (no flakes).
//! Lobe 1 is the broad flake lobe: F0 tinted by the base colour, roughness 0.2-0.5. Flake
//! sparkle is per-flake variation of that lobe: flakes are cells of periodic Worley noise at
//! a fixed density per unit (independent of the resolution; near one flake per texel at
//! 256²), each with its own brightness (most dim, a few glinting) and roughness (its tilt
//! spreads or concentrates the reflection). Lobe 2 is the clear coat: grey F0 0.04-0.05
//! (n ≈ 1.5), roughness 0.02-0.07 with a faint orange-peel variation. The diffuse map is the
//! pigment: dark for metallics (the flakes carry the colour), brighter for solids.
//!
//! Maps for `coated`: diffuse, specular, roughness, specular2, roughness2 (flat normal).
//! Per seed: kind (metallic 60 %, pearl 20 %, solid 20 %), hue, saturation and lightness,
//! flake tint, flake density and sparkle, flake-lobe roughness, clear-coat gloss.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::cellular::PeriodicCells;
use super::common::{CoatedTexel, Pattern, counts, hsv, scale, srgb};
use super::noise::PeriodicNoise;

/// Configuration of the car-paint family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct CarPaint {
    /// Flakes per unit along each side, least and most (default 200, 400: around one flake
    /// per texel at 256², a few texels per flake at 1024²).
    pub flakes: (u32, u32),
}

impl Default for CarPaint {
    fn default() -> Self {
        Self { flakes: (200, 400) }
    }
}

/// One member of the family.
pub(crate) struct Panel {
    pigment: [f64; 3],
    /// Mean flake F0, linear rgb.
    flake: [f64; 3],
    /// Fraction of flakes that glint, and how much brighter they are.
    glints: f64,
    glint_gain: f64,
    flake_roughness: f64,
    cells: PeriodicCells,
    flakes: u32,
    coat_f0: f64,
    coat_roughness: f64,
    noise: PeriodicNoise,
}

impl PatternFamily for CarPaint {
    const NAME: &'static str = "car_paint";
    type Member = Panel;

    fn brdf(&self) -> String {
        "coated".into()
    }

    fn member(&self, seed: u64) -> Panel {
        let mut rng = StdRng::seed_from_u64(seed);
        let hue = rng.random_range(0.0..1.0);
        let kind = rng.random_range(0..10);
        // Saturation: a third of cars are white, grey, silver or black.
        let saturation = if rng.random_bool(0.35) {
            rng.random_range(0.0..0.08)
        } else {
            rng.random_range(0.35..0.95)
        };
        let (pigment, flake, glints) = if kind < 6 {
            // Metallic: dark pigment, flakes carry a lighter version of the colour.
            let pigment = srgb(hsv(hue, saturation, rng.random_range(0.08..0.55)));
            let tint = srgb(hsv(hue, 0.6 * saturation, 1.0));
            let flake = scale(tint, rng.random_range(0.1..0.22));
            (pigment, flake, rng.random_range(0.03..0.1))
        } else if kind < 8 {
            // Pearl: mica flakes tint the flake lobe towards a neighbouring hue.
            let pigment = srgb(hsv(hue, saturation, rng.random_range(0.3..0.85)));
            let shift = hue + rng.random_range(-0.15..0.15);
            let flake = scale(srgb(hsv(shift, 0.5, 1.0)), rng.random_range(0.08..0.2));
            (pigment, flake, rng.random_range(0.02..0.06))
        } else {
            // Solid: no flakes, at most a faint broad lobe.
            let pigment = srgb(hsv(hue, saturation, rng.random_range(0.2..0.9)));
            (pigment, [rng.random_range(0.0..0.02); 3], 0.0)
        };
        Panel {
            pigment,
            flake,
            glints,
            glint_gain: rng.random_range(1.0..2.0),
            flake_roughness: rng.random_range(0.25..0.45),
            cells: PeriodicCells::new(rng.random(), 1.0),
            flakes: rng.random_range(counts(self.flakes, 1)),
            coat_f0: rng.random_range(0.04..0.05),
            coat_roughness: rng.random_range(0.02..0.07),
            noise: PeriodicNoise::new(rng.random()),
        }
    }
}

impl Pattern for Panel {
    type Texel = CoatedTexel;

    fn sample(&self, u: f64, v: f64) -> CoatedTexel {
        let flake = self.cells.sample(u, v, self.flakes);
        // Most flakes reflect 0.6-1.4 × the mean; a few glint, `glint_gain` × the mean more
        // (at most 0.22 · 3.4 < 1: F0 stays a reflectance).
        let glint = if flake.random(0) < self.glints {
            self.glint_gain
        } else {
            0.0
        };
        let brightness = 0.6 + 0.8 * flake.random(1) + glint;
        let peel = self.noise.fbm(u, v, 24, 2); // orange peel of the clear coat
        let mottle = self.noise.fbm(u, v, 3, 3); // uneven flake orientation across the panel
        CoatedTexel {
            diffuse: self.pigment,
            specular: scale(self.flake, brightness),
            roughness: self.flake_roughness + 0.12 * (flake.random(2) - 0.5) + 0.03 * mottle,
            specular2: [self.coat_f0; 3],
            roughness2: self.coat_roughness * (1.0 + 0.15 * peel),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::channel_stats;

    #[test]
    fn car_paint_has_a_sharp_clear_coat_over_a_broad_flake_lobe() {
        for seed in 0..12 {
            let s = channel_stats(&CarPaint::default().member(seed));
            // Channels: diffuse 0-2, specular 3-5, roughness 6, specular2 7-9, roughness2 10.
            assert!(
                (0.04..=0.05).contains(&s[7].1),
                "seed {seed}: coat F0 {:?}",
                s[7]
            );
            assert!(s[10].2 < 0.1, "seed {seed}: coat roughness {:?}", s[10]);
            assert!(
                s[6].0 > 0.15 && s[6].2 < 0.55,
                "seed {seed}: flake roughness {:?}",
                s[6]
            );
            assert!(
                s[6].1 > 4.0 * s[10].1,
                "the flake lobe is broader than the coat"
            );
            assert!(s[3].2 <= 1.0, "flake F0 is a reflectance");
        }
    }

    #[test]
    fn car_paint_flakes_sparkle() {
        // Metallic members: the flake lobe's F0 varies strongly from texel to texel, with a
        // bright tail (glints) well above the mean.
        let metallic: Vec<u64> = (0..20)
            .filter(|&s| CarPaint::default().member(s).glints >= 0.03)
            .collect();
        assert!(metallic.len() >= 5);
        for seed in metallic {
            let s = channel_stats(&CarPaint::default().member(seed));
            let (lo, mean, hi) = s[4];
            assert!(
                hi > 2.0 * mean && lo < 0.8 * mean,
                "seed {seed}: {:?}",
                s[4]
            );
        }
    }
}
