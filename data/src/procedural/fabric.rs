//! Woven fabric: warp threads (running along y) and weft threads (along x) interlaced in a
//! plain, twill or satin weave, with round thread profiles, twisted plies and gaps.
//!
//! Imitates woven cloth seen close up: canvas and poplin (plain), denim and gabardine
//! (twills), satin. The weave is a binary matrix that says which thread is on top at each
//! crossing; every thread undulates smoothly over and under the threads it crosses (a
//! cosine between crossings), has a round cross-section and a twisted-ply texture along its
//! length, and between threads lies a dark gap. The visible surface at a texel is the higher
//! of the two threads there. Cloth is a rough dielectric (F0 0.03-0.045, roughness
//! 0.65-0.9), except satin, whose long smooth floats are silkier (roughness 0.35-0.55).
//!
//! Maps for `height(ggx, scale=relief)`: diffuse, specular, roughness, height.
//! Per seed: weave (plain, twill 2/1, 2/2, 3/1, satin), thread count (a multiple of the
//! weave's repeat, so the square holds whole repeats), thread widths, colour scheme (solid,
//! denim: indigo warp on white weft, two-tone, heathered), per-thread colour variation,
//! twist, roughness, orientation (one of the 8 symmetries of the square).

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::common::{
    GgxTexel, Pattern, Symmetry, counts, hsv, jitter, mix, scale, smoothstep, srgb, wrap01,
};
use super::noise::{PeriodicNoise, mix64, unit_f64};

/// Configuration of the fabric family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct Fabric {
    /// World-space height of the height map's full range (default 0.006: threads a few
    /// hundredths of the swatch wide are about as tall as they are wide).
    pub relief: f64,
    /// Threads per unit in each direction, least and most (default 16, 48: at 256² a thread
    /// spans at least 5 texels).
    pub threads: (u32, u32),
}

impl Default for Fabric {
    fn default() -> Self {
        Self {
            relief: 0.006,
            threads: (16, 48),
        }
    }
}

/// Which thread lies on top at each crossing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Weave {
    /// Over one, under one.
    Plain,
    /// Warp over `over` wefts, under `under`, shifted by one weft per row: diagonal ribs.
    Twill { over: u32, under: u32 },
    /// Five-end satin: warp floats over four wefts, the binding points spread by a step of 2.
    Satin,
}

impl Weave {
    /// Crossings before the pattern repeats, in both directions.
    fn repeat(self) -> u32 {
        match self {
            Weave::Plain => 2,
            Weave::Twill { over, under } => over + under,
            Weave::Satin => 5,
        }
    }

    /// Whether the warp (column `j`) lies over the weft (row `i`) at their crossing.
    fn warp_over(self, i: i64, j: i64) -> bool {
        let r = self.repeat() as i64;
        match self {
            Weave::Plain => (i + j).rem_euclid(2) == 0,
            Weave::Twill { over, .. } => (j + i).rem_euclid(r) < over as i64,
            Weave::Satin => (j + 2 * i).rem_euclid(r) != 0,
        }
    }
}

/// Height of the gaps between threads, below every thread (threads span 0.24 … 0.99).
const GAP_HEIGHT: f64 = 0.05;

/// Albedo of a gap relative to the darker thread colour: deep shadow, darker than any lit
/// thread (thread shading stays above ~0.3 of the colour).
const GAP_SHADE: f64 = 0.15;

/// One member of the family.
pub(crate) struct Cloth {
    weave: Weave,
    threads: u32,
    symmetry: Symmetry,
    /// Half-widths of warp and weft threads, fractions of the thread spacing.
    half_width: [f64; 2],
    /// Warp and weft colours (linear) and per-thread colour variation.
    colours: [[f64; 3]; 2],
    variation: f64,
    /// Heathering: fraction of fibres that are grey instead of dyed.
    heather: f64,
    /// Ply turns per thread spacing: ½ or 1, with `twist · threads` whole so that the ply
    /// texture is periodic too.
    twist: f64,
    roughness: f64,
    f0: f64,
    seed: u64,
    noise: PeriodicNoise,
}

