//! Per-texel 3-vector helpers on NCHW tensors whose channel axis holds (x, y, z).
//!
//! Shapes: vectors are (B, 3, H, W), scalars per texel are (B, 1, H, W); broadcasting over
//! B, H and W follows candle's `broadcast_*` rules.

use candle_core::Tensor;

use crate::Result;
use crate::texel_ops::{channel_dot, scale_texels};

/// Squared-length floor inside `normalize3`: keeps the derivative of `sqrt` finite for a zero
/// vector, and lies far below f32 resolution for any unit-scale vector.
const NORM_SQ_FLOOR: f64 = 1e-24;

/// Per-texel dot product: (B, 3, H, W) × (B, 3, H, W) → (B, 1, H, W), broadcasting; one fused
/// pass when the shapes are equal ([`crate::texel_ops::channel_dot`]).
pub fn dot3(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    channel_dot(a, b)
}

/// Per-texel cross product: (B, 3, H, W) × (B, 3, H, W) → (B, 3, H, W), broadcasting.
pub fn cross3(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let c = |t: &Tensor, i: usize| t.narrow(1, i, 1);
    let (ax, ay, az) = (c(a, 0)?, c(a, 1)?, c(a, 2)?);
    let (bx, by, bz) = (c(b, 0)?, c(b, 1)?, c(b, 2)?);
    let x = (ay.broadcast_mul(&bz)? - az.broadcast_mul(&by)?)?;
    let y = (az.broadcast_mul(&bx)? - ax.broadcast_mul(&bz)?)?;
    let z = (ax.broadcast_mul(&by)? - ay.broadcast_mul(&bx)?)?;
    Ok(Tensor::cat(&[x, y, z], 1)?)
}

/// Per-texel unit vector: (B, 3, H, W) → (B, 3, H, W). A zero vector stays zero.
pub fn normalize3(v: &Tensor) -> Result<Tensor> {
    let len = channel_dot(v, v)?.maximum(NORM_SQ_FLOOR)?.sqrt()?;
    scale_texels(v, &len.recip()?)
}

/// A constant direction (x, y, z) as a (1, 3, 1, 1) tensor of `like`'s dtype and device.
pub fn constant3(xyz: [f64; 3], like: &Tensor) -> Result<Tensor> {
    Ok(Tensor::new(&xyz, like.device())?
        .to_dtype(like.dtype())?
        .reshape((1, 3, 1, 1))?)
}
