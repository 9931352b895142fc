//! `robust`: a highlight detector that fits the physics of a collocated flash photo.
//!
//! The paper's centroid (§"Dataset collection", [`super::paper`]) is pulled towards the image
//! centre by lens vignetting, by ambient light and by the image border cutting the flash lobe.
//! This detector instead fits what a flash photo of a flat sample looks like (DESIGN §2,
//! `docs/datasets.md`: the photo spans a square of side 2, flash and camera at height 1).
//!
//! # Model
//! With `s = |p − l|` the distance of a plane point `p` from the point `l` under the flash, the
//! collocated flash sees every point at `cos θ = 1/√(1+s²)` and distance² `1 + s²`, so any
//! isotropic BRDF gives a radiance that depends on `s` only. Two profiles span what materials do:
//! - diffuse: `g_d(s) = cos θ / d² = (1+s²)^(−3/2)`, exact for Lambert;
//! - specular: the GGX lobe `D(θ)·cos θ` normalised to 1 at s = 0,
//!   `g_s(s; α) = (α²/(α²+s²))² · (1+s²)^(3/2)` (`tan θ = s`; Fresnel and shadowing vary by
//!   less than 2 % within the photo and are left out).
//!
//! The camera multiplies by a vignetting that is radial about the image centre, approximated by
//! `1 − v·r²` (r = |p|), and ambient light adds a constant. For fixed (l, α) the model
//!
//! `Y(p) ≈ a·g_d + b·g_s − (a v)·r²·g_d − (b v)·r²·g_s + c`
//!
//! is linear in its five coefficients (the vignetting is allowed to differ between the two
//! terms), so they are solved exactly by weighted least squares (variable projection), and only
//! (lₓ, l_y, ln α) are searched, by Nelder–Mead from the best of a few starts.
//!
//! # Data and weights
//! Y is the paper's intensity (linear min(R,G,B)) averaged over blocks of a ~[`RobustDetector::grid`]²
//! grid. Saturated blocks carry no magnitude and are left out. Residuals are relative (texture
//! multiplies the flash falloff) and down-weighted with Cauchy weights, re-estimated four times
//! (IRLS), so grout lines, dark knots and sparkles do not drag the fit. Every fit uses only the
//! largest square centred on the current estimate that lies inside the image (at least
//! [`MIN_DOMAIN_HALF`] wide): a radial profile fitted over a domain symmetric about its centre has no
//! reason to shift towards the larger side, so profile mismatch (two-lobe car paint, bumpy
//! normals) does not bias the position.
//!
//! # Failure rule
//! Falls back to the image centre, with the reason, when
//! - the flash does not dominate: the fitted flash part is less than
//!   [`RobustDetector::min_flash_share`] of the mean intensity (ambient or black photos);
//! - the highlight is implausibly far: more than [`RobustDetector::max_offset`] of the width
//!   from the centre, where too little of the lobe is inside the photo to pin it down;
//! - the fit does not converge to a finite position.

use photomat_core::Result;
use photomat_core::image_io::PlanarImage;

use super::intensity::min_rgb_linear;
use super::{Detection, HighlightDetector, PHOTO_SIDE};

/// Configuration of the robust detector; every field has a documented default.
#[derive(Debug, Clone)]
pub struct RobustDetector {
    /// Approximate cells per side of the fitting grid (default 64: blocks of 8×8 pixels at 512²,
    /// 1/64 of the width, enough to sample a lobe of α ≥ 0.03 and fast: ~4 k residuals).
    pub grid: usize,
    /// Largest accepted distance of the highlight from the centre, fraction of the width
    /// (default 0.4: at least 10 % of the width between highlight and border, so the symmetric
    /// fitting domain still holds a lobe's core).
    pub max_offset: f64,
    /// Smallest accepted share of the flash in the mean intensity of the fitting domain
    /// (default 0.25: the paper asks for photos in which the flash dominates; below a quarter,
    /// ambient light or a black sample leaves too little falloff to localise).
    pub min_flash_share: f64,
}

impl Default for RobustDetector {
    fn default() -> Self {
        Self {
            grid: 64,
            max_offset: 0.4,
            min_flash_share: 0.25,
        }
    }
}

