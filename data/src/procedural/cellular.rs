//! Periodic cellular noise (Worley 1996) on the unit square, tileable by construction.
//!
//! One feature point per cell of a `period` × `period` lattice, jittered inside its cell by a
//! hash of the cell index taken modulo `period`, so the point set (and every distance derived
//! from it) is exactly periodic with period 1 in x and y. A sample reports the distances to the
//! nearest and second-nearest feature points (F1, F2), the exact distance to the Voronoi border
//! of the nearest feature's cell (Quilez's construction, better than (F2 − F1)/2 for creases
//! and grout of constant width), and an id per cell for per-cell random attributes.

use super::noise::{mix64, unit_f64};

/// Seeded periodic Voronoi / Worley noise.
#[derive(Debug, Clone, Copy)]
pub struct PeriodicCells {
    seed: u64,
    jitter: f64,
}

/// What [`PeriodicCells::sample`] reports at one point; distances in cell units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CellSample {
    /// Distance to the nearest feature point (F1).
    pub f1: f64,
    /// Distance to the second-nearest feature point (F2).
    pub f2: f64,
    /// Distance to the border of the nearest feature's Voronoi cell (0 on the border).
    pub border: f64,
    /// Hash of the nearest feature's cell: equal for every point of that Voronoi cell,
    /// including across the wrap.
    pub id: u64,
}

impl CellSample {
    /// Uniform value in [0, 1) attached to the Voronoi cell, stream `k` (distinct `k` give
    /// independent values).
    pub fn random(&self, k: u64) -> f64 {
        unit_f64(mix64(self.id ^ k.wrapping_mul(0xA24B_AED4_963E_E407)))
    }
}

/// Half-width of the searched neighbourhood, in cells: 5 × 5 cells around the sample's own
/// cell contain both nearest features and every neighbour of the nearest cell for jitter ≤ 1.
const REACH: i64 = 2;

impl PeriodicCells {
    /// Cells whose feature points lie `jitter` ∈ [0, 1] of a cell around the cell centre
    /// (0: a square grid; 1: anywhere in the cell, the classic Worley pattern).
    pub fn new(seed: u64, jitter: f64) -> Self {
        Self {
            seed,
            // Beyond 1 a feature could leave the 5 × 5 neighbourhood that `sample` searches.
            jitter: jitter.clamp(0.0, 1.0),
        }
    }

    /// Feature point of lattice cell (i, j), in lattice units, and the cell's id.
    fn feature(&self, i: i64, j: i64, period: i64) -> ([f64; 2], u64) {
        let (wi, wj) = (i.rem_euclid(period) as u64, j.rem_euclid(period) as u64);
        let id = mix64(self.seed ^ (wi << 32) ^ wj);
        let (hx, hy) = (unit_f64(mix64(id ^ 1)), unit_f64(mix64(id ^ 2)));
        let point = [
            i as f64 + 0.5 + self.jitter * (hx - 0.5),
            j as f64 + 0.5 + self.jitter * (hy - 0.5),
        ];
        (point, id)
    }

