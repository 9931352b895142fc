//! Heights from normal maps: the periodic least-squares integration of a slope field, and the
//! height map of photomat's `height(·)` adapter that holds the result (docs/conventions.md,
//! "Heights of imported materials").
//!
//! The height adapter turns a height `H` (world units) into normals by central differences
//! over one texel on each side, wrapping around (`brdf-plugins/src/height.rs`). The height
//! whose central differences best match slopes `(p, q)` in the least-squares sense,
//! `min Σ |D_x H − p|² + |D_y H − q|²`, is diagonal in the discrete Fourier basis of the
//! periodic grid (Frankot & Chellappa 1988, with the adapter's difference operators instead of
//! the continuous derivative): with `D_x = i·sin(ω_x)/Δ` and, y up (row index growing
//! downwards), `D_y = −i·sin(ω_y)/Δ`,
//!
//! `Ĥ = (conj(D_x)·P̂ + conj(D_y)·Q̂) / (|D_x|² + |D_y|² + ε·R)`,
//!
//! with `R = ((1 − cos ω_x)² + (1 − cos ω_y)²) / (4Δ²)`. Central differences cannot see
//! frequencies near Nyquist (`sin ω → 0` at `ω = π`), where the plain solution would amplify
//! the slopes' texel noise without bound; `ε·R` vanishes as `ω⁴` at low frequencies and bounds
//! that gain ([`NYQUIST_DAMPING`]). The mean height is 0.
//!
//! A height of range `[H_min, H_max]` is stored as the adapter's map `h = (H − H_min)/S` in
//! [0, 1] with `scale = S = H_max − H_min` ([`HeightMap`]), so nothing clips and the adapter's
//! normals are those of `H` exactly.

use rustfft::FftPlanner;
use rustfft::num_complex::Complex64;

/// ε of the module docs: the slope noise at the highest frequencies is amplified at most
/// `1/(2√ε)` = 5×, and below half of Nyquist the solution differs from the undamped one by
/// under 0.3 % (`ε·R / sin²ω` ≤ 0.01·(1−cos ω)²/(4 sin²ω) there).
pub const NYQUIST_DAMPING: f64 = 0.01;

/// Smallest relief range a height map records: below a millionth of a world unit (a micron on
/// the photos' 10 cm swatch) the material is flat, and dividing by the range would only
/// amplify rounding.
pub const MIN_SCALE: f64 = 1e-6;

/// The height `H` (world units, zero mean) whose central differences over texels of `texel`
/// world units best match the slopes `p = ∂H/∂x`, `q = ∂H/∂y` (y up) of a periodic
/// `width`×`height` grid, row-major (module docs).
pub fn integrate_periodic(
    p: &[f64],
    q: &[f64],
    width: usize,
    height: usize,
    texel: f64,
) -> Vec<f64> {
    let n = width * height;
    assert_eq!(p.len(), n, "p must hold width × height slopes");
    assert_eq!(q.len(), n, "q must hold width × height slopes");
    let mut planner = FftPlanner::<f64>::new();
    let mut ph: Vec<Complex64> = p.iter().map(|&v| Complex64::new(v, 0.0)).collect();
    let mut qh: Vec<Complex64> = q.iter().map(|&v| Complex64::new(v, 0.0)).collect();
    fft2(&mut planner, &mut ph, width, height, false);
    fft2(&mut planner, &mut qh, width, height, false);
    let tau = std::f64::consts::TAU;
    let mut hh = vec![Complex64::new(0.0, 0.0); n];
    for r in 0..height {
        let wy = tau * r as f64 / height as f64;
        for c in 0..width {
            let wx = tau * c as f64 / width as f64;
            let dx = Complex64::new(0.0, wx.sin() / texel);
            let dy = Complex64::new(0.0, -wy.sin() / texel);
            let damping = NYQUIST_DAMPING * ((1.0 - wx.cos()).powi(2) + (1.0 - wy.cos()).powi(2))
                / (4.0 * texel * texel);
            let denominator = dx.norm_sqr() + dy.norm_sqr() + damping;
            let i = r * width + c;
            // The mean (ω = 0) is not determined by slopes: it stays 0.
            if denominator > 0.0 {
                hh[i] = (dx.conj() * ph[i] + dy.conj() * qh[i]) / denominator;
            }
        }
    }
    fft2(&mut planner, &mut hh, width, height, true);
    let scale = 1.0 / n as f64;
    hh.iter().map(|v| v.re * scale).collect()
}

