//! Second-order gradients through [`photomat_kernels::per_texel_mlp`]: path-length
//! regularisation (StyleGAN2 §3.2) differentiates the gradient of `Σ M(F, ω) ⊙ y` with respect
//! to what produced F again, with respect to M's weights and F's own parameters. This checks
//! that the double backward through the fused op equals the one through candle's composition
//! (f64), and that the derivatives the op does not implement fail loudly instead of being
//! wrong.
//!
//! The inner passes keep the graph of their gradients (`backward_keeping_graph`,
//! `docs/candle-notes.md`, "Second-order gradients").

use candle_core::{DType, Device, Result, Tensor, Var};
use photomat_core::rng::pseudo_random;
use photomat_kernels::testing::max_abs_diff;
use photomat_kernels::{MlpActivation, MlpLayer, per_texel_mlp, with_reference_ops};

const ACT: MlpActivation = MlpActivation {
    slope: 0.2,
    gain: std::f64::consts::SQRT_2,
};

#[test]
fn path_length_double_backward_through_the_fused_mlp_equals_candle() -> Result<()> {
    let dev = Device::Cpu;
    let (b, c, h, w) = (2, 4, 17, 19);
    let dims = [c + 3, 16, 16, 16, 3];
    let params: Vec<(Var, Var)> = (0..dims.len() - 1)
        .map(|i| {
            let s = 10 + 2 * i as u64;
            Ok((
                Var::from_tensor(&pseudo_random((dims[i + 1], dims[i]), s, DType::F64, &dev)?)?,
                Var::from_tensor(&pseudo_random(dims[i + 1], s + 1, DType::F64, &dev)?)?,
            ))
        })
        .collect::<Result<_>>()?;
    let layers: Vec<MlpLayer<'_>> = params
        .iter()
        .enumerate()
        .map(|(i, (w, bias))| MlpLayer {
            weight: w.as_tensor(),
            bias: bias.as_tensor(),
            weight_gain: 1.0 / (dims[i] as f64).sqrt(),
            bias_gain: 0.5,
        })
        .collect();
    // F = tanh(ws ⊙ θ): smooth in both, so the second derivative through F is not zero.
    let theta = Var::from_tensor(&pseudo_random((1, c, 1, 1), 1, DType::F64, &dev)?)?;
    let ws0 = pseudo_random((b, c, h, w), 2, DType::F64, &dev)?;
    let omega = pseudo_random((b, 3, h, w), 3, DType::F64, &dev)?;
    let y = pseudo_random((b, 3, h, w), 4, DType::F64, &dev)?;
    let first = |ws: &Var| -> Result<Tensor> {
        let f = ws.as_tensor().broadcast_mul(theta.as_tensor())?.tanh()?;
        let img = per_texel_mlp(&f, &omega, &layers, ACT)?;
        let g = (img * &y)?.sum_all()?.backward_keeping_graph()?;
        Ok(g.get(ws.as_tensor()).cloned().expect("images depend on ws"))
    };
    let run = || -> Result<Vec<Tensor>> {
        let ws = Var::from_tensor(&ws0)?;
        let g = first(&ws)?;
        assert!(g.track_op(), "the first gradient keeps its graph");
        let loss = g.sqr()?.sum_all()?;
        let store = loss.backward()?;
        let mut out = vec![loss.clone()];
        let vars = std::iter::once(&theta).chain(params.iter().flat_map(|(w, b)| [w, b]));
        for v in vars {
            // The reference gives biases no gradient (its activation's derivative has none);
            // the fused op gives zeros.
            out.push(match store.get(v.as_tensor()) {
                Some(t) => t.clone(),
                None => v.as_tensor().zeros_like()?,
            });
        }
        Ok(out)
    };
    let fused = run()?;
    let reference = with_reference_ops(run)?;
    for (j, (f, r)) in fused.iter().zip(&reference).enumerate() {
        assert_eq!(f.dims(), r.dims(), "output {j}");
        let scale = r.abs()?.flatten_all()?.max(0)?.to_scalar::<f64>()?.max(1.0);
        // f64, two passes through 4 layers over 646 texels in another order: ≲ 1e-12 relative.
        let d = max_abs_diff(f, r)?;
        assert!(d <= 1e-9 * scale, "output {j}: |Δ| {d}, scale {scale}");
    }
    let weight_grads = fused[2..].iter().step_by(2);
    assert!(
        weight_grads
            .clone()
            .all(|t| max_abs_diff(t, &t.zeros_like().unwrap()).unwrap() > 0.0),
        "every weight has a second-order gradient"
    );

    // The second derivative of M's weight gradient is not implemented: it must fail.
    let ws = Var::from_tensor(&ws0)?;
    let f = ws.as_tensor().broadcast_mul(theta.as_tensor())?.tanh()?;
    let img = per_texel_mlp(&f, &omega, &layers, ACT)?;
    let g = (img * &y)?.sum_all()?.backward_keeping_graph()?;
    let dw0 = g.get(params[0].0.as_tensor()).expect("a weight gradient");
    assert!(dw0.sqr()?.sum_all()?.backward().is_err());
    // Nor is a third derivative.
    let g = first(&ws)?;
    let g2 = g.sqr()?.sum_all()?.backward_keeping_graph()?;
    let d2 = g2
        .get(params[1].0.as_tensor())
        .expect("a second-order gradient");
    assert!(d2.sqr()?.sum_all()?.backward().is_err());
    Ok(())
}