impl PatternFamily for Fabric {
    const NAME: &'static str = "fabric";
    type Member = Cloth;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Cloth {
        let mut rng = StdRng::seed_from_u64(seed);
        let weave = match rng.random_range(0..5) {
            0 => Weave::Plain,
            1 => Weave::Twill { over: 2, under: 1 },
            2 => Weave::Twill { over: 2, under: 2 },
            3 => Weave::Twill { over: 3, under: 1 },
            _ => Weave::Satin,
        };
        let r = weave.repeat();
        // A whole number of repeats, within the configured thread counts where possible.
        let (least, most) = self.threads;
        let threads = r * rng.random_range(counts((least.div_ceil(r), most / r), 1));
        let colour = |rng: &mut StdRng| {
            let h = rng.random_range(0.0..1.0);
            srgb(hsv(
                h,
                rng.random_range(0.15..0.8),
                rng.random_range(0.25..0.85),
            ))
        };
        let (colours, heather) = match rng.random_range(0..4) {
            0 => {
                let c = colour(&mut rng);
                ([c, c], 0.0)
            }
            1 => {
                let indigo = srgb(jitter(&mut rng, [0.16, 0.23, 0.42], 0.15));
                let ecru = srgb(jitter(&mut rng, [0.86, 0.84, 0.78], 0.05));
                ([indigo, ecru], 0.0)
            }
            2 => ([colour(&mut rng), colour(&mut rng)], 0.0),
            _ => {
                let c = colour(&mut rng);
                ([c, c], rng.random_range(0.2..0.5))
            }
        };
        let satin = weave == Weave::Satin;
        Cloth {
            weave,
            threads,
            symmetry: Symmetry::random(&mut rng),
            half_width: [rng.random_range(0.34..0.46), rng.random_range(0.34..0.46)],
            colours,
            variation: rng.random_range(0.02..0.12),
            heather,
            twist: if threads % 2 == 0 && rng.random_bool(0.5) {
                0.5
            } else {
                1.0
            },
            roughness: if satin {
                rng.random_range(0.35..0.55)
            } else {
                rng.random_range(0.65..0.88)
            },
            f0: rng.random_range(0.03..0.045),
            seed: rng.random(),
            noise: PeriodicNoise::new(rng.random()),
        }
    }
}

/// A thread at one texel: how high its top is (fraction of the relief) and its shading.
struct ThreadHit {
    height: f64,
    /// Ply texture in [−1, 1] and the thread's colour variation in [−1, 1].
    ply: f64,
    jitter: f64,
}

impl Cloth {
    /// The thread of direction `dir` (0 warp, 1 weft) at cross coordinate `cross` (thread
    /// spacings, across the thread) and `along` (thread spacings, along it), if the texel
    /// falls on it. `over(k, m)`: whether this thread family is on top at thread k, crossing m.
    fn thread(
        &self,
        dir: usize,
        cross: f64,
        along: f64,
        over: impl Fn(i64, i64) -> bool,
    ) -> Option<ThreadHit> {
        let k = cross.floor() as i64;
        let offset = (wrap01(cross) - 0.5) / self.half_width[dir]; // −1 … 1 on the thread
        if offset.abs() >= 1.0 {
            return None;
        }
        // Vertical position: +1 over a crossing, −1 under it, cosine between crossing centres.
        let c = along - 0.5;
        let m = c.floor() as i64;
        let z = |m| if over(k, m) { 1.0 } else { -1.0 };
        let t = (1.0 - (std::f64::consts::PI * (c - m as f64)).cos()) / 2.0;
        let level = z(m) + (z(m + 1) - z(m)) * t;
        let round = (1.0 - offset * offset).sqrt();
        let ply = (std::f64::consts::TAU * (offset + self.twist * along)).cos();
        let n = self.threads as i64;
        let id = (k.rem_euclid(n) as u64) << 1 | dir as u64;
        Some(ThreadHit {
            height: 0.48 + 0.24 * level + 0.24 * round, // 0.48 ± 0.48, room for the ply
            ply: ply * round,
            jitter: 2.0 * unit_f64(mix64(self.seed ^ id)) - 1.0,
        })
    }
}

