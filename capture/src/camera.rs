//! The photo's unknown camera terms, fitted with the maps: an exposure gain and, optionally,
//! the lens's residual vignetting (docs/capture.md, "Fit").
//!
//! A fitted render is exposed as `e^g · V(ρ) · radiance` with
//!
//! `V(ρ) = 1 − a · ρ²`,  `ρ² = (u² + v²) / 2`,
//!
//! where `(u, v) ∈ [−1, 1]²` are the texel centre's coordinates on the captured square (ρ = 1
//! in its corners) and `a ∈ (0, 1)` the vignetting strength, the corners' light loss. This is
//! the low-order term of both the cos⁴ law (`1 − v + v·cos⁴θ ≈ 1 − 2v·tan²θ`, the robust
//! highlight detector's model) and of the quadratic falloff that phone pipelines leave after
//! lens-shading correction. `a` is fitted through a logistic (`a = σ(t)`), which keeps it
//! inside (0, 1) without a clamp.

use candle_core::{DType, Device, Tensor, Var};

/// Vignetting strength a fit starts from: a tenth of the light lost in the corners, a
/// mid-range phone after its lens-shading correction.
pub const START_VIGNETTING: f64 = 0.1;

/// The fitted camera terms of a capture.
pub struct CameraTerms {
    log_gain: Var,
    /// The logit t of the vignetting strength a = σ(t), when it is fitted.
    vignetting_logit: Option<Var>,
}

impl CameraTerms {
    /// Terms starting at gain `e^log_gain` and, when `vignetting`, at strength
    /// [`START_VIGNETTING`] (else none: V = 1).
    pub fn new(log_gain: f64, vignetting: Option<f64>) -> candle_core::Result<Self> {
        let scalar = |v: f64| Var::from_tensor(&Tensor::new(&[v as f32], &Device::Cpu)?);
        Ok(Self {
            log_gain: scalar(log_gain)?,
            vignetting_logit: vignetting
                .map(|a| scalar((a / (1.0 - a)).ln()))
                .transpose()?,
        })
    }

    /// The variables an optimiser steps, named.
    pub fn vars(&self) -> Vec<(String, Var)> {
        let mut vars = vec![("log_gain".to_string(), self.log_gain.clone())];
        if let Some(t) = &self.vignetting_logit {
            vars.push(("vignetting_logit".to_string(), t.clone()));
        }
        vars
    }

    /// `radiance` (B, 3, N, N) exposed by the gain and the vignetting over `rho2`
    /// ([`rho_squared`] of the same N).
    pub fn expose(&self, radiance: &Tensor, rho2: &Tensor) -> candle_core::Result<Tensor> {
        let exposed = radiance.broadcast_mul(&self.log_gain.as_tensor().exp()?)?;
        match &self.vignetting_logit {
            None => Ok(exposed),
            Some(t) => {
                let a = (t.as_tensor().neg()?.exp()? + 1.0)?.recip()?;
                let falloff = rho2.broadcast_mul(&a)?.affine(-1.0, 1.0)?;
                exposed.broadcast_mul(&falloff)
            }
        }
    }

    /// The gain's log.
    pub fn log_gain(&self) -> candle_core::Result<f64> {
        Ok(self.log_gain.as_tensor().to_vec1::<f32>()?[0] as f64)
    }

    /// The vignetting strength a, when it is fitted.
    pub fn vignetting(&self) -> candle_core::Result<Option<f64>> {
        self.vignetting_logit
            .as_ref()
            .map(|t| {
                let t = t.as_tensor().to_vec1::<f32>()?[0] as f64;
                Ok(1.0 / (1.0 + (-t).exp()))
            })
            .transpose()
    }
}

/// ρ² of the module docs on an N×N square: (1, 1, N, N), 0 at the centre, → 1 towards the
/// corners (the corner texels' centres are half a texel inside).
pub fn rho_squared(n: usize) -> candle_core::Result<Tensor> {
    let coordinate = |i: usize| (2.0 * i as f32 + 1.0) / n as f32 - 1.0;
    let values: Vec<f32> = (0..n * n)
        .map(|i| {
            let (u, v) = (coordinate(i % n), coordinate(i / n));
            (u * u + v * v) / 2.0
        })
        .collect();
    Tensor::from_vec(values, (1, 1, n, n), &Device::Cpu)?.to_dtype(DType::F32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vignetting_darkens_the_corners_by_its_strength_and_leaves_the_centre() {
        let n = 64;
        let terms = CameraTerms::new(0.0, Some(0.3)).unwrap();
        assert!((terms.vignetting().unwrap().unwrap() - 0.3).abs() < 1e-6);
        let ones = Tensor::ones((1, 3, n, n), DType::F32, &Device::Cpu).unwrap();
        let exposed = terms.expose(&ones, &rho_squared(n).unwrap()).unwrap();
        let at = |y: usize, x: usize| {
            exposed
                .get(0)
                .unwrap()
                .get(0)
                .unwrap()
                .get(y)
                .unwrap()
                .get(x)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
        };
        // The corner texel's centre is at u = v = ±(1 − 1/n): ρ² = (1 − 1/n)².
        let corner = 1.0 - 0.3 * (1.0 - 1.0 / n as f32).powi(2);
        assert!((at(0, 0) - corner).abs() < 1e-6, "{}", at(0, 0));
        assert!((at(n - 1, 0) - corner).abs() < 1e-6);
        // Next to the centre ρ² = 2 (1/n)² / 2.
        let centre = 1.0 - 0.3 / (n * n) as f32;
        assert!(
            (at(n / 2, n / 2) - centre).abs() < 1e-6,
            "{}",
            at(n / 2, n / 2)
        );
        // Without vignetting only the gain applies.
        let plain = CameraTerms::new(2f64.ln(), None).unwrap();
        let doubled = plain.expose(&ones, &rho_squared(n).unwrap()).unwrap();
        let max = doubled.max_all().unwrap().to_scalar::<f32>().unwrap();
        let min = doubled.min_all().unwrap().to_scalar::<f32>().unwrap();
        assert!((max - 2.0).abs() < 1e-6 && (min - 2.0).abs() < 1e-6);
        assert!(plain.vignetting().unwrap().is_none());
    }
}