/// Smallest half-side of the fitting square, plane units (the photo spans [−1, 1]²): 0.5 keeps
/// at least a quarter of the photo in the fit when the highlight is near the border.
pub const MIN_DOMAIN_HALF: f64 = 0.5;

/// Linear intensity at or above which a block counts as saturated: an 8-bit 255 linearises to 1,
/// the mid-point to 254 to (254.5/255)^2.2 = 0.9957.
const SATURATED: f64 = 0.995;

/// Starting lobe widths α for the search: from a mirror-like lobe of a few pixels to a rough
/// one wider than the photo, a factor ≈2 apart so one of them is within the basin.
const ALPHA_STARTS: [f64; 7] = [0.015, 0.03, 0.06, 0.12, 0.25, 0.5, 1.0];

/// α is searched in [ALPHA_MIN, ALPHA_MAX]: below 0.005 the lobe is far narrower than one grid
/// cell, above 3 it is flatter than the diffuse profile and indistinguishable from it.
const ALPHA_MIN: f64 = 0.005;
const ALPHA_MAX: f64 = 3.0;

/// Cauchy tuning constant (95 % efficiency under Gaussian noise, Holland & Welsch 1977).
const CAUCHY_C: f64 = 2.385;

/// IRLS rounds: weights and fitting domain are re-estimated this often; the position moves by
/// less than 0.01 pixel after the third round on every simulated family.
const IRLS_ROUNDS: usize = 4;

/// One grid cell: plane position, mean linear intensity, whether it is usable.
#[derive(Debug, Clone, Copy)]
struct Cell {
    x: f64,
    y: f64,
    r2: f64,
    y_lin: f64,
    usable: bool,
}

/// A fitted model: position, lobe width, linear coefficients and weighted cost.
#[derive(Debug, Clone, Copy)]
struct Fit {
    lx: f64,
    ly: f64,
    alpha: f64,
    coef: [f64; 5],
    cost: f64,
}

impl HighlightDetector for RobustDetector {
    fn name(&self) -> &'static str {
        "robust"
    }

    fn detect(&self, image: &PlanarImage) -> Result<Detection> {
        let intensity = min_rgb_linear(image)?;
        let (h, w) = (image.height, image.width);
        let cells = self.cells(&intensity, h, w);
        let usable: Vec<&Cell> = cells.iter().filter(|c| c.usable).collect();
        let mean = usable.iter().map(|c| c.y_lin).sum::<f64>() / usable.len().max(1) as f64;
        if usable.len() < 16 || mean <= 0.0 {
            return Ok(Detection::fallback(
                h,
                w,
                "no usable pixels: the image is black or saturated",
            ));
        }
        // Relative residuals are taken against at least 2 % of the mean intensity, so black
        // texels (noise only) cannot dominate the fit.
        let floor = 0.02 * mean;
        let mut weights: Vec<f64> = cells
            .iter()
            .map(|c| {
                if c.usable {
                    1.0 / c.y_lin.max(floor).powi(2)
                } else {
                    0.0
                }
            })
            .collect();
        let half_h = h as f64 / w as f64; // plane half-height (the width spans [−1, 1])
        let mut fit = self.initial_fit(&cells, &weights, half_h);
        for _ in 0..IRLS_ROUNDS {
            let domain = domain_weights(&cells, fit.lx, fit.ly, half_h);
            let base: Vec<f64> = weights.iter().zip(&domain).map(|(w, d)| w * d).collect();
            fit = nelder_mead(&cells, &base, fit);
            weights = reweight(&cells, &fit, floor);
        }
        if !(fit.lx.is_finite() && fit.ly.is_finite()) {
            return Ok(Detection::fallback(h, w, "the flash model fit did not converge"));
        }
        let scale = w as f64 / PHOTO_SIDE;
        let (row, col) = (h as f64 / 2.0 - fit.ly * scale, w as f64 / 2.0 + fit.lx * scale);
        let offset = fit.lx.hypot(fit.ly) / PHOTO_SIDE;
        if offset > self.max_offset {
            return Ok(Detection::fallback(
                h,
                w,
                format!(
                    "fitted highlight ({row:.1}, {col:.1}) is {:.0} % of the width from the centre \
                     (limit {:.0} %)",
                    100.0 * offset,
                    100.0 * self.max_offset
                ),
            ));
        }
        let share = flash_share(&cells, &fit, half_h);
        if share < self.min_flash_share {
            return Ok(Detection::fallback(
                h,
                w,
                format!(
                    "the flash does not dominate: it explains {:.0} % of the intensity around \
                     the highlight (limit {:.0} %); ambient light or a black sample",
                    100.0 * share,
                    100.0 * self.min_flash_share
                ),
            ));
        }
        Ok(Detection::detected(row, col, h, w))
    }
}

