//! The photo's unknown camera terms, fitted with the maps: an exposure gain and, optionally,
//! the lens's residual vignetting and the room's ambient light (docs/capture.md, "Fit").
//!
//! A fitted render is exposed as `e^g · V(ρ) · (radiance + c · A)` with
//!
//! `V(ρ) = 1 − a · ρ²`,  `ρ² = (u² + v²) / 2`,
//!
//! where `(u, v) ∈ [−1, 1]²` are the texel centre's coordinates on the captured square (ρ = 1
//! in its corners) and `a ∈ (0, 1)` the vignetting strength, the corners' light loss. This is
//! the low-order term of both the cos⁴ law (`1 − v + v·cos⁴θ ≈ 1 − 2v·tan²θ`, the robust
//! highlight detector's model) and of the quadratic falloff that phone pipelines leave after
//! lens-shading correction. `a` is fitted through a logistic (`a = σ(t)`), which keeps it
//! inside (0, 1) without a clamp.
//!
//! `c · A` is the light of a dim, uniform white sky (a lit room) reflected by the maps:
//! `A` their reflectance under it ([`photomat_core::MaterialMaps::ambient_reflectance`]: the
//! diffuse albedo plus the specular F0) and `c ≥ 0` its radiance in the flash's units (a
//! white Lambertian texel straight under the flash at height 1 reflects 1). The photo
//! simulator lights its photos the same way (`photomat_data::simulator::camera`). `c` is
//! fitted as `e^k`, which keeps it positive without a clamp. A model with neither map has no
//! ambient term.

use candle_core::{DType, Device, Tensor, Var};

/// Vignetting strength a fit starts from: a tenth of the light lost in the corners, a
/// mid-range phone after its lens-shading correction.
pub const START_VIGNETTING: f64 = 0.1;

/// Ambient radiance a fit starts from: 1 % of the flash's at the centre, a dim room; the
/// simulator's phone photos draw it from 0–4 %.
pub const START_AMBIENT: f64 = 0.01;

/// The fitted camera terms of a capture.
pub struct CameraTerms {
    log_gain: Var,
    /// The logit t of the vignetting strength a = σ(t), when it is fitted.
    vignetting_logit: Option<Var>,
    /// The log k of the ambient radiance c = e^k, when it is fitted.
    ambient_log: Option<Var>,
}

impl CameraTerms {
    /// Terms starting at gain `e^log_gain`, vignetting strength `vignetting` (none: V = 1)
    /// and ambient radiance `ambient` (none: a dark room); a strength must lie in (0, 1) and
    /// an ambient radiance be positive.
    pub fn new(
        log_gain: f64,
        vignetting: Option<f64>,
        ambient: Option<f64>,
    ) -> candle_core::Result<Self> {
        let scalar = |v: f64| Var::from_tensor(&Tensor::new(&[v as f32], &Device::Cpu)?);
        if let Some(a) = vignetting.filter(|a| !(*a > 0.0 && *a < 1.0)) {
            candle_core::bail!("vignetting strength {a} is outside (0, 1)");
        }
        if let Some(c) = ambient.filter(|c| !(*c > 0.0 && c.is_finite())) {
            candle_core::bail!("ambient radiance {c} is not a positive number");
        }
        Ok(Self {
            log_gain: scalar(log_gain)?,
            vignetting_logit: vignetting
                .map(|a| scalar((a / (1.0 - a)).ln()))
                .transpose()?,
            ambient_log: ambient.map(|c| scalar(c.ln())).transpose()?,
        })
    }

    /// The variables an optimiser steps, named.
    pub fn vars(&self) -> Vec<(String, Var)> {
        let mut vars = vec![("log_gain".to_string(), self.log_gain.clone())];
        if let Some(t) = &self.vignetting_logit {
            vars.push(("vignetting_logit".to_string(), t.clone()));
        }
        if let Some(k) = &self.ambient_log {
            vars.push(("ambient_log".to_string(), k.clone()));
        }
        vars
    }

