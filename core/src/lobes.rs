//! Reflectance lobes that models sum: Lambert diffuse, the GGX microfacet specular lobe (with
//! its masking and Fresnel choices, `microfacet::{Masking, FresnelTerm}`) and the cheap
//! Blinn-Phong lobe.
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
use crate::microfacet::{
    FresnelTerm, Masking, alpha_from_roughness, blinn_phong_d, ggx_d, schlick,
    smith_correlated_over_4cos, smith_g1, smith_g1_over_cos,
};
use crate::shading::ShadingGeometry;
use crate::texel_ops::scale_texels;

/// Lambert: `ρ/π · cos θ_o`.
pub fn lambert(geometry: &ShadingGeometry, albedo: &Tensor) -> Result<Tensor> {
    let weight = (geometry.cos_o.broadcast_mul(&geometry.mask)? / PI)?;
    scale_texels(albedo, &weight)
}

/// A GGX lobe with any Fresnel term: `fresnel · D·G1(o)·(G1(i)/cos θ_i) / 4`, masked.
/// `fresnel` (B|1, 3, H, W), `alpha` (B|1, 1, H|1, W|1). Models with their own Fresnel or α
/// mapping build on this.
pub fn ggx_lobe(geometry: &ShadingGeometry, fresnel: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    ggx_lobe_masked(geometry, fresnel, alpha, Masking::Separable)
}

/// [`ggx_lobe`] with the masking term chosen: `fresnel · D · G/(4 cos θ_i cos θ_o) · cos θ_o`,
/// each form division-free in the cosines (`Masking` documents the three).
pub fn ggx_lobe_masked(
    geometry: &ShadingGeometry,
    fresnel: &Tensor,
    alpha: &Tensor,
    masking: Masking,
) -> Result<Tensor> {
    let d = ggx_d(&geometry.cos_h, &geometry.sin2_h, alpha)?;
    // G/(4 cos θ_i cos θ_o) · cos θ_o.
    let shadowing = match masking {
        Masking::Separable => {
            (smith_g1(&geometry.cos_o, alpha)?
                .broadcast_mul(&smith_g1_over_cos(&geometry.cos_i, alpha)?)?
                * 0.25)?
        }
        Masking::Correlated => {
            smith_correlated_over_4cos(&geometry.cos_i, &geometry.cos_o, alpha, &geometry.mask)?
        }
        Masking::Implicit => (&geometry.cos_o * 0.25)?,
    };
    let scalar = d.broadcast_mul(&shadowing)?.broadcast_mul(&geometry.mask)?;
    scale_texels(fresnel, &scalar)
}

/// GGX specular with Schlick Fresnel (`f0` = specular albedo) and `α = max(roughness², 1e-4)`.
pub fn ggx_specular(geometry: &ShadingGeometry, f0: &Tensor, roughness: &Tensor) -> Result<Tensor> {
    ggx_specular_with(
        geometry,
        f0,
        roughness,
        Masking::Separable,
        FresnelTerm::Schlick,
    )
}

/// [`ggx_specular`] with the masking and Fresnel terms chosen.
pub fn ggx_specular_with(
    geometry: &ShadingGeometry,
    f0: &Tensor,
    roughness: &Tensor,
    masking: Masking,
    fresnel: FresnelTerm,
) -> Result<Tensor> {
    let alpha = alpha_from_roughness(roughness)?;
    let fresnel = match fresnel {
        FresnelTerm::Schlick => schlick(&geometry.cos_d, f0)?,
        FresnelTerm::Constant => f0.clone(),
    };
    ggx_lobe_masked(geometry, &fresnel, &alpha, masking)
}

/// Blinn-Phong specular, the cheap end of the specular lobes: normalised Blinn-Phong D with
/// the exponent of `α = max(roughness², 1e-4)`, the implicit masking `G = cos θ_i cos θ_o` and
/// `F = f0` at every angle, i.e. `f0 · D · cos θ_o / 4`, masked. `f0` (B|1, 3, H, W).
pub fn blinn_phong_specular(
    geometry: &ShadingGeometry,
    f0: &Tensor,
    roughness: &Tensor,
) -> Result<Tensor> {
    let alpha = alpha_from_roughness(roughness)?;
    let d = blinn_phong_d(&geometry.cos_h, &geometry.sin2_h, &alpha)?;
    let scalar = d
        .broadcast_mul(&(&geometry.cos_o * 0.25)?)?
        .broadcast_mul(&geometry.mask)?;
    scale_texels(f0, &scalar)
}
