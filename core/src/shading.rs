//! Per-texel shading geometry shared by all lobes: cosines w.r.t. the shading normal, the
//! half vector and the below-horizon mask.
//!
//! Masking follows Mitsuba 3 (`diffuse.cpp`, `principled.cpp`): a pair with `n·wi ≤ 0` or
//! `n·wo ≤ 0` contributes exactly 0. The mask is a 0/1 factor rather than a `where`, and every
//! quantity it multiplies stays finite for masked texels (cosines are floored at 0 and the
//! microfacet forms never divide by a cosine), so masked texels have value 0 *and* gradient 0
//! (a `where` over an infinite branch still back-propagates 0·∞ = NaN).

use candle_core::Tensor;

use crate::Result;
use crate::vecops::{cross3, dot3, normalize3};

/// Geometry of one evaluation.
///
/// # Shapes
/// All fields are (B, 1, H, W) per-texel scalars.
#[derive(Debug, Clone)]
pub struct ShadingGeometry {
    /// `max(n·wi, 0)`.
    pub cos_i: Tensor,
    /// `max(n·wo, 0)`.
    pub cos_o: Tensor,
    /// `n·h` with the half vector `h = normalize(wi + wo)`.
    pub cos_h: Tensor,
    /// `|n × h|²` = sin²θ_h, computed without the cancellation of `1 − cos²θ_h`.
    pub sin2_h: Tensor,
    /// `wi·h` (the Fresnel angle).
    pub cos_d: Tensor,
    /// 1 where both directions are strictly above the shading horizon, else 0.
    pub mask: Tensor,
}

impl ShadingGeometry {
    /// `wi`, `wo`: (B, 3, H, W) unit directions; `normal`: (B|1, 3, H|1, W|1), normalised here
    /// (so gradients are w.r.t. the un-normalised normal, as in Mitsuba's `normalmap`).
    pub fn new(wi: &Tensor, wo: &Tensor, normal: &Tensor) -> Result<Self> {
        let n = normalize3(normal)?;
        let raw_i = dot3(&n, wi)?;
        let raw_o = dot3(&n, wo)?;
        let dtype = raw_i.dtype();
        let mask = (raw_i.gt(0.0)?.to_dtype(dtype)? * raw_o.gt(0.0)?.to_dtype(dtype)?)?;
        let h = normalize3(&(wi + wo)?)?;
        Ok(Self {
            cos_i: raw_i.maximum(0.0)?,
            cos_o: raw_o.maximum(0.0)?,
            cos_h: dot3(&n, &h)?,
            sin2_h: {
                let c = cross3(&n, &h)?;
                dot3(&c, &c)?
            },
            cos_d: dot3(wi, &h)?,
            mask,
        })
    }
}
