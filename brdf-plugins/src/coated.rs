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

use std::sync::Arc;

use candle_core::Tensor;
use photomat_core::lobes::{ggx_specular, lambert};
use photomat_core::vecops::constant3;
use photomat_core::{
    Brdf, BrdfArgs, BrdfRegistration, ColorSpace, DifferentiableBrdf, Encoding, MaterialMaps,
    ParamSpec, Result, ShadingGeometry, register_brdf,
};

use crate::common::{DIFFUSE, ROUGHNESS, SPECULAR};

const PARAMS: &[ParamSpec] = &[
    DIFFUSE,
    SPECULAR,
    ROUGHNESS,
    ParamSpec {
        name: "specular2",
        channels: 3,
        range: (0.0, 1.0),
        encoding: Encoding::Gamma22,
        color_space: ColorSpace::Gamma22,
        default: &[0.04, 0.04, 0.04],
        differentiable: true,
        doc: "second lobe's specular albedo (Schlick F0), e.g. the clear coat",
    },
    ParamSpec {
        name: "roughness2",
        channels: 1,
        range: (0.0, 1.0),
        encoding: Encoding::Linear,
        color_space: ColorSpace::Linear,
        default: &[0.1],
        differentiable: true,
        doc: "second lobe's perceptual roughness, α = max(r², 1e-4)",
    },
];

/// Lambert + two GGX lobes, flat normal.
pub struct Coated;

impl DifferentiableBrdf for Coated {
    fn name(&self) -> String {
        "coated".into()
    }

    fn params(&self) -> &[ParamSpec] {
        PARAMS
    }

    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let up = constant3([0.0, 0.0, 1.0], wi)?;
        let geometry = ShadingGeometry::new(wi, wo, &up)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let lobe1 = ggx_specular(&geometry, maps.get("specular")?, maps.get("roughness")?)?;
        let lobe2 = ggx_specular(&geometry, maps.get("specular2")?, maps.get("roughness2")?)?;
        Ok(((diffuse + lobe1)? + lobe2)?)
    }
}

fn construct(_: &BrdfArgs) -> Result<Brdf> {
    Ok(Arc::new(Coated))
}

register_brdf!(BrdfRegistration {
    name: "coated",
    summary: "car paint: Lambert + two GGX lobes with own rgb F0 and roughness, flat normal",
    params: PARAMS,
    replaces: &[],
    takes_nested: false,
    args: &[],
    construct,
});
