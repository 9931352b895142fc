//! Periodic value noise and fBm on the unit square (tileable by construction).
//!
//! Value noise (Perlin 1985's lattice idea with random values instead of gradients) on an
//! integer lattice of `period` cells per side whose hash wraps modulo `period`, with quintic
//! fade (Perlin 2002) so the result is C² and exactly periodic with period 1 in x and y.
//! fBm sums octaves whose periods double, so it stays periodic too.

/// Seeded periodic noise.
#[derive(Debug, Clone, Copy)]
pub struct PeriodicNoise {
    seed: u64,
}

impl PeriodicNoise {
    pub fn new(seed: u64) -> Self {
        Self { seed }
    }

    /// Lattice value in [−1, 1] at integer cell (i, j) of a `period`-periodic lattice.
    fn lattice(&self, i: i64, j: i64, period: i64, octave: u64) -> f64 {
        let (i, j) = (i.rem_euclid(period) as u64, j.rem_euclid(period) as u64);
        // SplitMix64 finaliser over the packed coordinates: a well-mixed 64-bit hash.
        let mut z = self.seed ^ (octave << 48) ^ (i << 24) ^ j;
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }

    /// Noise in [−1, 1] at (x, y) with `period` lattice cells per unit.
    pub fn value(&self, x: f64, y: f64, period: u32, octave: u64) -> f64 {
        let p = period.max(1) as i64;
        let (fx, fy) = (x * p as f64, y * p as f64);
        let (i, j) = (fx.floor() as i64, fy.floor() as i64);
        let (tx, ty) = (fade(fx - i as f64), fade(fy - j as f64));
        let v00 = self.lattice(i, j, p, octave);
        let v10 = self.lattice(i + 1, j, p, octave);
        let v01 = self.lattice(i, j + 1, p, octave);
        let v11 = self.lattice(i + 1, j + 1, p, octave);
        let a = v00 + (v10 - v00) * tx;
        let b = v01 + (v11 - v01) * tx;
        a + (b - a) * ty
    }

    /// Fractal sum of `octaves` octaves starting at `period` cells, amplitude halving;
    /// normalised to [−1, 1].
    pub fn fbm(&self, x: f64, y: f64, period: u32, octaves: u32) -> f64 {
        let (mut sum, mut norm, mut amp) = (0.0, 0.0, 1.0);
        for o in 0..octaves {
            sum += amp * self.value(x, y, period << o, o as u64);
            norm += amp;
            amp *= 0.5;
        }
        sum / norm
    }
}

/// Quintic fade 6t⁵ − 15t⁴ + 10t³.
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_periodic_and_bounded() {
        let n = PeriodicNoise::new(7);
        for k in 0..200 {
            let (x, y) = ((k as f64 * 0.137) % 1.0, (k as f64 * 0.291) % 1.0);
            let v = n.fbm(x, y, 3, 4);
            assert!((-1.0..=1.0).contains(&v));
            for (dx, dy) in [(1.0, 0.0), (0.0, 1.0), (-2.0, 3.0)] {
                assert!((n.fbm(x + dx, y + dy, 3, 4) - v).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn noise_depends_on_the_seed() {
        let (a, b) = (PeriodicNoise::new(1), PeriodicNoise::new(2));
        let differs = (0..50).any(|k| {
            (a.value(k as f64 * 0.07, 0.3, 8, 0) - b.value(k as f64 * 0.07, 0.3, 8, 0)).abs() > 1e-3
        });
        assert!(differs);
    }
}