/// In-place 2-D DFT of a row-major `width`×`height` grid (unnormalised; `inverse` flips the
/// exponent's sign).
fn fft2(
    planner: &mut FftPlanner<f64>,
    data: &mut [Complex64],
    width: usize,
    height: usize,
    inverse: bool,
) {
    let row_fft = if inverse {
        planner.plan_fft_inverse(width)
    } else {
        planner.plan_fft_forward(width)
    };
    for row in data.chunks_exact_mut(width) {
        row_fft.process(row);
    }
    let col_fft = if inverse {
        planner.plan_fft_inverse(height)
    } else {
        planner.plan_fft_forward(height)
    };
    let mut column = vec![Complex64::new(0.0, 0.0); height];
    for c in 0..width {
        for r in 0..height {
            column[r] = data[r * width + c];
        }
        col_fft.process(&mut column);
        for r in 0..height {
            data[r * width + c] = column[r];
        }
    }
}

/// A height as the `height(·)` adapter's map: values in [0, 1] and the scale that makes them
/// world units (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct HeightMap {
    /// `(H − H_min) / scale`, row-major.
    pub values: Vec<f32>,
    /// World units of a map value of 1 (the adapter's `scale`), at least [`MIN_SCALE`].
    pub scale: f64,
}

impl HeightMap {
    /// The map of heights `h` (world units).
    pub fn from_heights(h: &[f64]) -> Self {
        let lo = h.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let scale = (hi - lo).max(MIN_SCALE);
        let values = h
            .iter()
            .map(|&v| ((v - lo) / scale).clamp(0.0, 1.0) as f32)
            .collect();
        Self { values, scale }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::normals::tests::{stored_normals, test_height};
    use crate::normals::{decode, slopes};

    #[test]
    fn heights_to_normals_to_heights_is_the_identity_on_smooth_reliefs() {
        // Heights in world units on texels of 1/64: the normals a height adapter derives from
        // them, stored as a (16-bit-exact, here f32) normal map, integrate back to the same
        // heights up to their mean.
        let side = 64;
        let texel = 1.0 / side as f64;
        let h_texels = test_height(side);
        let normal_map = stored_normals(&h_texels, side, false);
        let (p, q) = slopes(&decode(&normal_map, false));
        let h = integrate_periodic(&p, &q, side, side, 1.0);
        let mean = h_texels.iter().sum::<f64>() / h_texels.len() as f64;
        let amplitude = h_texels.iter().fold(0.0f64, |a, v| a.max((v - mean).abs()));
        let worst = h
            .iter()
            .zip(&h_texels)
            .fold(0.0f64, |a, (x, y)| a.max((x - (y - mean)).abs()));
        assert!(worst < 1e-3 * amplitude, "worst {worst} of {amplitude}");
        // In world units the same slopes give heights scaled by the texel.
        let world = integrate_periodic(&p, &q, side, side, texel);
        for (a, b) in world.iter().zip(&h) {
            assert!((a - b * texel).abs() < 1e-12);
        }
    }

    #[test]
    fn the_height_map_spans_zero_to_one_and_keeps_the_range_as_its_scale() {
        let map = HeightMap::from_heights(&[-0.01, 0.0, 0.03]);
        assert_eq!(map.values, [0.0, 0.25, 1.0]);
        assert!((map.scale - 0.04).abs() < 1e-15);
        let flat = HeightMap::from_heights(&[0.5, 0.5]);
        assert_eq!((flat.values, flat.scale), (vec![0.0, 0.0], MIN_SCALE));
    }
}
