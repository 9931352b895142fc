//! Derivatives of a two-operand op for equivalence tests: the value, both gradients of a
//! weighted sum, and one mixed second derivative. Fused custom ops (this crate's
//! `texel_ops`, `photomat-kernels`' per-plane ops) compare these against the candle
//! composition they replace; the second derivative checks that an op's backward is itself
//! differentiable, as R1 and path-length penalties need (`docs/neural-models.md`, "GAN
//! training").

use candle_core::{Tensor, Var};

use crate::Result;

/// `[y, ∂L/∂u, ∂L/∂v, ∂⟨∂L/∂u, h⟩/∂v]` for `y = op(u, v)` and `L = Σ g ⊙ y`.
///
/// The mixed derivative reaches v through the operands of the ops in the backward of `op`
/// (a plain `backward` detaches the incoming gradient), so it
/// exercises the backward of those ops, not a second backward through the gradient itself.
///
/// # Shapes
/// g as y, h as u.
pub fn bilinear_derivatives(
    op: impl Fn(&Tensor, &Tensor) -> Result<Tensor>,
    u: &Var,
    v: &Var,
    g: &Tensor,
    h: &Tensor,
) -> Result<Vec<Tensor>> {
    let missing =
        |what: &str| crate::Error::Invalid(format!("no {what}: the op does not depend on it"));
    let y = op(u.as_tensor(), v.as_tensor())?;
    let first = (&y * g)?.sum_all()?.backward()?;
    let du = first
        .get(u.as_tensor())
        .ok_or_else(|| missing("∂L/∂u"))?
        .clone();
    let dv = first
        .get(v.as_tensor())
        .ok_or_else(|| missing("∂L/∂v"))?
        .clone();
    let second = (&du * h)?.sum_all()?.backward()?;
    let ddv = second
        .get(v.as_tensor())
        .ok_or_else(|| missing("mixed second derivative"))?
        .clone();
    Ok(vec![y, du, dv, ddv])
}
