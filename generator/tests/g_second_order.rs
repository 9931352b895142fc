//! Path-length regularisation (StyleGAN2 §3.2; `train::path_length`) differentiates G twice:
//! the gradient of `Σ F ⊙ y` with respect to the per-layer w, then the gradient of its squared
//! norm with respect to G's parameters. G runs on photomat-kernels' fused ops (modulated conv,
//! noise + bias + lrelu epilogue, sparse FIR), whose backward passes are built from ops with a
//! backward; this checks that the double backward through them equals the one through plain
//! candle ops, in zero-padded and tileable mode. The inner pass is `backward_keeping_graph`
//! (`docs/candle-notes.md`, "Second-order gradients").

mod common;

use anyhow::Result;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::VarMap;
use common::{compare, config, perturb, seeded_noise, value_and_grads};
use photomat_generator::{Generator, NoiseInput, seeded_uniform, seeded_var_builder};
use photomat_kernels::with_reference_ops;

#[test]
fn path_length_double_backward_through_g_equals_plain_candle() -> Result<()> {
    let dev = Device::Cpu;
    for tileable in [false, true] {
        let cfg = config(tileable);
        let vars = VarMap::new();
        let g = Generator::new(&cfg, seeded_var_builder(&vars, 7, DType::F64, &dev))?;
        perturb(&vars)?;
        let z = seeded_uniform((2, cfg.latent_dim), 1, DType::F64, &dev)?;
        let noise = seeded_noise(&g, 2)?;
        let y = seeded_uniform((2, cfg.feature_channels, 32, 32), 2, DType::F64, &dev)?;
        let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
            let ws = Var::from_tensor(&g.ws(&z, 1.0)?.detach())?;
            let f = g
                .synthesis()
                .forward(ws.as_tensor(), &NoiseInput::Given(&noise))?;
            let jvp = (f * &y)?.sum_all()?;
            let grad_ws = jvp
                .backward_keeping_graph()?
                .remove(ws.as_tensor())
                .expect("F depends on w");
            assert!(grad_ws.track_op(), "the first gradient keeps its graph");
            value_and_grads(&grad_ws.sqr()?.sum_all()?, &vars)
        };
        let fast = run()?;
        let reference = with_reference_ops(run)?;
        assert!(
            fast.1.len() > 20,
            "the synthesis layers have second-order gradients"
        );
        // f64, other summation orders through two passes of ~10 layers: ≲ 1e-12 relative.
        compare(
            &format!("path length tileable={tileable}"),
            fast,
            reference,
            1e-9,
        )?;
    }
    Ok(())
}