    /// `radiance` (B, 3, N, N) under the flash, plus the ambient light reflected by
    /// `reflectance` (B, 3, N, N; [`photomat_core::MaterialMaps::ambient_reflectance`]) when
    /// the ambient term is fitted, exposed by the gain and the vignetting over `rho2`
    /// ([`rho_squared`] of the same N).
    pub fn expose(
        &self,
        radiance: &Tensor,
        reflectance: Option<&Tensor>,
        rho2: &Tensor,
    ) -> candle_core::Result<Tensor> {
        let lit = match (&self.ambient_log, reflectance) {
            (Some(k), Some(a)) => (radiance + a.broadcast_mul(&k.as_tensor().exp()?)?)?,
            _ => radiance.clone(),
        };
        let exposed = lit.broadcast_mul(&self.log_gain.as_tensor().exp()?)?;
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

    /// Whether the ambient term is fitted: only then does [`Self::expose`] read a
    /// reflectance.
    pub fn fits_ambient(&self) -> bool {
        self.ambient_log.is_some()
    }

    /// The ambient radiance c, when it is fitted.
    pub fn ambient(&self) -> candle_core::Result<Option<f64>> {
        self.ambient_log
            .as_ref()
            .map(|k| Ok((k.as_tensor().to_vec1::<f32>()?[0] as f64).exp()))
            .transpose()
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
        let terms = CameraTerms::new(0.0, Some(0.3), None).unwrap();
        assert!((terms.vignetting().unwrap().unwrap() - 0.3).abs() < 1e-6);
        let ones = Tensor::ones((1, 3, n, n), DType::F32, &Device::Cpu).unwrap();
        let exposed = terms.expose(&ones, None, &rho_squared(n).unwrap()).unwrap();
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
        let plain = CameraTerms::new(2f64.ln(), None, None).unwrap();
        let doubled = plain.expose(&ones, None, &rho_squared(n).unwrap()).unwrap();
        let max = doubled.max_all().unwrap().to_scalar::<f32>().unwrap();
        let min = doubled.min_all().unwrap().to_scalar::<f32>().unwrap();
        assert!((max - 2.0).abs() < 1e-6 && (min - 2.0).abs() < 1e-6);
        assert!(plain.vignetting().unwrap().is_none());
    }

    #[test]
    fn ambient_light_adds_its_radiance_times_the_reflectance_before_the_exposure() {
        let (n, dev) = (8, Device::Cpu);
        let radiance = Tensor::full(0.5f32, (1, 3, n, n), &dev).unwrap();
        let reflectance = Tensor::full(0.25f32, (1, 3, n, n), &dev).unwrap();
        let rho2 = rho_squared(n).unwrap();
        let terms = CameraTerms::new(3f64.ln(), None, Some(0.04)).unwrap();
        assert!((terms.ambient().unwrap().unwrap() - 0.04).abs() < 1e-7);
        let exposed = terms.expose(&radiance, Some(&reflectance), &rho2).unwrap();
        // 3 · (0.5 + 0.04 · 0.25) = 1.53 everywhere.
        let (lo, hi) = (
            exposed.min_all().unwrap().to_scalar::<f32>().unwrap(),
            exposed.max_all().unwrap().to_scalar::<f32>().unwrap(),
        );
        assert!(
            (lo - 1.53).abs() < 1e-6 && (hi - 1.53).abs() < 1e-6,
            "{lo} {hi}"
        );
        // A model without a reflectance map has no ambient term.
        let dark = terms.expose(&radiance, None, &rho2).unwrap();
        let max = dark.max_all().unwrap().to_scalar::<f32>().unwrap();
        assert!((max - 1.5).abs() < 1e-6);
        assert_eq!(terms.vars().len(), 2);
        assert!(CameraTerms::new(0.0, None, Some(0.0)).is_err());
        assert!(CameraTerms::new(0.0, Some(1.0), None).is_err());
    }
}
