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

    /// Lattice value in [−1, 1] at integer cell (i, j) of a lattice with `px` × `py` cells.
    fn lattice(&self, i: i64, j: i64, (px, py): (i64, i64), octave: u64) -> f64 {
        let (i, j) = (i.rem_euclid(px) as u64, j.rem_euclid(py) as u64);
        unit_f64(mix64(self.seed ^ (octave << 48) ^ (i << 24) ^ j)) * 2.0 - 1.0
    }

    /// Noise in [−1, 1] at (x, y) with `period` lattice cells per unit.
    pub fn value(&self, x: f64, y: f64, period: u32, octave: u64) -> f64 {
        self.value_xy(x, y, (period, period), octave)
    }

    /// Anisotropic noise in [−1, 1] at (x, y) with `px` lattice cells per unit along x and `py`
    /// along y: `px ≫ py` gives streaks along y. Equals [`Self::value`] when `px == py`.
    pub fn value_xy(&self, x: f64, y: f64, (px, py): (u32, u32), octave: u64) -> f64 {
        let p = (px.max(1) as i64, py.max(1) as i64);
        let (fx, fy) = (x * p.0 as f64, y * p.1 as f64);
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

    /// Anisotropic fBm: [`Self::fbm`] with `(px, py)` cells per unit in the first octave.
    pub fn fbm_xy(&self, x: f64, y: f64, (px, py): (u32, u32), octaves: u32) -> f64 {
        let (mut sum, mut norm, mut amp) = (0.0, 0.0, 1.0);
        for o in 0..octaves {
            sum += amp * self.value_xy(x, y, (px << o, py << o), o as u64);
            norm += amp;
            amp *= 0.5;
        }
        sum / norm
    }
}

// The SplitMix64 hash (Steele et al. 2014) and its top 53 bits as a uniform value in [0, 1),
// from the workspace's one seeded generator.
pub(crate) use photomat_core::rng::{mix64, unit_f64};

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
    fn anisotropic_noise_is_periodic_and_matches_isotropic() {
        let n = PeriodicNoise::new(11);
        for k in 0..200 {
            let (x, y) = ((k as f64 * 0.173) % 1.0, (k as f64 * 0.377) % 1.0);
            assert_eq!(n.value_xy(x, y, (5, 5), 2), n.value(x, y, 5, 2));
            let v = n.fbm_xy(x, y, (24, 3), 3);
            assert!((-1.0..=1.0).contains(&v));
            for (dx, dy) in [(1.0, 0.0), (0.0, 1.0), (-3.0, 2.0)] {
                assert!((n.fbm_xy(x + dx, y + dy, (24, 3), 3) - v).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn anisotropic_noise_varies_faster_along_the_denser_axis() {
        // 32 cells per unit along x, 2 along y: mean |Δ| over a step of 1/64 is much larger
        // along x (half a cell) than along y (1/32 of a cell).
        let n = PeriodicNoise::new(5);
        let (mut along_x, mut along_y) = (0.0, 0.0);
        for k in 0..400 {
            let (x, y) = ((k as f64 * 0.0137) % 1.0, (k as f64 * 0.0291) % 1.0);
            let v = n.value_xy(x, y, (32, 2), 0);
            along_x += (n.value_xy(x + 1.0 / 64.0, y, (32, 2), 0) - v).abs();
            along_y += (n.value_xy(x, y + 1.0 / 64.0, (32, 2), 0) - v).abs();
        }
        assert!(along_x > 4.0 * along_y, "{along_x} vs {along_y}");
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
