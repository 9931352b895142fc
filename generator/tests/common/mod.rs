//! Helpers shared by the tests comparing G, M and D on photomat-kernels' ops with the same
//! networks on plain candle ops (`fast_ops.rs`, `g_second_order.rs`).

use anyhow::Result;
use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use photomat_generator::{GeneratorConfig, seeded_uniform};
use photomat_kernels::testing::max_abs_diff;

/// 32², 8 channels per block (multiplier 1/64), w of 16, F of 8 channels: every kind of
/// layer, small enough for the dev profile.
pub fn config(tileable: bool) -> GeneratorConfig {
    GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        tileable,
        ..Default::default()
    }
}

/// Seeded noise images for every noise layer of `g`, batch `b`.
pub fn seeded_noise(g: &photomat_generator::Generator, b: usize) -> Result<Vec<Tensor>> {
    Ok(g.synthesis()
        .noise_shapes(b)
        .into_iter()
        .enumerate()
        .map(|(i, s)| seeded_uniform(s, 10 + i as u64, DType::F64, &Device::Cpu))
        .collect::<candle_core::Result<Vec<_>>>()?)
}

/// Seeded weights, then every variable shifted by a seeded O(0.1) perturbation so that the
/// biases and noise strengths (initialised to 0) are not 0 and every term is exercised.
pub fn perturb(vars: &VarMap) -> Result<()> {
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
pub fn value_and_grads(loss: &Tensor, vars: &VarMap) -> Result<(f64, Vec<(String, Tensor)>)> {
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
pub fn compare(
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
