//! G, M and D on photomat-kernels' ops (im2col + gemm convolutions, sparse separable FIR,
//! fused bias + LeakyReLU) compute the same values and parameter gradients as on plain candle
//! ops ([`photomat_kernels::with_reference_ops`], the implementation before the kernels were
//! used), for the same seeded weights, in f64: in zero-padded and tileable mode, for G + M
//! and for D.

use anyhow::Result;
use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use photomat_generator::{
    Discriminator, Generator, GeneratorConfig, NoiseInput, Relight, seeded_uniform,
    seeded_var_builder,
};
use photomat_kernels::testing::max_abs_diff;
use photomat_kernels::with_reference_ops;

fn config(tileable: bool) -> GeneratorConfig {
    // 32², 8 channels per block (multiplier 1/64), w of 16, F of 8 channels: every kind of
    // layer, small enough for the dev profile.
    GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        tileable,
        ..Default::default()
    }
}

/// Seeded weights, then every variable shifted by a seeded O(0.1) perturbation so that the
/// biases and noise strengths (initialised to 0) are not 0 and every term is exercised.
fn perturb(vars: &VarMap) -> Result<()> {
    let data = vars.data().lock().expect("lock");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for (i, name) in names.into_iter().enumerate() {
        let v = &data[name];
        let noise = seeded_uniform(v.shape(), 1000 + i as u64, DType::F64, &Device::Cpu)?;
        v.set(&(v.as_tensor() + (noise * 0.1)?)?)?;
    }
    Ok(())
}

/// The loss's value and its gradient w.r.t. every variable of `vars`, sorted by name.
fn value_and_grads(loss: &Tensor, vars: &VarMap) -> Result<(f64, Vec<(String, Tensor)>)> {
    let grads = loss.backward()?;
    let data = vars.data().lock().expect("lock");
    let mut out: Vec<(String, Tensor)> = data
        .iter()
        .filter_map(|(n, v)| grads.get(v.as_tensor()).map(|g| (n.clone(), g.clone())))
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    Ok((loss.to_scalar::<f64>()?, out))
}

/// Compares the kernels' run with the reference run: same value, same set of gradients, each
/// within `tol` of the reference relative to its largest entry.
fn compare(
    what: &str,
    fast: (f64, Vec<(String, Tensor)>),
    reference: (f64, Vec<(String, Tensor)>),
    tol: f64,
) -> Result<()> {
    let ((v, g), (rv, rg)) = (fast, reference);
    assert!(
        (v - rv).abs() <= tol * rv.abs().max(1.0),
        "{what}: loss {v} vs {rv}"
    );
    let names = |g: &[(String, Tensor)]| g.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(
        names(&g),
        names(&rg),
        "{what}: gradients of the same variables"
    );
    for ((name, a), (_, b)) in g.iter().zip(&rg) {
        let scale = b.abs()?.max_all()?.to_scalar::<f64>()?;
        assert!(scale > 0.0, "{what}: {name} has a zero reference gradient");
        let diff = max_abs_diff(a, b)?;
        assert!(
            diff <= tol * scale,
            "{what}: ∂/∂{name} differs by {diff} (scale {scale})"
        );
    }
    Ok(())
}

#[test]
fn generator_and_relight_on_kernels_equal_plain_candle() -> Result<()> {
    let dev = Device::Cpu;
    for tileable in [false, true] {
        let cfg = config(tileable);
        let vars = VarMap::new();
        let vb = seeded_var_builder(&vars, 3, DType::F64, &dev);
        let g = Generator::new(&cfg, vb.pp("g"))?;
        let m = Relight::new(&cfg, vb.pp("m"))?;
        perturb(&vars)?;
        let z = seeded_uniform((2, cfg.latent_dim), 1, DType::F64, &dev)?;
        let noise = g
            .synthesis()
            .noise_shapes(2)
            .into_iter()
            .enumerate()
            .map(|(i, s)| seeded_uniform(s, 10 + i as u64, DType::F64, &dev))
            .collect::<candle_core::Result<Vec<_>>>()?;
        let omega = seeded_uniform((2, 3, 32, 32), 2, DType::F64, &dev)?;
        let weights = seeded_uniform((2, 3, 32, 32), 3, DType::F64, &dev)?;
        let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
            let f = g.forward(&z, 0.7, &NoiseInput::Given(&noise))?;
            let rgb = m.forward(&f, &omega)?;
            // Both F and M's output enter the loss, so G's gradients do not only come
            // through M.
            let loss = ((rgb * &weights)?.sum_all()? + f.sqr()?.mean_all()?)?;
            value_and_grads(&loss, &vars)
        };
        let fast = run()?;
        let reference = with_reference_ops(run)?;
        assert!(fast.1.len() > 30, "every layer has gradients");
        // f64: the two paths sum the same products in other orders (gemm blocking, sparse vs
        // dense FIR with exact zeros); through ~12 layers the rounding stays ≲ 1e-13 relative.
        compare(&format!("G+M tileable={tileable}"), fast, reference, 1e-9)?;
    }
    Ok(())
}

#[test]
fn discriminator_on_kernels_equals_plain_candle() -> Result<()> {
    let dev = Device::Cpu;
    let cfg = config(false);
    let vars = VarMap::new();
    let d = Discriminator::new(&cfg, seeded_var_builder(&vars, 4, DType::F64, &dev))?;
    perturb(&vars)?;
    let image = seeded_uniform((3, 3, 32, 32), 5, DType::F64, &dev)?;
    let omega = seeded_uniform((3, 3, 32, 32), 6, DType::F64, &dev)?;
    let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
        let logits = d.forward(&image, &omega)?;
        let loss = (logits.sqr()? + logits)?.sum_all()?;
        value_and_grads(&loss, &vars)
    };
    let fast = run()?;
    let reference = with_reference_ops(run)?;
    // Same argument as for G: other summation orders only.
    compare("D", fast, reference, 1e-9)
}
