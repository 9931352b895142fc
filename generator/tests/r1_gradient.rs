//! The R1 penalty's gradient with respect to D's parameters is a double backward (its inner
//! pass is `backward_keeping_graph`): this file checks it against central finite differences
//! on a tiny D, with no environment variable set, and that D on photomat-kernels' ops gives
//! the same double backward as on plain candle ops.

use anyhow::Result;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::VarMap;
use photomat_generator::{Discriminator, GeneratorConfig, seeded_uniform, seeded_var_builder};

/// (parameter name, flat index) pairs probed, spread over every kind of layer: fromrgb, the
/// residual convs, the skip, the epilogue conv and both fully connected layers.
const PROBES: [(&str, usize); 9] = [
    ("b32.fromrgb.weight", 5),
    ("b32.fromrgb.bias", 1),
    ("b32.conv0.weight", 17),
    ("b16.conv1.weight", 40),
    ("b8.skip.weight", 3),
    ("b16.conv0.bias", 2),
    ("b4.conv.weight", 60),
    ("b4.fc.weight", 33),
    ("b4.out.weight", 2),
];

struct Setup {
    vars: VarMap,
    d: Discriminator,
    image: Tensor,
    omega: Tensor,
}

fn setup() -> Result<Setup> {
    let dev = Device::Cpu;
    // 32², 4 channels per block; f64 so that finite differences resolve 1e-6 relative.
    let cfg = GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 128.0,
        ..Default::default()
    };
    let vars = VarMap::new();
    // Seeded weights: the probes' derivatives (checked below) are reproducible.
    let d = Discriminator::new(&cfg, seeded_var_builder(&vars, 1, DType::F64, &dev))?;
    // B = 5: two minibatch-stddev groups of sizes 3 and 2 are part of the graph.
    let image = seeded_uniform((5, 3, 32, 32), 1, DType::F64, &dev)?;
    let omega = seeded_uniform((5, 3, 32, 32), 2, DType::F64, &dev)?;
    Ok(Setup {
        vars,
        d,
        image,
        omega,
    })
}

fn var(s: &Setup, name: &str) -> Var {
    s.vars.data().lock().expect("lock")[name].clone()
}

/// Σ over the batch of the R1 penalty.
fn penalty(s: &Setup) -> candle_core::Result<Tensor> {
    s.d.r1_penalty(&s.image, &s.omega)?.sum_all()
}

/// ∂(Σ R1)/∂θ at the probes, by backpropagation.
fn analytic(s: &Setup) -> Result<Vec<f64>> {
    let grads = penalty(s)?.backward()?;
    let mut out = Vec::new();
    for (name, i) in PROBES {
        let v = var(s, name);
        let g = grads
            .get(v.as_tensor())
            .map_or(Ok(0.0), |g| g.flatten_all()?.get(i)?.to_scalar::<f64>())?;
        out.push(g);
    }
    Ok(out)
}

/// ∂(Σ R1)/∂θ at the probes, by central differences (the penalty itself needs only the first
/// backward pass, which is exact either way). R1 is smooth in θ away from LeakyReLU kinks;
/// with δ = 1e-7 no pre-activation crosses 0 (else a probe would disagree by O(1)), so the
/// error is O(δ²·f''') + the rounding of Σ R1 (a sum of ~10⁴ f64 terms, ≈ 1.7e-3 at this
/// seeded initialisation: ~1e-17 … 1e-16 absolute) divided by δ, i.e. ≲ 1e-10.
fn finite_differences(s: &Setup) -> Result<Vec<f64>> {
    let delta = 1e-7;
    let mut out = Vec::new();
    for (name, i) in PROBES {
        let v = var(s, name);
        let base = v.as_tensor().copy()?;
        let shape = base.shape().clone();
        let eval = |d: f64| -> Result<f64> {
            let mut values = base.flatten_all()?.to_vec1::<f64>()?;
            values[i] += d;
            v.set(&Tensor::from_vec(values, shape.clone(), &Device::Cpu)?)?;
            Ok(penalty(s)?.to_scalar::<f64>()?)
        };
        let fd = (eval(delta)? - eval(-delta)?) / (2.0 * delta);
        v.set(&base)?;
        out.push(fd);
    }
    Ok(out)
}

#[test]
fn r1_gradient_matches_finite_differences() -> Result<()> {
    let s = setup()?;
    let reference = photomat_kernels::with_reference_ops(|| analytic(&s))?;
    let (analytic, fd) = (analytic(&s)?, finite_differences(&s)?);
    // The inner pass kept its graph for itself only: the thread's backward passes detach again.
    assert!(!candle_core::backprop::keeps_graph());
    // D runs on photomat-kernels' convolutions, FIR passes and activations; on plain candle
    // ops the double backward must give the same numbers (f64, other summation orders:
    // ≲ 1e-12 relative).
    for ((name, i), (a, r)) in PROBES.iter().zip(analytic.iter().zip(&reference)) {
        assert!(
            (a - r).abs() <= 1e-9 * r.abs(),
            "{name}[{i}]: kernels {a} vs plain candle {r}"
        );
    }
    // Measured (seed 1): derivatives 2.5e-6 … 8.7e-4, differences ≤ 4e-11 absolute and
    // ≤ 5e-6 relative. Tolerance: 1e-4 relative plus the 1e-10 rounding floor above; every
    // probe is ≥ 1e-6, 10⁴ times that floor, so a wrong or missing term cannot hide in it.
    for ((name, i), (a, f)) in PROBES.iter().zip(analytic.iter().zip(&fd)) {
        assert!(
            f.abs() > 1e-6,
            "{name}[{i}]: the penalty depends on it ({f})"
        );
        assert!(
            (a - f).abs() <= 1e-4 * f.abs() + 1e-10,
            "{name}[{i}]: backprop {a} vs finite differences {f}"
        );
    }
    Ok(())
}
