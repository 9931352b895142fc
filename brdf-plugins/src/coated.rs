//! `coated`: Lambert diffuse + two GGX specular lobes, for car paint (paper §"Car paint").
//!
//! `f = ρ_d/π + GGX(F0 = specular, r = roughness) + GGX(F0 = specular2, r = roughness2)`, each
//! lobe exactly the specular lobe of `ggx` (Mitsuba 3: `diffuse` + two `principled` lobes with
//! metallic = 1). The normal is fixed to +z: the paper's car-paint model has no normal map, the
//! second lobe carries the flake sparkle that a normal map would otherwise fake. By convention
//! lobe 1 is the broad metallic-flake lobe and lobe 2 the sharp clear coat; nothing enforces it.
//!
//! | map          | ch | range  | encoding | file       | at 0                  | at the top            |
//! |--------------|----|--------|----------|------------|-----------------------|-----------------------|
//! | `diffuse`    | 3  | [0, 1] | gamma2.2 | gamma PNG  | no diffuse reflection | white Lambertian base |
//! | `specular`   | 3  | [0, 1] | gamma2.2 | gamma PNG  | lobe 1 off            | lobe 1 F = 1          |
//! | `roughness`  | 1  | [0, 1] | linear   | linear PNG | lobe 1 mirror         | lobe 1 α = 1          |
//! | `specular2`  | 3  | [0, 1] | gamma2.2 | gamma PNG  | lobe 2 off            | lobe 2 F = 1          |
//! | `roughness2` | 1  | [0, 1] | linear   | linear PNG | lobe 2 mirror         | lobe 2 α = 1          |
//!
//! n = 3 + 2·(3 + 1) = 11, as in the paper.
//! Usage: `photomat render --maps DIR --brdf coated --orbit 8 --out sheet.png`.

use candle_core::Tensor;
use photomat_core::lobes::{ggx_specular, lambert};
use photomat_core::param::common::{DIFFUSE, ROUGHNESS, SPECULAR};
use photomat_core::vecops::constant3;
use photomat_core::{MaterialMaps, ParamSpec, Reflectance, Result, ShadingGeometry, register_brdf};

/// The second lobe's specular albedo: [`SPECULAR`] under its own name and documentation.
const SPECULAR2: ParamSpec = ParamSpec {
    name: "specular2",
    doc: "second lobe's specular albedo (Schlick F0), e.g. the clear coat",
    ..SPECULAR
};

/// The second lobe's roughness: [`ROUGHNESS`] with a sharper default (the clear coat).
const ROUGHNESS2: ParamSpec = ParamSpec {
    name: "roughness2",
    default: &[0.1],
    doc: "second lobe's perceptual roughness, α = max(r², 1e-4)",
    ..ROUGHNESS
};

/// Lambert + two GGX lobes, flat normal.
pub struct Coated;

impl Reflectance for Coated {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let up = constant3([0.0, 0.0, 1.0], wi)?;
        let geometry = ShadingGeometry::new(wi, wo, &up)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let lobe1 = ggx_specular(&geometry, maps.get("specular")?, maps.get("roughness")?)?;
        let lobe2 = ggx_specular(&geometry, maps.get("specular2")?, maps.get("roughness2")?)?;
        Ok(((diffuse + lobe1)? + lobe2)?)
    }
}

register_brdf! {
    name: "coated",
    summary: "car paint: Lambert + two GGX lobes with own rgb F0 and roughness, flat normal",
    params: &[DIFFUSE, SPECULAR, ROUGHNESS, SPECULAR2, ROUGHNESS2],
    model: |_| Ok(Coated),
}
