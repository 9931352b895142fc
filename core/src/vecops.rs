//! Per-texel 3-vector helpers on NCHW tensors whose channel axis holds (x, y, z).
//!
//! Shapes: vectors are (B, 3, H, W), scalars per texel are (B, 1, H, W); broadcasting over
//! B, H and W follows candle's `broadcast_*` rules.

use candle_core::Tensor;

use crate::Result;

/// Squared-length floor inside `normalize3`: keeps the derivative of `sqrt` finite for a zero
/// vector, and lies far below f32 resolution for any unit-scale vector.
const NORM_SQ_FLOOR: f64 = 1e-24;

/// Per-texel dot product: (B, 3, H, W) × (B, 3, H, W) → (B, 1, H, W).
pub fn dot3(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    Ok(a.broadcast_mul(b)?.sum_keepdim(1)?)
}

/// Per-texel unit vector: (B, 3, H, W) → (B, 3, H, W). A zero vector stays zero.
pub fn normalize3(v: &Tensor) -> Result<Tensor> {
    let len = v.sqr()?.sum_keepdim(1)?.maximum(NORM_SQ_FLOOR)?.sqrt()?;
    Ok(v.broadcast_div(&len)?)
}

/// A constant direction (x, y, z) as a (1, 3, 1, 1) tensor of `like`'s dtype and device.
pub fn constant3(xyz: [f64; 3], like: &Tensor) -> Result<Tensor> {
    Ok(Tensor::new(&xyz, like.device())?
        .to_dtype(like.dtype())?
        .reshape((1, 3, 1, 1))?)
}
