//! Reflectance lobes that models sum: Lambert diffuse and the GGX microfacet specular lobe.
//!
//! Both return the lobe's `f·cos θ_o`, masked to exactly 0 below the horizon. The specular
//! lobe is `D·F·G / (4 cos θ_i cos θ_o) · cos θ_o = D·F·G1(o)·(G1(i)/cos θ_i) / 4` (Walter et al.
//! 2007; Mitsuba's `principled` with metallic = 1), with `G1(i)/cos θ_i` in its division-free
//! form; the diffuse lobe is `ρ/π · cos θ_o`.
//!
//! Shapes: albedos (B|1, 3, H|1, W|1), roughness (B|1, 1, H|1, W|1), result (B, 3, H, W).

use std::f64::consts::PI;

use candle_core::Tensor;

use crate::Result;
use crate::microfacet::{alpha_from_roughness, ggx_d, schlick, smith_g1, smith_g1_over_cos};
use crate::shading::ShadingGeometry;

/// Lambert: `ρ/π · cos θ_o`.
pub fn lambert(geometry: &ShadingGeometry, albedo: &Tensor) -> Result<Tensor> {
    let weight = (geometry.cos_o.broadcast_mul(&geometry.mask)? / PI)?;
    Ok(albedo.broadcast_mul(&weight)?)
}

/// A GGX lobe with any Fresnel term: `fresnel · D·G1(o)·(G1(i)/cos θ_i) / 4`, masked.
/// `fresnel` (B|1, 3, H, W), `alpha` (B|1, 1, H|1, W|1). Models with their own Fresnel or α
/// mapping build on this.
pub fn ggx_lobe(geometry: &ShadingGeometry, fresnel: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    let d = ggx_d(&geometry.cos_h, &geometry.sin2_h, alpha)?;
    let g1_o = smith_g1(&geometry.cos_o, alpha)?;
    let g1_i_over_cos = smith_g1_over_cos(&geometry.cos_i, alpha)?;
    let scalar = (d.broadcast_mul(&g1_o)?.broadcast_mul(&g1_i_over_cos)? * 0.25)?
        .broadcast_mul(&geometry.mask)?;
    Ok(fresnel.broadcast_mul(&scalar)?)
}

/// GGX specular with Schlick Fresnel (`f0` = specular albedo) and `α = max(roughness², 1e-4)`.
pub fn ggx_specular(geometry: &ShadingGeometry, f0: &Tensor, roughness: &Tensor) -> Result<Tensor> {
    let alpha = alpha_from_roughness(roughness)?;
    ggx_lobe(geometry, &schlick(&geometry.cos_d, f0)?, &alpha)
}
