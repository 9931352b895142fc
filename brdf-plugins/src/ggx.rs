//! `ggx`: Lambert diffuse + GGX microfacet specular, the standard SVBRDF of the paper.
//!
//! `f = ρ_d/π + D·F·G / (4 cosθ_i cosθ_o)` with GGX D, separable Smith G with the exact GGX G1,
//! Schlick F with F0 = specular albedo, `α = max(roughness², 1e-4)` (Walter et al. 2007).
//! Equals Mitsuba 3's `diffuse` + `principled` (metallic = 1, base_color = F0, roughness r).
//!
//! | map         | ch | range  | encoding | file        | at 0                    | at the top              |
//! |-------------|----|--------|----------|-------------|-------------------------|-------------------------|
//! | `diffuse`   | 3  | [0, 1] | gamma2.2 | gamma PNG   | no diffuse reflection   | white Lambertian base   |
//! | `specular`  | 3  | [0, 1] | gamma2.2 | gamma PNG   | no specular lobe        | perfect metal (F = 1)   |
//! | `roughness` | 1  | [0, 1] | linear   | linear PNG  | mirror (α floored 1e-4) | α = 1: broad lobe       |
//! | `normal`    | 3  | unit   | normal   | 0.5·n + 0.5 | +z: flat                | grazing tilt            |
//!
//! n = 10; with the height adapter, `height(ggx)` has n = 8 as in the paper.
//! Usage: `photomat render --maps DIR --brdf ggx --light 0.1,-0.2 --out img.png`.

use candle_core::Tensor;
use photomat_core::lobes::{ggx_specular, lambert};
use photomat_core::param::common::{DIFFUSE, NORMAL, ROUGHNESS, SPECULAR};
use photomat_core::{MaterialMaps, Reflectance, Result, ShadingGeometry, register_brdf};

/// Lambert + GGX.
pub struct Ggx;

impl Reflectance for Ggx {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let specular = ggx_specular(&geometry, maps.get("specular")?, maps.get("roughness")?)?;
        Ok((diffuse + specular)?)
    }
}

register_brdf! {
    name: "ggx",
    summary: "Lambert + GGX specular, Smith G, Schlick F0 (Mitsuba diffuse + principled metallic)",
    params: &[DIFFUSE, SPECULAR, ROUGHNESS, NORMAL],
    model: |_| Ok(Ggx),
}