impl Pattern for Cloth {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        let (x, y) = self.symmetry.apply(u, v);
        let n = self.threads as f64;
        // In thread spacings; threads meander by up to a sixth of a spacing (loose weaving).
        let (cx, cy) = (
            x * n + 0.15 * self.noise.fbm(x, y, 3, 2),
            y * n + 0.15 * self.noise.fbm(y, x, 3, 2),
        );
        let weave = self.weave;
        // Warp: column j = ⌊cx⌋ along y, crossing weft i; weft: row i = ⌊cy⌋ along x.
        let warp = self.thread(0, cx, cy, |j, i| weave.warp_over(i, j));
        let weft = self.thread(1, cy, cx, |i, j| !weave.warp_over(i, j));
        let top = match (warp, weft) {
            (Some(a), Some(b)) if b.height > a.height => Some((1, b)),
            (Some(a), _) => Some((0, a)),
            (None, Some(b)) => Some((1, b)),
            (None, None) => None,
        };
        let slub = self.noise.fbm(x, y, 8, 2);
        let fibre = self.noise.fbm(x, y, 96, 2); // loose fibres, fuzz
        let Some((dir, hit)) = top else {
            // Gap between threads: deep, in shadow, dull.
            let [w, f] = self.colours;
            let dark = [0, 1, 2].map(|c| GAP_SHADE * w[c].min(f[c]));
            return GgxTexel {
                diffuse: dark,
                specular: [self.f0; 3],
                roughness: 0.9,
                height: GAP_HEIGHT,
            };
        };
        let dyed = scale(self.colours[dir], 1.0 + self.variation * hit.jitter);
        let grey = [(dyed[0] + dyed[1] + dyed[2]) / 3.0; 3]; // undyed fibre of equal lightness
        let heathered = mix(dyed, grey, self.heather * smoothstep(-0.3, 0.3, fibre));
        // Lower parts of a thread (diving under a crossing) lie in their neighbours' shadow.
        let occlusion = 0.55 + 0.45 * smoothstep(0.2, 0.9, hit.height);
        let shade = occlusion * (1.0 + 0.12 * hit.ply + 0.06 * slub + 0.08 * fibre);
        GgxTexel {
            diffuse: scale(heathered, shade),
            specular: [self.f0; 3],
            roughness: self.roughness + 0.05 * hit.ply + 0.04 * slub + 0.05 * fibre,
            height: hit.height + 0.03 * hit.ply,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::channel_stats;

    #[test]
    fn fabric_thread_count_holds_whole_repeats() {
        for seed in 0..40 {
            let cloth = Fabric::default().member(seed);
            assert_eq!(cloth.threads % cloth.weave.repeat(), 0, "{:?}", cloth.weave);
            assert!((16..=48).contains(&cloth.threads), "{}", cloth.threads);
        }
    }

    #[test]
    fn fabric_weaves_interlace() {
        // In every weave each warp goes over and under within one repeat, and so does every
        // weft: otherwise the cloth would fall apart.
        for weave in [
            Weave::Plain,
            Weave::Twill { over: 2, under: 1 },
            Weave::Twill { over: 3, under: 1 },
            Weave::Satin,
        ] {
            let r = weave.repeat() as i64;
            for k in 0..r {
                let warp: Vec<bool> = (0..r).map(|i| weave.warp_over(i, k)).collect();
                let weft: Vec<bool> = (0..r).map(|j| weave.warp_over(k, j)).collect();
                assert!(warp.contains(&true) && warp.contains(&false), "{weave:?}");
                assert!(weft.contains(&true) && weft.contains(&false), "{weave:?}");
            }
        }
        assert_eq!(
            (0..5).filter(|&j| Weave::Satin.warp_over(0, j)).count(),
            4,
            "satin is warp-faced"
        );
    }

    #[test]
    fn fabric_is_a_rough_dielectric_with_low_dark_gaps() {
        for seed in 0..12 {
            let cloth = Fabric::default().member(seed);
            let s = channel_stats(&cloth);
            assert!(
                (0.03..=0.045).contains(&s[3].1),
                "seed {seed}: F0 {:?}",
                s[3]
            );
            assert!(
                (0.3..0.95).contains(&s[6].1),
                "seed {seed}: roughness {:?}",
                s[6]
            );
            assert!(s[7].2 - s[7].0 > 0.2, "seed {seed}: height {:?}", s[7]);
            // Between threads there are gaps: the lowest and darkest texels of the cloth.
            let texels: Vec<GgxTexel> = (0..4096)
                .map(|k| cloth.sample(wrap01(k as f64 * 0.7549), wrap01(k as f64 * 0.5698)))
                .collect();
            let (gaps, threads): (Vec<_>, Vec<_>) =
                texels.iter().partition(|t| t.height == GAP_HEIGHT);
            assert!(!gaps.is_empty(), "seed {seed}: no gaps");
            let lowest = |ts: &[&GgxTexel], f: &dyn Fn(&GgxTexel) -> f64| {
                ts.iter().map(|t| f(t)).fold(f64::INFINITY, f64::min)
            };
            let highest = |ts: &[&GgxTexel], f: &dyn Fn(&GgxTexel) -> f64| {
                ts.iter().map(|t| f(t)).fold(f64::NEG_INFINITY, f64::max)
            };
            assert!(
                lowest(&threads, &|t| t.height) > GAP_HEIGHT + 0.1,
                "seed {seed}"
            );
            for c in 0..3 {
                let (thread, gap) = (
                    lowest(&threads, &|t| t.diffuse[c]),
                    highest(&gaps, &|t| t.diffuse[c]),
                );
                assert!(thread > gap, "seed {seed}: channel {c}: {thread} vs {gap}");
            }
        }
    }
}
