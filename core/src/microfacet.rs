//! The one shared microfacet module: GGX and Blinn-Phong normal distributions, the masking-shadowing terms
//! (exact separable Smith, height-correlated Smith, the implicit term) and Schlick Fresnel, on
//! per-texel cosines.
//!
//! Follows Mitsuba 3's `MicrofacetDistribution` (GGX, isotropic) and Walter et al. 2007,
//! "Microfacet Models for Refraction through Rough Surfaces"; Heitz 2014, "Understanding the
//! Masking-Shadowing Function in Microfacet-Based BRDFs", for the height-correlated form;
//! Hoffman 2010, "Physically-Based Shading Models in Film and Game Production", for the implicit
//! term; Schlick 1994 for Fresnel.
//! Every plugin builds its specular lobes from these functions so that the α floor and the
//! numerically careful forms live in exactly one place (pbrt-v4's `scattering.h` layout).
//!
//! Precision (checked against Mitsuba by the goldens, `golden/FINDINGS.md`): no formula here
//! subtracts `1 − cos²` or divides by a cosine. D takes sin²θ_h computed from the half vector
//! (`|n × h|²`), and G1 uses division-free forms that are exact and finite down to cos = 0.
//!
//! Shapes: every argument is a per-texel scalar or colour, (B, 1|3, H, W), broadcastable.

use candle_core::Tensor;

use crate::Result;

/// Smallest GGX α: α = 0 makes D a Dirac delta (division by zero). Mitsuba's
/// `MicrofacetDistribution` clamps at 1e-4 too; there the peak D = 1/(π α²) ≈ 3e7 fits f32.
pub const ALPHA_MIN: f64 = 1e-4;

/// GGX α from perceptual roughness: `α = max(roughness², ALPHA_MIN)` (the mapping is fixed
/// project-wide and locked by the goldens).
///
/// The derivative is the subgradient chosen on purpose: `2·roughness` where `roughness² >
/// ALPHA_MIN`, and 0 where the floor holds, ties included, as in Dr.Jit's `maximum`. A plain
/// `maximum` splits a tie's gradient in half, and in f32 the tie is no corner case:
/// roughness 0.01 squares to exactly the f32 value of 1e-4, where half the unclamped
/// derivative of a render is about −7e7.
pub fn alpha_from_roughness(roughness: &Tensor) -> Result<Tensor> {
    let squared = roughness.sqr()?;
    let floor = squared.ones_like()?.affine(ALPHA_MIN, 0.0)?;
    // `where_cond` sends the gradient to the selected branch only.
    Ok(squared.gt(ALPHA_MIN)?.where_cond(&squared, &floor)?)
}

/// GGX normal distribution D(h) from `cos_h = n·h`, `sin2_h = |n × h|²` and α (all
/// (B,1,H,W)): `D = 1 / (π α² (sin²θ/α² + cos²θ)²)`, Mitsuba's form (includes the 1/π).
/// Passing sin² separately avoids the cancellation of `1 − cos²` near the peak, which in f32
/// costs D most of its digits at low roughness.
pub fn ggx_d(cos_h: &Tensor, sin2_h: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    let alpha2 = alpha.sqr()?;
    // For a unit normal sin² + cos² = 1, so the bracket is ≥ min(1, 1/α²) ≥ ½ whenever
    // α ≤ √2 (roughness ≤ 1.19): the floor never binds on valid input and only keeps D finite
    // for a zero (degenerate) normal, whose texel the shading mask zeroes anyway.
    let inner = sin2_h
        .broadcast_div(&alpha2)?
        .broadcast_add(&cos_h.sqr()?)?
        .maximum(0.5)?;
    let denom = (alpha2.broadcast_mul(&inner.sqr()?)? * std::f64::consts::PI)?;
    Ok(denom.recip()?)
}

/// Blinn-Phong exponent from α, `e = 2/α² − 2` (Walter et al. 2007, eq. 33): the exponent
/// whose lobe matches a Beckmann/GGX lobe of width α near the peak, so that the `roughness`
/// map means the same in `blinn_phong` as in `ggx`. α ∈ [1e-4, 1] gives e ∈ [0, 2·10⁸].
pub fn blinn_phong_exponent(alpha: &Tensor) -> Result<Tensor> {
    Ok(((alpha.sqr()?.recip()? * 2.0)? - 2.0)?)
}

