//! `ggx_aniso`: Lambert diffuse + anisotropic GGX specular, for brushed metals and other
//! surfaces whose highlight stretches in one direction.
//!
//! `f = ρ_d/π + D·F·G / (4 cosθ_i cosθ_o)` with the anisotropic GGX D and separable Smith G
//! with the anisotropic G1 (Heitz 2014, "Understanding the Masking-Shadowing Function",
//! eq. 86–87; Burley 2012), Schlick F with F0 = specular albedo. α_t = max(r_t², 1e-4) along
//! the tangent and α_b = max(r_b², 1e-4) along the bitangent. The tangent is the texture-plane
//! direction at angle θ = π·`angle` counter-clockwise from +x, made perpendicular to the
//! shading normal (`t = normalize(t₀ − (t₀·n) n)`, `b = n × t`); directions are a half turn
//! periodic, so `angle` 0 and 1 are the same tangent. With `roughness_t = roughness_b` it is
//! exactly `ggx`. Equals Mitsuba 3's `diffuse` + a GGX `MicrofacetDistribution(α_u = α_t,
//! α_v = α_b)` lobe in that frame with Schlick's Fresnel (composed in Dr.Jit for the goldens).
//!
//! | map           | ch | range  | encoding | file        | at 0                   | at the top            |
//! |---------------|----|--------|----------|-------------|------------------------|-----------------------|
//! | `diffuse`     | 3  | [0, 1] | gamma2.2 | gamma PNG   | no diffuse reflection  | white Lambertian base |
//! | `specular`    | 3  | [0, 1] | gamma2.2 | gamma PNG   | no specular lobe       | perfect metal (F = 1) |
//! | `roughness_t` | 1  | [0, 1] | linear   | linear PNG  | mirror along t         | α_t = 1               |
//! | `roughness_b` | 1  | [0, 1] | linear   | linear PNG  | mirror along b         | α_b = 1               |
//! | `angle`       | 1  | [0, 1] | linear   | linear PNG  | tangent along +x       | a half turn: +x again |
//! | `normal`      | 3  | unit   | normal   | 0.5·n + 0.5 | +z: flat               | grazing tilt          |
//!
//! A brushed metal has `roughness_b > roughness_t` with t along the brushing: the flash
//! highlight stretches across the grooves. n = 12; `height(ggx_aniso)` has n = 10.
//! Usage: `photomat render --maps DIR --brdf ggx_aniso --light 0.1,-0.2 --out img.png`.

use candle_core::Tensor;
use photomat_core::lobes::lambert;
use photomat_core::microfacet::{
    alpha_from_roughness, ggx_d_anisotropic, schlick, smith_g1_over_cos_anisotropic,
};
use photomat_core::param::common::{DIFFUSE, NORMAL, ROUGHNESS, SPECULAR};
use photomat_core::vecops::{cross3, dot3, normalize3};
use photomat_core::{MaterialMaps, ParamSpec, Reflectance, Result, ShadingGeometry, register_brdf};

/// Roughness along the tangent.
const ROUGHNESS_T: ParamSpec = ParamSpec {
    name: "roughness_t",
    doc: "perceptual roughness along the tangent, α_t = max(r_t², 1e-4)",
    ..ROUGHNESS
};

/// Roughness along the bitangent.
const ROUGHNESS_B: ParamSpec = ParamSpec {
    name: "roughness_b",
    doc: "perceptual roughness along the bitangent (n × t), α_b = max(r_b², 1e-4)",
    ..ROUGHNESS
};

/// The tangent's direction in the texture plane, in half turns.
const ANGLE: ParamSpec = ParamSpec {
    name: "angle",
    default: &[0.0],
    doc: "tangent direction θ = π·angle counter-clockwise from +x (0 and 1: the same tangent)",
    ..ROUGHNESS
};

/// Lambert + anisotropic GGX.
pub struct GgxAniso;

impl Reflectance for GgxAniso {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let normal = maps.get("normal")?;
        let geometry = ShadingGeometry::new(wi, wo, normal)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;

        // The shading frame: t₀ in the plane, made perpendicular to n.
        let n = normalize3(normal)?;
        let theta = (maps.get("angle")? * std::f64::consts::PI)?;
        let t0 = Tensor::cat(&[theta.cos()?, theta.sin()?, theta.zeros_like()?], 1)?;
        let t = normalize3(&(t0.broadcast_sub(&n.broadcast_mul(&dot3(&n, &t0)?)?))?)?;
        let b = cross3(&n, &t)?;
        let h = normalize3(&(wi + wo)?)?;
        let alpha_t = alpha_from_roughness(maps.get("roughness_t")?)?;
        let alpha_b = alpha_from_roughness(maps.get("roughness_b")?)?;

        let d = ggx_d_anisotropic(
            &dot3(&h, &t)?,
            &dot3(&h, &b)?,
            &geometry.cos_h,
            &alpha_t,
            &alpha_b,
        )?;
        let g1_over_cos = |v: &Tensor, cos_v: &Tensor| {
            smith_g1_over_cos_anisotropic(&dot3(v, &t)?, &dot3(v, &b)?, cos_v, &alpha_t, &alpha_b)
        };
        // G/(4 cos θ_i cos θ_o) · cos θ_o = (G1(i)/cos θ_i) · (G1(o)/cos θ_o) · cos θ_o / 4.
        let shadowing = (g1_over_cos(wi, &geometry.cos_i)?
            .broadcast_mul(&g1_over_cos(wo, &geometry.cos_o)?)?
            .broadcast_mul(&geometry.cos_o)?
            * 0.25)?;
        let scalar = d.broadcast_mul(&shadowing)?.broadcast_mul(&geometry.mask)?;
        let fresnel = schlick(&geometry.cos_d, maps.get("specular")?)?;
        Ok((diffuse + fresnel.broadcast_mul(&scalar)?)?)
    }
}

register_brdf! {
    name: "ggx_aniso",
    summary: "Lambert + anisotropic GGX (α along a tangent at a mapped angle), Smith G, Schlick F0",
    params: &[DIFFUSE, SPECULAR, ROUGHNESS_T, ROUGHNESS_B, ANGLE, NORMAL],
    model: |_| Ok(GgxAniso),
}
