//! Brushed metal: a bare metal sheet finished with an abrasive in one direction, giving fine
//! parallel grooves, broader bands of sheen and a few deeper scratches.
//!
//! Imitates brushed aluminium, steel, titanium, nickel, silver and the yellow and red metals
//! (brass, gold, copper). A metal has no diffuse reflection: its colour is the specular F0
//! (measured values at normal incidence, linear sRGB, after Hoffman, "Physics and Math of
//! Shading", SIGGRAPH 2015 course; capped at 0.95), the diffuse map holds only a trace of grime.
//! The isotropic GGX lobe cannot stretch a highlight by itself; the brushing does it the way
//! the real surface does: the grooves tilt the normals across the brushing direction only,
//! so the flash highlight spreads perpendicular to the grooves into the familiar streak. The
//! grooves are anisotropic periodic noise (dense across, sparse along the direction), and
//! the roughness follows the broad bands.
//!
//! Maps for `height(ggx, scale=relief)`: diffuse, specular, roughness, height.
//! Per seed: the metal, brushing direction (0°, 45°, 90°, 135°), groove density, roughness,
//! band contrast, scratch density, grime.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::common::{GgxTexel, Pattern, Streaks, counts, scale, smoothstep};
use super::noise::PeriodicNoise;

/// Configuration of the brushed-metal family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct BrushedMetal {
    /// World-space height of the height map's full range (default 0.01; the grooves use a
    /// tenth of it, but they are so narrow that their slopes tilt normals by ~10° rms).
    pub relief: f64,
    /// Grooves per unit across the brushing direction, least and most (default 64, 128).
    pub grooves: (u32, u32),
}

impl Default for BrushedMetal {
    fn default() -> Self {
        Self {
            relief: 0.01,
            grooves: (64, 128),
        }
    }
}

/// Linear F0 of metals: aluminium, iron/steel, titanium, chromium, nickel, silver, brass,
/// gold, copper.
const METALS: [[f64; 3]; 9] = [
    [0.913, 0.922, 0.924],
    [0.562, 0.565, 0.578],
    [0.542, 0.497, 0.449],
    [0.549, 0.556, 0.554],
    [0.660, 0.609, 0.526],
    [0.950, 0.950, 0.915],
    [0.910, 0.778, 0.423],
    [0.950, 0.766, 0.336],
    [0.950, 0.638, 0.538],
];

/// One member of the family.
pub(crate) struct Sheet {
    f0: [f64; 3],
    streaks: Streaks,
    grooves: u32,
    roughness: f64,
    /// Roughness contrast of the broad bands.
    bands: f64,
    /// Scratch grooves per unit across the direction (sparse zero crossings).
    scratches: u32,
    grime: f64,
    noise: [PeriodicNoise; 4],
}

impl PatternFamily for BrushedMetal {
    const NAME: &'static str = "brushed_metal";
    type Member = Sheet;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Sheet {
        let mut rng = StdRng::seed_from_u64(seed);
        let f0 = METALS[rng.random_range(0..METALS.len())];
        Sheet {
            // Alloys and surface oxide shift the measured F0 a little.
            f0: scale(f0, rng.random_range(0.95..1.0)),
            streaks: Streaks::random(&mut rng),
            // At least 8 grooves: the broad bands use an eighth of the groove count as their period.
            grooves: rng.random_range(counts(self.grooves, 8)),
            roughness: rng.random_range(0.05..0.22),
            bands: rng.random_range(0.03..0.1),
            scratches: rng.random_range(6..24),
            grime: rng.random_range(0.0..0.012),
            noise: [(); 4].map(|_| PeriodicNoise::new(rng.random())),
        }
    }
}

impl Pattern for Sheet {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        let (along, across) = self.streaks.apply(u, v);
        let [n0, n1, n2, n3] = &self.noise;
        // Noise dense across the direction (x = across) and sparse along it (y = along).
        let fine = n0.fbm_xy(across, along, (self.grooves, 3), 2);
        let band = n1.fbm_xy(across, along, (self.grooves / 8, 2), 3);
        let scratch_line = n2.value_xy(across, along, (self.scratches, 1), 0);
        let scratch = 1.0 - smoothstep(0.0, 0.015, scratch_line.abs());
        let grime = self.grime * (1.0 + 0.8 * n3.fbm(u, v, 4, 3));
        GgxTexel {
            diffuse: [grime; 3],
            specular: scale(self.f0, 1.0 + 0.03 * band),
            roughness: self.roughness + self.bands * band + 0.04 * fine + 0.08 * scratch,
            height: 0.5 + 0.35 * fine + 0.1 * band - 0.3 * scratch,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::channel_stats;

    #[test]
    fn brushed_metal_is_a_metal() {
        let mut coloured = 0;
        for seed in 0..16 {
            let s = channel_stats(&BrushedMetal::default().member(seed));
            let f0 = [s[3].1, s[4].1, s[5].1];
            let (lo, hi) = (
                f0.iter().cloned().fold(1.0, f64::min),
                f0.iter().cloned().fold(0.0, f64::max),
            );
            assert!(
                (0.5..=0.96).contains(&hi) && lo > 0.3,
                "seed {seed}: F0 {f0:?}"
            );
            assert!(s[0].2 < 0.03, "seed {seed}: diffuse {:?}", s[0]);
            assert!(
                (0.04..0.4).contains(&s[6].1),
                "seed {seed}: roughness {:?}",
                s[6]
            );
            coloured += usize::from(hi - lo > 0.2);
        }
        assert!(coloured > 0, "some seeds give coloured metals");
    }

    #[test]
    fn brushed_metal_varies_across_the_brushing_not_along_it() {
        for seed in 0..8 {
            let sheet = BrushedMetal::default().member(seed);
            // Mean |Δheight| over a step of h·(a, b) along the brushing direction and of
            // h·(−b, a) across it.
            let (mut along, mut across) = (0.0, 0.0);
            let h = 1.0 / 512.0;
            let (a, b) = (sheet.streaks.a as f64, sheet.streaks.b as f64);
            for k in 0..300 {
                let (u, v) = ((k as f64 * 0.6180) % 1.0, (k as f64 * 0.4142) % 1.0);
                let h0 = sheet.sample(u, v).height;
                along += (sheet.sample(u + a * h, v + b * h).height - h0).abs();
                across += (sheet.sample(u - b * h, v + a * h).height - h0).abs();
            }
            assert!(across > 5.0 * along, "seed {seed}: {across} vs {along}");
        }
    }
}