/// Normalised Blinn-Phong distribution (Blinn 1977, normalised so that `∫ D cos θ_h dω = 1`):
/// `D = (e + 2)/(2π) · cos^e θ_h` with `e` from [`blinn_phong_exponent`]; all arguments
/// (B,1,H,W). At the peak it equals GGX's `1/(π α²)`. `cos^e` is evaluated as
/// `exp(−e/2 · ln(1 + tan²θ_h))` with `tan² = sin²/cos²` from the cancellation-free `sin2_h`
/// and a `ln(1 + x)` accurate for small x: a plain `powf(cos, e)` loses every digit near the
/// peak of a narrow lobe (e·ulp(1) ≈ 12 at the α floor).
pub fn blinn_phong_d(cos_h: &Tensor, sin2_h: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    let exponent = blinn_phong_exponent(alpha)?;
    // cos θ_h > 0 for every pair above the horizon; the floor only keeps masked texels (a zero
    // normal, a direction below the horizon) finite, where tan² then reaches 1e12 and D → 0.
    let tan2 = sin2_h.broadcast_div(&cos_h.sqr()?.maximum(1e-12)?)?;
    let log_cos = (ln_1p(&tan2)? * -0.5)?;
    let falloff = exponent.broadcast_mul(&log_cos)?.exp()?;
    let norm = ((exponent + 2.0)? / (2.0 * std::f64::consts::PI))?;
    Ok(norm.broadcast_mul(&falloff)?)
}

/// `ln(1 + x)` for `x ≥ 0`, accurate near 0. Below 0.01 it is the series
/// `2·atanh(y) = 2(y + y³/3 + y⁵/5)` of `y = x/(2 + x) ≤ 0.005`, truncated at a relative error
/// of about `3y⁶/7 ≤ 7e-15`: that matters because D's exponent multiplies the absolute error,
/// so even a 1e-11 relative error would show as 1e-9 in a deep tail. Above 0.01 it is
/// `ln(1 + x)`, whose f32 rounding of `1 + x` costs at most ulp(1)/x ≤ 6e-6 relative. The
/// gradient goes to the chosen branch; both stay finite.
fn ln_1p(x: &Tensor) -> Result<Tensor> {
    // The series sees x clipped to its own range: where it is not selected its value is
    // discarded, but a zero gradient times a non-finite value (x reaches 1e12 at grazing half
    // vectors) would still be NaN in the backward pass.
    let small = x.minimum(1e-2)?;
    let y = (&small / (&small + 2.0)?)?;
    let y2 = y.sqr()?;
    let odd = ((&y2 * y2.affine(1.0 / 5.0, 1.0 / 3.0)?)? + 1.0)?;
    let series = (y * odd)?.affine(2.0, 0.0)?;
    let direct = (x + 1.0)?.log()?;
    Ok(x.lt(1e-2)?.where_cond(&series, &direct)?)
}

/// The masking-shadowing term G(i, o) of a GGX lobe: the accuracy/cost choice of the `ggx`
/// model's `shadowing` argument (`docs/plugins.md`, "Model variants").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Masking {
    /// `G = G1(i)·G1(o)`, the exact GGX G1 per direction: Mitsuba's and the paper's choice.
    Separable,
    /// `G = 1 / (1 + Λ(i) + Λ(o))`, height-correlated Smith (Heitz 2014): the more accurate
    /// masking (a microfacet masked for one direction is likely shadowed for the other).
    Correlated,
    /// `G = cos θ_i · cos θ_o` (Hoffman 2010): cancels the denominator's cosines, no masking
    /// to evaluate; the cheap end.
    Implicit,
}

/// `sqrt(c² + α²(1 − c²))` written as `sqrt(α² + c²(1 − α²))`: no cancellation, and the
/// argument is ≥ α² ≥ 1e-8 for c ∈ [0, 1], so its slope stays finite. It is `c·sqrt(1 + α²
/// tan²θ)`, from which Smith's Λ(c) = (root − c) / 2c.
fn smith_root(cos_v: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    let alpha2 = alpha.sqr()?;
    Ok(cos_v
        .sqr()?
        .broadcast_mul(&(1.0 - &alpha2)?)?
        .broadcast_add(&alpha2)?
        .sqrt()?)
}

/// `c + sqrt(c² + α²(1 − c²))` = `2c / G1(c)`.
fn smith_denominator(cos_v: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    Ok((cos_v + smith_root(cos_v, alpha)?)?)
}

/// Height-correlated Smith divided by the microfacet denominator's `4 cos θ_i`:
/// `G2 / (4 cos θ_i)` with `G2 = 1/(1 + Λ(i) + Λ(o)) = 2 c_i c_o / (c_o r_i + c_i r_o)` and
/// `r = smith_root`, i.e. `c_o / (2 (c_o r_i + c_i r_o))`, division-free in the cosines.
/// `mask` (0/1) is the below-horizon mask: masked texels divide by `denominator + 1` instead,
/// so a texel with both cosines 0 (denominator 0) stays finite in value and gradient, and
/// unmasked ones (denominator ≥ α (c_i + c_o) > 0) are exact.
pub fn smith_correlated_over_4cos(
    cos_i: &Tensor,
    cos_o: &Tensor,
    alpha: &Tensor,
    mask: &Tensor,
) -> Result<Tensor> {
    let root_i = smith_root(cos_i, alpha)?;
    let root_o = smith_root(cos_o, alpha)?;
    let denominator = (cos_o.broadcast_mul(&root_i)? + cos_i.broadcast_mul(&root_o)?)?;
    let safe = (denominator + (1.0 - mask)?)?;
    Ok((cos_o / (safe * 2.0)?)?)
}