impl RobustDetector {
    /// Block averages of the intensity on a grid of about `self.grid` cells across the width.
    fn cells(&self, intensity: &[f64], h: usize, w: usize) -> Vec<Cell> {
        let k = (w / self.grid.max(1)).max(1);
        let (rows, cols) = ((h / k).max(1), (w / k).max(1));
        let (kr, kc) = (k.min(h), k.min(w));
        let scale = PHOTO_SIDE / w as f64;
        let mut cells = Vec::with_capacity(rows * cols);
        for bi in 0..rows {
            for bj in 0..cols {
                let (mut sum, mut saturated) = (0.0, false);
                for i in bi * kr..(bi + 1) * kr {
                    for &v in &intensity[i * w + bj * kc..i * w + (bj + 1) * kc] {
                        sum += v;
                        saturated |= v >= SATURATED;
                    }
                }
                let row = (bi as f64 + 0.5) * kr as f64;
                let col = (bj as f64 + 0.5) * kc as f64;
                let (x, y) = ((col - w as f64 / 2.0) * scale, (h as f64 / 2.0 - row) * scale);
                cells.push(Cell {
                    x,
                    y,
                    r2: x * x + y * y,
                    y_lin: sum / (kr * kc) as f64,
                    usable: !saturated,
                });
            }
        }
        cells
    }

    /// Best of a few starting positions (brightest blurred cell, above-mean centroid, image
    /// centre) × [`ALPHA_STARTS`], scored on the whole image.
    fn initial_fit(&self, cells: &[Cell], weights: &[f64], half_h: f64) -> Fit {
        let mut starts = vec![(0.0, 0.0)];
        if let Some(c) = brightest(cells) {
            starts.push(c);
        }
        let mean = cells.iter().map(|c| c.y_lin).sum::<f64>() / cells.len() as f64;
        let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for c in cells.iter().filter(|c| c.y_lin > mean) {
            s += c.y_lin;
            sx += c.y_lin * c.x;
            sy += c.y_lin * c.y;
        }
        if s > 0.0 {
            starts.push((sx / s, sy / s));
        }
        let mut best: Option<Fit> = None;
        for &(lx, ly) in &starts {
            let domain = domain_weights(cells, lx, ly, half_h);
            let base: Vec<f64> = weights.iter().zip(&domain).map(|(w, d)| w * d).collect();
            for &alpha in &ALPHA_STARTS {
                let fit = solve(cells, &base, lx, ly, alpha);
                // Compare starts by cost per unit of domain weight: domains differ in size.
                let norm = base.iter().sum::<f64>().max(f64::MIN_POSITIVE);
                let fit = Fit {
                    cost: fit.cost / norm,
                    ..fit
                };
                if best.is_none_or(|b| fit.cost < b.cost) {
                    best = Some(fit);
                }
            }
        }
        best.expect("at least one start")
    }
}

/// Centre of the brightest cell after a 5×5 box blur (the blur keeps single hot texels
/// and sparkles from winning).
fn brightest(cells: &[Cell]) -> Option<(f64, f64)> {
    let n = (cells.len() as f64).sqrt() as usize;
    if n * n != cells.len() || n < 5 {
        return cells
            .iter()
            .max_by(|a, b| a.y_lin.total_cmp(&b.y_lin))
            .map(|c| (c.x, c.y));
    }
    let mut best = (f64::NEG_INFINITY, 0);
    for i in 2..n - 2 {
        for j in 2..n - 2 {
            let mut s = 0.0;
            for di in 0..5 {
                for dj in 0..5 {
                    s += cells[(i + di - 2) * n + j + dj - 2].y_lin;
                }
            }
            if s > best.0 {
                best = (s, i * n + j);
            }
        }
    }
    Some((cells[best.1].x, cells[best.1].y))
}

