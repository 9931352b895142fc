//! `blinn_phong_gloss`: Lambert diffuse + energy-normalised Blinn–Phong specular, registered from a
//! user's crate without touching photomat's own crates. photomat's built-in `blinn_phong` is the
//! same lobe on `ggx`'s roughness map; this one shows a model that brings a map of its own
//! (glossiness) and a name that must not collide with a built-in's.
//!
//! `f = ρ_d/π + k_s·(e + 2)/(8π)·(n·h)^e` with `h = normalize(wi + wo)`.
//! The factor is the microfacet form of Blinn's lobe (Blinn 1977, "Models of light reflection
//! for computer synthesized pictures"): the normalised Blinn–Phong distribution
//! `D = (e + 2)/(2π)·(n·h)^e` (∫ D (n·h) dω_h = 1) inside `D·F·G / (4 cosθ_i cosθ_o)` with the
//! implicit visibility term `G = cosθ_i cosθ_o` and a constant `F = k_s` gives `k_s·D/4`
//! (Akenine-Möller et al., *Real-Time Rendering*, 4th ed. 2018, §9.8, Blinn–Phong NDF and the
//! implicit G). Unlike `ggx` there is no Fresnel term: `k_s` is the specular albedo at every
//! angle.
//!
//! The exponent comes from a `glossiness` map g ∈ [0, 1] as `e = 2^(1 + 12·g)` ∈ [2, 8192]:
//! equal steps in g are equal ratios of lobe width, so the map stays well conditioned for an
//! estimator (a linear exponent would spend almost all of its range on mirror-like lobes).
//!
//! | map          | ch | range  | encoding | file        | at 0                           | at the top                       |
//! |--------------|----|--------|----------|-------------|--------------------------------|----------------------------------|
//! | `diffuse`    | 3  | [0, 1] | gamma2.2 | gamma PNG   | no diffuse reflection          | white Lambertian base            |
//! | `specular`   | 3  | [0, 1] | gamma2.2 | gamma PNG   | no specular lobe               | k_s = 1 at every angle           |
//! | `glossiness` | 1  | [0, 1] | linear   | linear PNG  | e = 2: broad lobe, peak 1/(2π) | e = 8192: sharp lobe, peak ≈ 326 |
//! | `normal`     | 3  | unit   | normal   | 0.5·n + 0.5 | +z: flat                       | grazing tilt                     |
//!
//! n = 10; with the built-in height adapter, `height(blinn_phong_gloss)` has n = 8.
//! Usage: `photomat-custom render --maps DIR --brdf blinn_phong_gloss --light 0.1,0.1 --out img.png`.

use std::f64::consts::{LN_2, PI};

use candle_core::Tensor;
use photomat_core::lobes::lambert;
use photomat_core::param::common::{DIFFUSE, NORMAL, SPECULAR};
use photomat_core::{
    ColorSpace, Encoding, MaterialMaps, ParamSpec, Reflectance, Result, ShadingGeometry,
    register_brdf,
};

/// Smallest exponent, at glossiness 0: `2^EXPONENT_LOG2_MIN`.
pub const EXPONENT_LOG2_MIN: f64 = 1.0;
/// log2 of the exponent's range: glossiness 1 gives `2^(EXPONENT_LOG2_MIN + EXPONENT_LOG2_SPAN)`.
pub const EXPONENT_LOG2_SPAN: f64 = 12.0;

/// The specular albedo: the shared [`SPECULAR`] map, documented for a lobe without Fresnel.
const SPECULAR_KS: ParamSpec = ParamSpec {
    doc: "specular albedo k_s (no Fresnel: the same at every angle), linear rgb",
    ..SPECULAR
};

/// Glossiness g ∈ [0, 1], mapped to the exponent by [`exponent`].
const GLOSSINESS: ParamSpec = ParamSpec {
    name: "glossiness",
    channels: 1,
    range: (0.0, 1.0),
    encoding: Encoding::Linear,
    color_space: ColorSpace::Linear,
    default: &[0.5],
    differentiable: true,
    doc: "glossiness g, Blinn-Phong exponent e = 2^(1 + 12·g) in [2, 8192]",
};

/// Lambert + normalised Blinn–Phong.
pub struct BlinnPhong;

/// Blinn–Phong exponent `e = 2^(1 + 12·g)` from glossiness (B|1, 1, H|1, W|1).
pub fn exponent(glossiness: &Tensor) -> Result<Tensor> {
    // Clamp to the documented range: decoded and loaded maps never leave it, and it keeps
    // e ≤ 8192 for hand-made inputs (at g ≈ 10.6 the exponent would overflow f32 to ∞).
    let g = glossiness.clamp(0.0, 1.0)?;
    // e = exp(ln 2 · (1 + 12 g)).
    Ok(
        g.affine(LN_2 * EXPONENT_LOG2_SPAN, LN_2 * EXPONENT_LOG2_MIN)?
            .exp()?,
    )
}

/// Floor of n·h before its logarithm (see `blinn_phong_gloss_specular`): any positive value far below
/// the cosines of unmasked texels works; 1e-7 ≈ f32 machine epsilon.
const COS_H_MIN: f64 = 1e-7;

/// The specular lobe's `k_s·(e + 2)/(8π)·(n·h)^e·cosθ_o`, masked below the horizon.
///
/// # Shapes
/// `specular` (B|1, 3, H|1, W|1), `glossiness` (B|1, 1, H|1, W|1), result (B, 3, H, W).
pub fn blinn_phong_gloss_specular(
    geometry: &ShadingGeometry,
    specular: &Tensor,
    glossiness: &Tensor,
) -> Result<Tensor> {
    let e = exponent(glossiness)?;
    // Lower bound: n·h > 0 whenever both directions are above the horizon (h is their
    // normalised sum), so only masked texels reach it; there it keeps ln finite, so they get
    // value 0 *and* gradient 0 instead of 0·∞ = NaN. Upper bound: rounding of the two unit
    // vectors can give n·h slightly above 1, which the exponent (up to 8192) would amplify.
    let cos_h = geometry.cos_h.clamp(COS_H_MIN, 1.0)?;
    // (n·h)^e = exp(e·ln(n·h)): a per-texel exponent; underflows to exactly 0 for sharp lobes.
    let lobe = cos_h.log()?.broadcast_mul(&e)?.exp()?;
    let norm = ((e + 2.0)? / (8.0 * PI))?;
    let scalar = norm
        .broadcast_mul(&lobe)?
        .broadcast_mul(&geometry.cos_o)?
        .broadcast_mul(&geometry.mask)?;
    Ok(specular.broadcast_mul(&scalar)?)
}

impl Reflectance for BlinnPhong {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        // Shared geometry: cosines floored at 0 and the 0/1 below-horizon mask, exactly as
        // the built-in models use it.
        let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let specular =
            blinn_phong_gloss_specular(&geometry, maps.get("specular")?, maps.get("glossiness")?)?;
        Ok((diffuse + specular)?)
    }
}

register_brdf! {
    name: "blinn_phong_gloss",
    summary: "Lambert + energy-normalised Blinn-Phong (e+2)/(8π)·(n·h)^e, e = 2^(1+12·glossiness)",
    params: &[DIFFUSE, SPECULAR_KS, GLOSSINESS, NORMAL],
    model: |_| Ok(BlinnPhong),
}
