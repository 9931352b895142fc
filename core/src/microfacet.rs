//! The one shared microfacet module: GGX normal distribution, exact Smith G1 and Schlick
//! Fresnel, on per-texel cosines.
//!
//! Follows Mitsuba 3's `MicrofacetDistribution` (GGX, isotropic) and Walter et al. 2007,
//! "Microfacet Models for Refraction through Rough Surfaces"; Schlick 1994 for Fresnel.
//! Every plugin builds its specular lobes from these functions so that the α floor and the
//! grazing-angle clamps live in exactly one place (pbrt-v4's `scattering.h` layout).
//!
//! Shapes: every argument is a per-texel scalar or colour, (B, 1|3, H, W), broadcastable.

use candle_core::Tensor;

use crate::Result;

/// Smallest GGX α: α = 0 makes D a Dirac delta (division by zero). Mitsuba's
/// `MicrofacetDistribution` clamps at 1e-4 too; there the peak D = 1/(π α²) ≈ 3e7 fits f32.
pub const ALPHA_MIN: f64 = 1e-4;

/// Smallest cosine used in a denominator. Below it the geometry is clamped, not masked:
/// G1(c)/c tends to a finite limit as c → 0, so the clamped value equals the limit to f32
/// precision while keeping 1/c finite (1e-7 ≈ f32 machine epsilon).
pub const COS_MIN: f64 = 1e-7;

/// GGX α from perceptual roughness: `α = max(roughness², ALPHA_MIN)` (the mapping is fixed
/// project-wide and locked by the goldens).
pub fn alpha_from_roughness(roughness: &Tensor) -> Result<Tensor> {
    Ok(roughness.sqr()?.maximum(ALPHA_MIN)?)
}

/// GGX normal distribution D(h) from `cos_h = n·h` (B,1,H,W) and α (B,1,H,W):
/// `D = 1 / (π α² (sin²θ/α² + cos²θ)²)`, Mitsuba's form (includes the 1/π).
pub fn ggx_d(cos_h: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    let cos2 = cos_h.sqr()?;
    // sin²θ = 1 − cos²θ; rounding can make it slightly negative at cos θ ≈ 1.
    let sin2 = (1.0 - &cos2)?.maximum(0.0)?;
    let alpha2 = alpha.sqr()?;
    let inner = (sin2.broadcast_div(&alpha2)? + cos2)?;
    let denom = (alpha2.broadcast_mul(&inner.sqr()?)? * std::f64::consts::PI)?;
    Ok(denom.recip()?)
}

/// Exact GGX Smith masking for one direction with `cos_v = n·v` already clamped to
/// ≥ [`COS_MIN`]: `G1 = 2 / (1 + sqrt(1 + α² tan²θ))`.
pub fn smith_g1(cos_v: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    let cos2 = cos_v.sqr()?;
    let tan2 = ((1.0 - &cos2)?.maximum(0.0)? / cos2)?; // same rounding guard as in ggx_d
    let root = (alpha.sqr()?.broadcast_mul(&tan2)? + 1.0)?.sqrt()?; // argument ≥ 1: finite slope
    Ok(((root + 1.0)?.recip()? * 2.0)?)
}

/// Separable Smith shadowing-masking `G = G1(wi)·G1(wo)`.
pub fn smith_g(cos_i: &Tensor, cos_o: &Tensor, alpha: &Tensor) -> Result<Tensor> {
    Ok((smith_g1(cos_i, alpha)? * smith_g1(cos_o, alpha)?)?)
}

/// Schlick's Fresnel `F = F0 + (1 − F0)(1 − cos)^5` with `cos = wi·h` (B,1,H,W) and
/// `f0` (B,3,H,W) → (B,3,H,W).
pub fn schlick(cos_d: &Tensor, f0: &Tensor) -> Result<Tensor> {
    // wi·h ∈ [0, 1] for any pair above the horizon; the clamp only removes rounding excess.
    let weight = (1.0 - cos_d.clamp(0.0, 1.0)?)?.powf(5.0)?;
    Ok(f0.broadcast_add(&(1.0 - f0)?.broadcast_mul(&weight)?)?)
}