/// Exact GGX Smith masking for one direction, `cos_v = n·v ≥ 0`:
/// `G1 = 2 / (1 + sqrt(1 + α² tan²θ)) = 2c / (c + sqrt(c² + α²(1 − c²)))`.
pub fn smith_g1(cos_v: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    Ok(((cos_v * 2.0)? / smith_denominator(cos_v, alpha)?)?)
}

/// `G1(c)/c = 2 / (c + sqrt(c² + α²(1 − c²)))` for `c ≥ 0`: finite (2/α) at c = 0, which is
/// what lets the specular lobe divide by cos θ_i without any clamp.
pub fn smith_g1_over_cos(cos_v: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    Ok((smith_denominator(cos_v, alpha)?.recip()? * 2.0)?)
}

/// Anisotropic GGX D(h) (Heitz 2014, eq. 86; Mitsuba's `MicrofacetDistribution` with α_u, α_v)
/// from the half vector's components in a shading frame (tangent t, bitangent b, normal n):
/// `D = 1 / (π α_t α_b (h_t²/α_t² + h_b²/α_b² + h_n²)²)`. All arguments (B,1,H,W).
pub fn ggx_d_anisotropic(
    h_t: &Tensor,
    h_b: &Tensor,
    h_n: &Tensor,
    alpha_t: &Tensor,
    alpha_b: &Tensor,
) -> Result<Tensor> {
    // For an orthonormal frame the bracket is ≥ min(1, 1/α_t², 1/α_b²) ≥ ½ whenever both α
    // ≤ √2 (roughness ≤ 1.19), so the floor never binds on valid input; it only keeps D
    // finite where the frame is degenerate (a zero normal, whose texel the mask zeroes).
    let inner = ((h_t.sqr()?.broadcast_div(&alpha_t.sqr()?)?
        + h_b.sqr()?.broadcast_div(&alpha_b.sqr()?)?)?
        + h_n.sqr()?)?
    .maximum(0.5)?;
    let denom = (alpha_t
        .broadcast_mul(alpha_b)?
        .broadcast_mul(&inner.sqr()?)?
        * std::f64::consts::PI)?;
    Ok(denom.recip()?)
}

/// `2 / (c + sqrt(c² + α_t² v_t² + α_b² v_b²))` = anisotropic Smith `G1(v)/cos θ_v` (Heitz
/// 2014, eq. 86–87) from the direction's components in the shading frame, `c = v_n ≥ 0`.
pub fn smith_g1_over_cos_anisotropic(
    v_t: &Tensor,
    v_b: &Tensor,
    cos_v: &Tensor,
    alpha_t: &Tensor,
    alpha_b: &Tensor,
) -> Result<Tensor> {
    // In an orthonormal frame `v_t² + v_b² = 1 − c²`, so the argument is ≥ c² + min(α)²(1 − c²)
    // ≥ min(α)² ≥ ALPHA_MIN²: the floor never binds there and only keeps the root and its
    // slope finite in a degenerate frame (a zero normal, which the mask zeroes).
    let root = ((cos_v.sqr()? + v_t.broadcast_mul(alpha_t)?.sqr()?)?
        + v_b.broadcast_mul(alpha_b)?.sqr()?)?
    .maximum(ALPHA_MIN * ALPHA_MIN)?
    .sqrt()?;
    Ok(((cos_v + root)?.recip()? * 2.0)?)
}

/// The Fresnel term of a GGX lobe: the `ggx` model's `fresnel` argument.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FresnelTerm {
    /// Schlick 1994 with `F0` = specular albedo: the paper's and Mitsuba `principled`'s choice.
    Schlick,
    /// `F = F0` at every angle: no grazing brightening, one multiply cheaper.
    Constant,
}

/// Schlick's Fresnel `F = F0 + (1 − F0)(1 − cos)^5` with `cos = wi·h` (B,1,H,W) and
/// `f0` (B,3,H,W) → (B,3,H,W).
pub fn schlick(cos_d: &Tensor, f0: &Tensor) -> Result<Tensor> {
    // wi·h ∈ [0, 1] for any pair above the horizon; the clamp only removes rounding excess.
    let weight = (1.0 - cos_d.clamp(0.0, 1.0)?)?.powf(5.0)?;
    Ok(f0.broadcast_add(&(1.0 - f0)?.broadcast_mul(&weight)?)?)
}