    /// Cellular noise at (x, y) with `period` cells per unit along each axis.
    pub fn sample(&self, x: f64, y: f64, period: u32) -> CellSample {
        let p = period.max(1) as i64;
        let q = [x * p as f64, y * p as f64];
        let (ci, cj) = (q[0].floor() as i64, q[1].floor() as i64);
        const SIDE: usize = (2 * REACH + 1) as usize;
        let mut points = [([0.0; 2], 0u64); SIDE * SIDE];
        let (mut best, mut f1_sq, mut f2_sq) = (0, f64::INFINITY, f64::INFINITY);
        for (k, slot) in points.iter_mut().enumerate() {
            let (di, dj) = ((k % SIDE) as i64 - REACH, (k / SIDE) as i64 - REACH);
            *slot = self.feature(ci + di, cj + dj, p);
            let d_sq = (slot.0[0] - q[0]).powi(2) + (slot.0[1] - q[1]).powi(2);
            if d_sq < f1_sq {
                (f2_sq, f1_sq, best) = (f1_sq, d_sq, k);
            } else if d_sq < f2_sq {
                f2_sq = d_sq;
            }
        }
        // Distance to the bisector between the nearest feature a and each other feature b:
        // (q − (a + b)/2) · (a − b)/|a − b|; the border is the closest bisector.
        let a = points[best].0;
        let mut border = f64::INFINITY;
        for (k, (b, _)) in points.iter().enumerate() {
            if k == best {
                continue;
            }
            let (ex, ey) = (a[0] - b[0], a[1] - b[1]);
            let len = (ex * ex + ey * ey).sqrt();
            let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
            border = border.min(((q[0] - mid[0]) * ex + (q[1] - mid[1]) * ey) / len);
        }
        CellSample {
            f1: f1_sq.sqrt(),
            f2: f2_sq.sqrt(),
            border,
            id: points[best].1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points() -> impl Iterator<Item = (f64, f64)> {
        (0..300).map(|k| ((k as f64 * 0.1371) % 1.0, (k as f64 * 0.2913) % 1.0))
    }

    #[test]
    fn cells_are_periodic() {
        let cells = PeriodicCells::new(9, 1.0);
        for (x, y) in points() {
            let s = cells.sample(x, y, 7);
            for (dx, dy) in [(1.0, 0.0), (0.0, 1.0), (-2.0, 3.0)] {
                let t = cells.sample(x + dx, y + dy, 7);
                assert_eq!(s.id, t.id);
                assert!((s.f1 - t.f1).abs() < 1e-9 && (s.border - t.border).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn cells_border_is_the_distance_to_the_nearest_other_cell() {
        // Brute force: every point closer than the border lies in the same Voronoi cell, and
        // some point just beyond it (the direction towards the closest bisector is within
        // half a degree of one of 360 directions) lies in another.
        let (cells, period) = (PeriodicCells::new(4, 0.9), 12);
        for (x, y) in points().take(60) {
            let s = cells.sample(x, y, period);
            assert!(0.0 <= s.f1 && s.f1 <= s.f2 && s.border >= 0.0, "{s:?}");
            let at = |r: f64, k: usize| {
                let t = k as f64 * std::f64::consts::TAU / 360.0;
                let scale = r / period as f64; // cell units → unit-square units
                cells
                    .sample(x + scale * t.cos(), y + scale * t.sin(), period)
                    .id
            };
            assert!((0..360).all(|k| at(0.99 * s.border, k) == s.id), "{s:?}");
            assert!(
                (0..360).any(|k| at(1.01 * s.border + 1e-9, k) != s.id),
                "{s:?}"
            );
        }
        // A point exactly between two features of a regular grid lies on the border.
        let grid = PeriodicCells::new(4, 0.0);
        let s = grid.sample(1.0 / 12.0, 0.5 / 12.0, 12);
        assert!(s.border.abs() < 1e-9 && (s.f1 - s.f2).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn cells_regular_grid_has_known_distances() {
        // Jitter 0: features at cell centres; the centre of a cell has F1 = 0, F2 = 1 and
        // border 0.5.
        let grid = PeriodicCells::new(1, 0.0);
        let s = grid.sample(2.5 / 8.0, 5.5 / 8.0, 8);
        assert!(s.f1.abs() < 1e-12 && (s.f2 - 1.0).abs() < 1e-12);
        assert!((s.border - 0.5).abs() < 1e-12);
    }

    #[test]
    fn cells_ids_and_randoms_depend_on_cell_and_seed() {
        let (a, b) = (PeriodicCells::new(1, 1.0), PeriodicCells::new(2, 1.0));
        let ids: std::collections::HashSet<u64> =
            points().map(|(x, y)| a.sample(x, y, 16).id).collect();
        assert!(ids.len() > 100, "only {} distinct cells", ids.len());
        assert!(points().any(|(x, y)| a.sample(x, y, 16).id != b.sample(x, y, 16).id));
        let s = a.sample(0.3, 0.6, 16);
        assert_ne!(s.random(0), s.random(1));
        assert!((0.0..1.0).contains(&s.random(5)));
    }
}
