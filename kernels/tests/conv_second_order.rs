//! Second-order gradients through [`photomat_kernels::conv2d`] and
//! [`photomat_kernels::bias_leaky_relu_gain`]: the R1 penalty of a small
//! discriminator-like network (`docs/neural-models.md`, "GAN training": lazy R1 = ‖∂D(x)/∂x‖²,
//! differentiated w.r.t. the weights) equals the same computation through candle's own `conv2d` and
//! composite LeakyReLU, and f64 central differences.
//!
//! The inner pass keeps the graph of its gradients (`backward_keeping_graph`,
//! `docs/candle-notes.md`, "Second-order gradients").

use candle_core::{DType, Device, Result, Tensor, Var};
use photomat_core::rng::pseudo_random;
use photomat_kernels::testing::max_abs_diff;
use photomat_kernels::{Conv2dSpec, bias_leaky_relu_gain, conv2d, conv2d_reference};

/// Which implementation D is built from: photomat-kernels' ops, or candle's own.
#[derive(Clone, Copy)]
enum Ops {
    Ours,
    Candle,
}

impl Ops {
    fn conv(self, x: &Tensor, w: &Tensor, spec: Conv2dSpec) -> Result<Tensor> {
        match self {
            Ops::Ours => conv2d(x, w, spec),
            Ops::Candle => conv2d_reference(x, w, spec),
        }
    }

    /// StyleGAN2's `bias_act` with `lrelu` (bias 0.1·c − 0.15 on channel c, slope 0.2, gain
    /// √2); candle's form is `broadcast_add` then `g·(1 − a)·relu(z) + g·a·z`.
    fn bias_lrelu(self, x: &Tensor) -> Result<Tensor> {
        let (a, g) = (0.2, std::f64::consts::SQRT_2);
        let c = x.dim(1)?;
        let bias: Vec<f64> = (0..c).map(|i| 0.1 * i as f64 - 0.15).collect();
        let bias = Tensor::from_vec(bias, c, x.device())?;
        match self {
            Ops::Ours => bias_leaky_relu_gain(x, &bias, a, g),
            Ops::Candle => {
                let z = x.broadcast_add(&bias.reshape((1, c, 1, 1))?)?;
                z.relu()?.affine(g * (1.0 - a), 0.0)? + z.affine(g * a, 0.0)?
            }
        }
    }
}

/// D(x) = Σ v ⊙ conv₂(lrelu(tanh(conv₁(x)) + bias)): a 3×3 circular conv, a smooth nonlinearity
/// (so the second derivative is not zero), D's activation and a 4×4 stride-2 zero-padded
/// conv, as in D's blocks.
/// (Even sizes: candle 0.11.1's own conv2d backward fails with a shape mismatch when a
/// stride-2 conv leaves the last input row unread, so the reference needs them.)
fn discriminator(ops: Ops, x: &Tensor, w1: &Tensor, w2: &Tensor, v: &Tensor) -> Result<Tensor> {
    let h = ops.bias_lrelu(&ops.conv(x, w1, Conv2dSpec::circular(1, 1))?.tanh()?)?;
    (ops.conv(&h, w2, Conv2dSpec::zeros(2, 1))? * v)?.sum_all()
}

/// R1 = ‖∂D/∂x‖² and its gradients w.r.t. (w1, w2).
fn r1_and_grads(
    ops: Ops,
    x0: &Tensor,
    w1: &Var,
    w2: &Var,
    v: &Tensor,
) -> Result<(f64, Tensor, Tensor)> {
    let x = Var::from_tensor(x0)?;
    let d = discriminator(ops, x.as_tensor(), w1.as_tensor(), w2.as_tensor(), v)?;
    let dx = d
        .backward_keeping_graph()?
        .remove(x.as_tensor())
        .expect("D depends on x");
    let r1 = dx.sqr()?.sum_all()?;
    let grads = r1.backward()?;
    let get = |w: &Var| {
        grads
            .get(w.as_tensor())
            .cloned()
            .expect("R1 depends on the weights")
    };
    Ok((r1.to_scalar::<f64>()?, get(w1), get(w2)))
}

#[test]
fn conv_r1_gradient_matches_candle_and_finite_differences() -> Result<()> {
    let dev = Device::Cpu;
    let x = pseudo_random((2, 3, 8, 6), 1, DType::F64, &dev)?;
    let w1 = Var::from_tensor(&(pseudo_random((4, 3, 3, 3), 2, DType::F64, &dev)? * 0.5)?)?;
    let w2 = Var::from_tensor(&(pseudo_random((2, 4, 4, 4), 3, DType::F64, &dev)? * 0.5)?)?;
    let v = pseudo_random((2, 2, 4, 3), 4, DType::F64, &dev)?;

    let (r, g1, g2) = r1_and_grads(Ops::Ours, &x, &w1, &w2, &v)?;
    let (r_ref, g1_ref, g2_ref) = r1_and_grads(Ops::Candle, &x, &w1, &w2, &v)?;
    // f64, two nested sums of ≤ 4·16·56 terms of O(1): rounding ≲ 1e-12 relative.
    assert!(
        (r - r_ref).abs() < 1e-10 * r_ref.abs().max(1.0),
        "{r} vs {r_ref}"
    );
    assert!(
        max_abs_diff(&g1, &g1_ref)? < 1e-9,
        "∂R1/∂w1 differs from candle's"
    );
    assert!(
        max_abs_diff(&g2, &g2_ref)? < 1e-9,
        "∂R1/∂w2 differs from candle's"
    );
    assert!(
        g1.abs()?.sum_all()?.to_scalar::<f64>()? > 1e-3,
        "non-trivial gradient"
    );

    // Central differences of R1 on a few weights of each layer: truncation O(δ²·R1''') with
    // δ = 1e-4 is ≈ 1e-8 for these O(1) terms; rounding 1e-16·R1/δ ≈ 1e-11.
    let delta = 1e-4;
    for (w, grad, other_is_w1) in [(&w1, &g1, false), (&w2, &g2, true)] {
        let base = w.as_tensor().flatten_all()?.to_vec1::<f64>()?;
        let analytic = grad.flatten_all()?.to_vec1::<f64>()?;
        for i in (0..base.len()).step_by(base.len() / 7 + 1) {
            let r1_at = |d: f64| -> Result<f64> {
                let mut vals = base.clone();
                vals[i] += d;
                let shifted = Var::from_tensor(&Tensor::from_vec(vals, w.shape(), &dev)?)?;
                let (a, b) = if other_is_w1 {
                    (&w1, &shifted)
                } else {
                    (&shifted, &w2)
                };
                Ok(r1_and_grads(Ops::Ours, &x, a, b, &v)?.0)
            };
            let fd = (r1_at(delta)? - r1_at(-delta)?) / (2.0 * delta);
            let tol = 1e-6 * analytic[i].abs().max(1.0);
            assert!(
                (analytic[i] - fd).abs() < tol,
                "w[{i}]: {} vs {fd}",
                analytic[i]
            );
        }
    }
    Ok(())
}
