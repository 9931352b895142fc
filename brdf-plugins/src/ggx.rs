//! `ggx`: Lambert diffuse + GGX microfacet specular, the standard SVBRDF of the paper.
//!
//! `f = ρ_d/π + D·F·G / (4 cosθ_i cosθ_o)` with GGX D, `α = max(roughness², 1e-4)` (Walter et
//! al. 2007). By default separable Smith G with the exact GGX G1 and Schlick F with F0 =
//! specular albedo: then it equals Mitsuba 3's `diffuse` + `principled` (metallic = 1,
//! base_color = F0, roughness r).
//!
//! | map         | ch | range  | encoding | file        | at 0                    | at the top              |
//! |-------------|----|--------|----------|-------------|-------------------------|-------------------------|
//! | `diffuse`   | 3  | [0, 1] | gamma2.2 | gamma PNG   | no diffuse reflection   | white Lambertian base   |
//! | `specular`  | 3  | [0, 1] | gamma2.2 | gamma PNG   | no specular lobe        | perfect metal (F = 1)   |
//! | `roughness` | 1  | [0, 1] | linear   | linear PNG  | mirror (α floored 1e-4) | α = 1: broad lobe       |
//! | `normal`    | 3  | unit   | normal   | 0.5·n + 0.5 | +z: flat                | grazing tilt            |
//!
//! | argument    | values                                   | what                                  |
//! |-------------|------------------------------------------|---------------------------------------|
//! | `shadowing` | `separable` (default), `correlated`, `implicit` | G: product of G1s; height-correlated Smith (Heitz 2014); `cos θ_i cos θ_o` (Hoffman 2010) |
//! | `fresnel`   | `schlick` (default), `constant`          | F: Schlick 1994; `F0` at every angle   |
//!
//! The variants trade accuracy for cost (`docs/plugins.md`, "Model variants"); the maps are the
//! same for all of them. n = 10; with the height adapter, `height(ggx)` has n = 8 as in the paper.
//! Usage: `photomat render --maps DIR --brdf "ggx(shadowing=correlated)" --light 0.1,-0.2 --out img.png`.

use candle_core::Tensor;
use photomat_core::lobes::{ggx_specular_with, lambert};
use photomat_core::microfacet::{FresnelTerm, Masking};
use photomat_core::param::common::{DIFFUSE, NORMAL, ROUGHNESS, SPECULAR};
use photomat_core::{
    ArgSpec, Error, MaterialMaps, Reflectance, Result, ShadingGeometry, register_brdf,
};

/// Lambert + GGX with the chosen masking and Fresnel terms.
pub struct Ggx {
    pub masking: Masking,
    pub fresnel: FresnelTerm,
}

impl Reflectance for Ggx {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let specular = ggx_specular_with(
            &geometry,
            maps.get("specular")?,
            maps.get("roughness")?,
            self.masking,
            self.fresnel,
        )?;
        Ok((diffuse + specular)?)
    }
}

const SHADOWING: ArgSpec = ArgSpec::choice(
    "shadowing",
    &["separable", "correlated", "implicit"],
    "masking-shadowing G: separable Smith, height-correlated Smith, or cos θ_i cos θ_o",
);

const FRESNEL: ArgSpec = ArgSpec::choice(
    "fresnel",
    &["schlick", "constant"],
    "Fresnel F: Schlick with F0 = specular, or F0 at every angle",
);

register_brdf! {
    name: "ggx",
    summary: "Lambert + GGX specular, Smith G, Schlick F0 (Mitsuba diffuse + principled metallic)",
    params: &[DIFFUSE, SPECULAR, ROUGHNESS, NORMAL],
    args: &[SHADOWING, FRESNEL],
    model: |args| {
        let masking = match args.choice("shadowing")? {
            "separable" => Masking::Separable,
            "correlated" => Masking::Correlated,
            "implicit" => Masking::Implicit,
            other => return Err(Error::Invalid(format!("ggx: no shadowing '{other}'"))),
        };
        let fresnel = match args.choice("fresnel")? {
            "schlick" => FresnelTerm::Schlick,
            "constant" => FresnelTerm::Constant,
            other => return Err(Error::Invalid(format!("ggx: no fresnel '{other}'"))),
        };
        Ok(Ggx { masking, fresnel })
    },
}
