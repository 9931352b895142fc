//! `blinn_phong`: Lambert diffuse + normalised Blinn-Phong specular, the cheap end of the
//! specular models.
//!
//! `f = ρ_d/π + F0 · D / 4` with `D = (e + 2)/(2π) · cos^e θ_h` (Blinn 1977, normalised),
//! the exponent `e = 2/α² − 2` of `α = max(roughness², 1e-4)` (Walter et al. 2007, eq. 33),
//! the implicit masking `G = cos θ_i cos θ_o` and `F = F0` at every angle (Hoffman 2010).
//! No G1, no Fresnel and no rational D: it is what the real-time shading of the 2000s used and
//! what `photomat trade` measures as the cheapest specular model (`docs/plugins.md`, "Model
//! variants"). The maps mean what they mean in `ggx`: at the peak D equals GGX's `1/(π α²)`,
//! so the same roughness gives a highlight of the same height and about the same width, and
//! a material's maps can be swapped between the two models. Mitsuba 3 has no Blinn-Phong
//! plugin; the golden composes the model in Dr.Jit (`golden/generate.py`).
//!
//! | map         | ch | range  | encoding | file        | at 0                    | at the top              |
//! |-------------|----|--------|----------|-------------|-------------------------|-------------------------|
//! | `diffuse`   | 3  | [0, 1] | gamma2.2 | gamma PNG   | no diffuse reflection   | white Lambertian base   |
//! | `specular`  | 3  | [0, 1] | gamma2.2 | gamma PNG   | no specular lobe        | F = 1 at every angle    |
//! | `roughness` | 1  | [0, 1] | linear   | linear PNG  | mirror (α floored 1e-4) | α = 1: e = 0, flat lobe |
//! | `normal`    | 3  | unit   | normal   | 0.5·n + 0.5 | +z: flat                | grazing tilt            |
//!
//! n = 10, as `ggx`. Usage: `photomat render --maps DIR --brdf blinn_phong --light 0.1,-0.2 --out img.png`.

use candle_core::Tensor;
use photomat_core::lobes::{blinn_phong_specular, lambert};
use photomat_core::param::common::{DIFFUSE, NORMAL, ROUGHNESS, SPECULAR};
use photomat_core::{MaterialMaps, Reflectance, Result, ShadingGeometry, register_brdf};

/// Lambert + normalised Blinn-Phong.
pub struct BlinnPhong;

impl Reflectance for BlinnPhong {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let specular =
            blinn_phong_specular(&geometry, maps.get("specular")?, maps.get("roughness")?)?;
        Ok((diffuse + specular)?)
    }
}

register_brdf! {
    name: "blinn_phong",
    summary: "Lambert + normalised Blinn-Phong, implicit G, F = F0 (cheapest specular model)",
    params: &[DIFFUSE, SPECULAR, ROUGHNESS, NORMAL],
    model: |_| Ok(BlinnPhong),
}