/// 1 inside the largest square centred on (lx, ly) within the photo (half-side at least
/// [`MIN_DOMAIN_HALF`]), 0 outside.
fn domain_weights(cells: &[Cell], lx: f64, ly: f64, half_h: f64) -> Vec<f64> {
    let half = (1.0 - lx.abs())
        .min(half_h - ly.abs())
        .max(MIN_DOMAIN_HALF);
    cells
        .iter()
        .map(|c| {
            if (c.x - lx).abs() <= half && (c.y - ly).abs() <= half {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// The five basis functions at a cell for flash point (lx, ly) and lobe width α.
#[inline]
fn basis(c: &Cell, lx: f64, ly: f64, alpha2: f64) -> [f64; 5] {
    let s2 = (c.x - lx).powi(2) + (c.y - ly).powi(2);
    let q = 1.0 + s2;
    let root = q.sqrt();
    let g_d = 1.0 / (q * root);
    let lobe = alpha2 / (alpha2 + s2);
    let g_s = lobe * lobe * q * root;
    [g_d, g_s, -c.r2 * g_d, -c.r2 * g_s, 1.0]
}

/// Weighted least-squares coefficients for fixed (lx, ly, α); flash coefficients must be
/// non-negative (a dip is not a flash), so a fit violating that is redone without the
/// offending profile.
fn solve(cells: &[Cell], weights: &[f64], lx: f64, ly: f64, alpha: f64) -> Fit {
    let alpha2 = alpha * alpha;
    let mut ata = [[0.0f64; 5]; 5];
    let mut atb = [0.0f64; 5];
    let mut btb = 0.0;
    for (c, &wt) in cells.iter().zip(weights) {
        if wt == 0.0 {
            continue;
        }
        let b = basis(c, lx, ly, alpha2);
        for i in 0..5 {
            let wb = wt * b[i];
            atb[i] += wb * c.y_lin;
            for j in i..5 {
                ata[i][j] += wb * b[j];
            }
        }
        btb += wt * c.y_lin * c.y_lin;
    }
    for i in 0..5 {
        for j in 0..i {
            ata[i][j] = ata[j][i];
        }
    }
    // Subsets: both profiles; diffuse only (drop g_s and its vignetting); specular only.
    const SUBSETS: [&[usize]; 3] = [&[0, 1, 2, 3, 4], &[0, 2, 4], &[1, 3, 4]];
    let mut best = Fit {
        lx,
        ly,
        alpha,
        coef: [0.0; 5],
        cost: btb,
    };
    for subset in SUBSETS {
        let Some(x) = solve_subset(&ata, &atb, subset) else {
            continue;
        };
        let mut coef = [0.0; 5];
        for (k, &i) in subset.iter().enumerate() {
            coef[i] = x[k];
        }
        if coef[0] < 0.0 || coef[1] < 0.0 {
            continue;
        }
        // Weighted SSE = yᵀWy − 2 xᵀAᵀWy + xᵀAᵀWAx = yᵀWy − xᵀAᵀWy at the LS solution.
        let cost = btb - subset.iter().zip(&x).map(|(&i, xi)| xi * atb[i]).sum::<f64>();
        if cost < best.cost {
            best.coef = coef;
            best.cost = cost.max(0.0);
        }
    }
    best
}

/// Solve the normal equations restricted to `subset` by Cholesky; `None` if singular.
fn solve_subset(ata: &[[f64; 5]; 5], atb: &[f64; 5], subset: &[usize]) -> Option<Vec<f64>> {
    let n = subset.len();
    let mut l = vec![0.0f64; n * n];
    // A relative ridge of 1e-12 keeps nearly collinear profiles (α ≫ 1) solvable without
    // changing well-posed solutions beyond f64 rounding.
    let ridge = 1e-12 * subset.iter().map(|&i| ata[i][i]).sum::<f64>();
    for i in 0..n {
        for j in 0..=i {
            let mut s = ata[subset[i]][subset[j]] + if i == j { ridge } else { 0.0 };
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s <= 0.0 {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut z = vec![0.0; n];
    for i in 0..n {
        let mut s = atb[subset[i]];
        for k in 0..i {
            s -= l[i * n + k] * z[k];
        }
        z[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = z[i];
        for k in i + 1..n {
            s -= l[k * n + i] * z[k];
        }
        z[i] = s / l[i * n + i];
    }
    Some(z)
}

/// Model value at a cell.
fn model(c: &Cell, fit: &Fit) -> f64 {
    let b = basis(c, fit.lx, fit.ly, fit.alpha * fit.alpha);
    b.iter().zip(&fit.coef).map(|(b, k)| b * k).sum()
}

/// IRLS weights: relative residuals (against the model, floored) with Cauchy down-weighting
/// at a scale of 1.4826 × their median absolute value.
fn reweight(cells: &[Cell], fit: &Fit, floor: f64) -> Vec<f64> {
    let rel: Vec<Option<(f64, f64)>> = cells
        .iter()
        .map(|c| {
            c.usable.then(|| {
                let m = model(c, fit).max(floor);
                ((c.y_lin - m) / m, m)
            })
        })
        .collect();
    let mut abs: Vec<f64> = rel.iter().flatten().map(|(r, _)| r.abs()).collect();
    abs.sort_unstable_by(f64::total_cmp);
    // 1e-3 keeps noise-free synthetic images from getting an infinite weight scale.
    let sigma = (1.4826 * abs.get(abs.len() / 2).copied().unwrap_or(0.0)).max(1e-3);
    rel.iter()
        .map(|r| match r {
            Some((r, m)) => {
                let u = r / (CAUCHY_C * sigma);
                1.0 / (m * m * (1.0 + u * u))
            }
            None => 0.0,
        })
        .collect()
}

/// Share of the fitted flash (everything but the ambient constant) in the fitted intensity,
/// averaged over the fitting domain.
fn flash_share(cells: &[Cell], fit: &Fit, half_h: f64) -> f64 {
    let domain = domain_weights(cells, fit.lx, fit.ly, half_h);
    let (mut flash, mut total) = (0.0, 0.0);
    for (c, d) in cells.iter().zip(domain) {
        if d > 0.0 {
            let m = model(c, fit);
            flash += m - fit.coef[4];
            total += m;
        }
    }
    if total > 0.0 { flash / total } else { 0.0 }
}

/// Nelder–Mead over (lx, ly, ln α) with the linear coefficients solved at every vertex;
/// standard coefficients (reflection 1, expansion 2, contraction ½, shrink ½).
fn nelder_mead(cells: &[Cell], weights: &[f64], start: Fit) -> Fit {
    // Initial steps: 0.04 plane units (1 % of the side-2 width ≈ 10 px at 512²) and a factor
    // 1.5 in α; the search stops when the simplex spans less than 1e-4 units (0.005 % width).
    const STEP_POS: f64 = 0.04;
    const STEP_LOG_ALPHA: f64 = 0.4;
    const TOLERANCE: f64 = 1e-4;
    const MAX_EVALS: usize = 300;
    let eval = |p: [f64; 3]| -> Fit {
        let alpha = p[2].exp().clamp(ALPHA_MIN, ALPHA_MAX);
        solve(cells, weights, p[0], p[1], alpha)
    };
    let p0 = [start.lx, start.ly, start.alpha.ln()];
    let mut simplex: Vec<([f64; 3], Fit)> = vec![(p0, eval(p0))];
    for (k, step) in [STEP_POS, STEP_POS, STEP_LOG_ALPHA].into_iter().enumerate() {
        let mut p = p0;
        p[k] += step;
        simplex.push((p, eval(p)));
    }
    let mut evals = 4;
    while evals < MAX_EVALS {
        simplex.sort_by(|a, b| a.1.cost.total_cmp(&b.1.cost));
        let spread = simplex[1..]
            .iter()
            .map(|(p, _)| (p[0] - simplex[0].0[0]).hypot(p[1] - simplex[0].0[1]))
            .fold(0.0, f64::max);
        if spread < TOLERANCE {
            break;
        }
        let mut centroid = [0.0; 3];
        for (p, _) in &simplex[..3] {
            for k in 0..3 {
                centroid[k] += p[k] / 3.0;
            }
        }
        let worst = simplex[3].clone();
        let along = |t: f64| -> [f64; 3] {
            let mut p = [0.0; 3];
            for k in 0..3 {
                p[k] = centroid[k] + t * (worst.0[k] - centroid[k]);
            }
            p
        };
        let reflected = along(-1.0);
        let fr = eval(reflected);
        evals += 1;
        if fr.cost < simplex[0].1.cost {
            let expanded = along(-2.0);
            let fe = eval(expanded);
            evals += 1;
            simplex[3] = if fe.cost < fr.cost {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr.cost < simplex[2].1.cost {
            simplex[3] = (reflected, fr);
        } else {
            let contracted = if fr.cost < worst.1.cost {
                along(-0.5)
            } else {
                along(0.5)
            };
            let fc = eval(contracted);
            evals += 1;
            if fc.cost < worst.1.cost.min(fr.cost) {
                simplex[3] = (contracted, fc);
            } else {
                let best = simplex[0].0;
                for vertex in simplex.iter_mut().skip(1) {
                    let mut p = [0.0; 3];
                    for k in 0..3 {
                        p[k] = best[k] + 0.5 * (vertex.0[k] - best[k]);
                    }
                    *vertex = (p, eval(p));
                    evals += 1;
                }
            }
        }
    }
    simplex
        .into_iter()
        .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))
        .map(|(_, f)| f)
        .expect("four vertices")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::highlight::DetectionStatus;

    /// A noise-free grey photo rendered from the detector's own model.
    fn synthetic(size: usize, lx: f64, ly: f64, alpha: f64, vignetting: f64) -> PlanarImage {
        let mut data = Vec::with_capacity(size * size);
        for row in 0..size {
            for col in 0..size {
                let x = ((col as f64 + 0.5) / size as f64) * 2.0 - 1.0;
                let y = 1.0 - ((row as f64 + 0.5) / size as f64) * 2.0;
                let s2 = (x - lx).powi(2) + (y - ly).powi(2);
                let q = 1.0 + s2;
                let lobe = (alpha * alpha / (alpha * alpha + s2)).powi(2) * q.powf(1.5);
                let v = 1.0 - vignetting * (x * x + y * y);
                let lin = v * (0.5 * q.powf(-1.5) + 0.4 * lobe) + 0.01;
                data.push(lin.powf(1.0 / 2.2) as f32);
            }
        }
        PlanarImage::new(1, size, size, data).unwrap()
    }

    #[test]
    fn robust_recovers_its_own_model_exactly() {
        for (lx, ly, alpha) in [(0.1, -0.15, 0.1), (-0.3, 0.2, 0.4), (0.0, 0.0, 0.05)] {
            let image = synthetic(128, lx, ly, alpha, 0.2);
            let d = RobustDetector::default().detect(&image).unwrap();
            assert_eq!(d.status, DetectionStatus::Detected, "{d:?}");
            let h = d.highlight();
            // 0.002 plane units = 0.1 % of the width: the grid and f32 input limit the rest.
            assert!((h.x - lx).abs() < 2e-3 && (h.y - ly).abs() < 2e-3, "{h:?} vs ({lx}, {ly})");
        }
    }

    #[test]
    fn robust_falls_back_on_black_and_flat_images() {
        let detector = RobustDetector::default();
        let black = detector.detect(&PlanarImage::filled(3, 64, 64, 0.0)).unwrap();
        assert_eq!(black.status, DetectionStatus::FallbackCentre);
        let flat = detector.detect(&PlanarImage::filled(3, 64, 64, 0.5)).unwrap();
        assert_eq!(flat.status, DetectionStatus::FallbackCentre, "{flat:?}");
        assert!(flat.reason.unwrap().contains("does not dominate"));
    }
}
