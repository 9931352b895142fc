//! Reflectance lobes that models sum: Lambert diffuse and the GGX microfacet specular lobe.
//!
//! Both return the lobe's `f·cos θ_o`, masked to exactly 0 below the horizon. The specular
//! lobe is `D·F·G / (4 cos θ_i cos θ_o) · cos θ_o = D·F·G / (4 cos θ_i)` (Walter et al. 2007;
//! Mitsuba's `principled` with metallic = 1); the diffuse lobe is `ρ/π · cos θ_o`.
//!
//! Shapes: albedos (B|1, 3, H|1, W|1), roughness (B|1, 1, H|1, W|1), result (B, 3, H, W).

use std::f64::consts::PI;

use candle_core::Tensor;

use crate::Result;
use crate::microfacet::{alpha_from_roughness, ggx_d, schlick, smith_g};
use crate::shading::ShadingGeometry;

/// Lambert: `ρ/π · cos θ_o`.
pub fn lambert(geometry: &ShadingGeometry, albedo: &Tensor) -> Result<Tensor> {
    let weight = (geometry.cos_o.broadcast_mul(&geometry.mask)? / PI)?;
    Ok(albedo.broadcast_mul(&weight)?)
}

/// GGX specular with Schlick Fresnel (`f0` = specular albedo) and `α = roughness²`.
pub fn ggx_specular(geometry: &ShadingGeometry, f0: &Tensor, roughness: &Tensor) -> Result<Tensor> {
    let alpha = alpha_from_roughness(roughness)?;
    let d = ggx_d(&geometry.cos_h, &alpha)?;
    let g = smith_g(&geometry.cos_i, &geometry.cos_o, &alpha)?;
    let f = schlick(&geometry.cos_d, f0)?;
    let scalar = (d.broadcast_mul(&g)?.broadcast_div(&geometry.cos_i)? * 0.25)?
        .broadcast_mul(&geometry.mask)?;
    Ok(f.broadcast_mul(&scalar)?)
}
