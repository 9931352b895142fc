//! Properties of the map estimator E (paper §4 "Implementation"; `docs/neural-models.md`, "Map
//! estimator E"): its head fits every registered BRDF plugin, it is tileable (commutes with rolls
//! by the total stride, keeps periodic features periodic), its size is the paper's, and it trains.

use candle_core::{DType, Device, Result, Shape, Tensor};
use candle_nn::{AdamW, Optimizer, ParamsAdamW, VarBuilder, VarMap};
use photomat_brdfs as _; // link the built-in plugins into the registry
use photomat_estimator::{Estimator, EstimatorConfig};

/// Values uniform in [−1, 1), f32 on the CPU, from the workspace's seeded generator (candle's
/// CPU generator cannot be seeded), so inputs are identical on every run.
fn pseudo_random(shape: impl Into<Shape>, seed: u64) -> Result<Tensor> {
    photomat_core::rng::pseudo_random(shape, seed, DType::F32, &Device::Cpu)
}

fn max_abs(t: &Tensor) -> Result<f32> {
    t.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()
}

fn max_abs_diff(a: &Tensor, b: &Tensor) -> Result<f32> {
    max_abs(&(a - b)?)
}

/// A freshly initialised estimator and its variables.
fn estimator(cfg: EstimatorConfig) -> Result<(Estimator, VarMap)> {
    let vars = VarMap::new();
    let e = Estimator::new(
        cfg,
        VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu),
    )?;
    Ok((e, vars))
}

/// Overwrites every variable with seeded values of the initialiser's scale (Xavier σ for conv
/// weights, 0.02 for biases; uniform on [−√3σ, √3σ) has standard deviation σ), so that a test
/// whose outcome depends on the weights is identical on every run.
fn reseed(vars: &VarMap, seed: u64) -> Result<()> {
    let data = vars.data().lock().expect("varmap lock");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for (i, name) in names.into_iter().enumerate() {
        let var = &data[name];
        let sigma = match *var.dims() {
            [co, ci, k, _] => (2.0 / ((co + ci) * k * k) as f64).sqrt(),
            _ => 0.02,
        };
        let values =
            pseudo_random(var.shape(), seed + i as u64)?.affine(3f64.sqrt() * sigma, 0.0)?;
        var.set(&values)?;
    }
    Ok(())
}

/// Registry specification of every registered plugin: models by name, adapters wrapping
/// `ggx` (which has the `normal` map every built-in adapter replaces).
fn every_model_spec() -> Vec<String> {
    let regs = photomat_core::registrations().expect("registry without duplicates");
    regs.iter()
        .map(|r| {
            if r.takes_nested {
                format!("{}(ggx)", r.name)
            } else {
                r.name.to_string()
            }
        })
        .collect()
}

#[test]
fn estimator_head_has_plugin_channel_count() -> anyhow::Result<()> {
    let specs = every_model_spec();
    // Guard: an unlinked plugin crate leaves the registry empty and this loop vacuous.
    for builtin in photomat_brdfs::builtin_names()? {
        assert!(
            specs
                .iter()
                .any(|s| s == builtin || s.starts_with(&format!("{builtin}("))),
            "plugin '{builtin}' is not registered (registry: {specs:?})"
        );
    }
    let features = pseudo_random((2, 32, 32, 32), 1)?;
    for spec in &specs {
        let brdf = photomat_core::lookup(spec)?;
        let n = brdf.channels();
        let vars = VarMap::new();
        let e = Estimator::for_brdf(
            brdf.as_ref(),
            VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu),
        )?;
        assert_eq!(e.config().out_channels, n, "{spec}");
        assert_eq!(e.forward(&features)?.dims4()?, (2, n, 32, 32), "{spec}");
        let maps = e.estimate(&features, brdf.as_ref())?;
        maps.validate(&brdf.name(), brdf.params())?;
        for param in brdf.params() {
            let map = maps.get(param.name)?;
            let (lo, hi) = param.range;
            let min = map.flatten_all()?.min(0)?.to_scalar::<f32>()?;
            let max = map.flatten_all()?.max(0)?.to_scalar::<f32>()?;
            assert!(
                lo <= min && max <= hi,
                "{spec}: '{}' spans [{min}, {max}], range [{lo}, {hi}]",
                param.name
            );
        }
    }
    // The paper's two configurations.
    assert_eq!(photomat_core::lookup("height(ggx)")?.channels(), 8);
    assert_eq!(photomat_core::lookup("coated")?.channels(), 11);
    Ok(())
}

#[test]
fn estimator_rejects_a_model_with_another_channel_count() -> anyhow::Result<()> {
    let (e, _vars) = estimator(EstimatorConfig::default())?; // n = 8
    let coated = photomat_core::lookup("coated")?; // n = 11
    let err = e
        .estimate(&pseudo_random((1, 32, 32, 32), 2)?, coated.as_ref())
        .expect_err("8 ≠ 11");
    assert!(err.to_string().contains("takes 11"), "{err}");
    Ok(())
}

#[test]
fn estimator_is_shift_equivariant() -> Result<()> {
    // Non-square input (rows ≠ columns) catches transposed shifts.
    let (e, _vars) = estimator(EstimatorConfig::default())?;
    let x = pseudo_random((1, 32, 64, 96), 3)?;
    let y = e.forward(&x)?;
    let scale = max_abs(&y)?.max(1.0);
    // Every layer commutes with the roll exactly in real arithmetic; in f32 the tiled gemms
    // and the dense interpolation rows may add the same terms in another order, a few ulps
    // per layer over 19 layers: ≤ 1e-5 of the output scale. A boundary artefact (zero padding,
    // clamped upsampling) is O(output) at the seams.
    let tolerance = 1e-4 * scale;
    for (rows, cols) in [(32, 0), (0, 64), (32, -32), (-64, 32)] {
        let rolled_in = e.forward(&x.roll(rows, 2)?.roll(cols, 3)?)?;
        let rolled_out = y.roll(rows, 2)?.roll(cols, 3)?;
        let diff = max_abs_diff(&rolled_in, &rolled_out)?;
        assert!(
            diff < tolerance,
            "roll ({rows}, {cols}): |E(roll x) − roll E(x)| = {diff}"
        );
    }
    // Control: a shift that is not a multiple of the stride-2 levels is not an equivariance, so
    // the comparison above does detect a mismatch.
    let diff = max_abs_diff(&e.forward(&x.roll(1, 3)?)?, &y.roll(1, 3)?)?;
    assert!(
        diff > 100.0 * tolerance,
        "a 1-texel roll should not commute (diff {diff})"
    );
    Ok(())
}

#[test]
fn estimator_maps_periodic_features_to_periodic_maps() -> Result<()> {
    // A 2 × 2 tiling of one 32 × 32 tile. With circular padding and periodic upsampling every
    // level sees a periodic image, so the output repeats with period 32. Zero padding (or
    // PyTorch's clamped/align-corners upsampling) would make the seams at rows/columns 0 and
    // 63 differ from the seam at 31/32, breaking the period.
    let (e, _vars) = estimator(EstimatorConfig::default())?;
    let tile = pseudo_random((2, 32, 32, 32), 4)?;
    let row = Tensor::cat(&[&tile, &tile], 3)?;
    let x = Tensor::cat(&[&row, &row], 2)?;
    let y = e.forward(&x)?;
    let tolerance = 1e-4 * max_abs(&y)?.max(1.0); // as in estimator_is_shift_equivariant
    let top_left = y.narrow(2, 0, 32)?.narrow(3, 0, 32)?;
    for (r, c) in [(0, 32), (32, 0), (32, 32)] {
        let quadrant = y.narrow(2, r, 32)?.narrow(3, c, 32)?;
        let diff = max_abs_diff(&quadrant, &top_left)?;
        assert!(diff < tolerance, "quadrant ({r}, {c}) differs by {diff}");
    }
    // The tile itself is not constant: periodicity is not trivially satisfied.
    let spread = max_abs_diff(&top_left, &top_left.roll(1, 3)?)?;
    assert!(
        spread > 100.0 * tolerance,
        "degenerate output, spread {spread}"
    );
    Ok(())
}

#[test]
fn estimator_default_parameter_count() -> Result<()> {
    // Hand count for the paper's configuration at n = 8: a k×k conv C_in → C_out has
    // C_out·C_in·k² weights + C_out biases.
    let conv = |c_in: usize, c_out: usize, k: usize| c_out * c_in * k * k + c_out;
    let encoder = conv(32, 32, 4)
        + conv(32, 32, 3)
        + conv(32, 64, 4)
        + conv(64, 64, 3)
        + conv(64, 128, 4)
        + conv(128, 128, 3)
        + conv(128, 256, 4)
        + conv(256, 256, 3)
        + conv(256, 256, 4)
        + conv(256, 256, 3);
    // Decoder inputs: upsampled coarse level ‖ skip.
    let decoder = conv(256 + 256, 256, 3)
        + conv(256, 256, 3)
        + conv(256 + 128, 128, 3)
        + conv(128, 128, 3)
        + conv(128 + 64, 64, 3)
        + conv(64, 64, 3)
        + conv(64 + 32, 32, 3)
        + conv(32, 32, 3);
    let head = conv(32, 8, 3);
    let expected = encoder + decoder + head;
    assert_eq!(expected, 5_674_632);

    let cfg = EstimatorConfig::default();
    assert_eq!(cfg.out_channels, 8);
    assert_eq!(cfg.num_parameters(), expected);
    let (_e, vars) = estimator(cfg)?;
    let counted: usize = vars.all_vars().iter().map(|v| v.elem_count()).sum();
    assert_eq!(counted, expected);
    assert_eq!(vars.all_vars().len(), 2 * 19); // 19 convs, weight + bias each
    Ok(())
}

/// A smooth, periodic (B, 8, 32, 32) target: a per-channel level in [−0.8, 0.8] plus a wave of
/// amplitude 0.2, inside tanh's working range and reachable by E (whose head sees H/2 features,
/// so per-texel noise could not be fitted).
fn smooth_target() -> Result<Tensor> {
    let (c, s) = (8, 32);
    let mut v = Vec::with_capacity(c * s * s);
    for k in 0..c {
        let level = 0.8 * (2.0 * k as f32 / (c - 1) as f32 - 1.0);
        for i in 0..s {
            for j in 0..s {
                let phase =
                    std::f32::consts::TAU * ((i + 2 * j) as f32 / s as f32 + k as f32 / c as f32);
                v.push(level + 0.2 * phase.sin());
            }
        }
    }
    Tensor::from_vec(v, (1, c, s, s), &Device::Cpu)
}

#[test]
fn estimator_adam_steps_reduce_l1() -> Result<()> {
    // Fixed weights, input and target; AdamW with weight decay 0 is Adam, at the paper's
    // learning rate 1e-4. 32² batch 1 keeps this fast.
    let (e, vars) = estimator(EstimatorConfig::default())?;
    reseed(&vars, 100)?;
    let x = pseudo_random((1, 32, 32, 32), 5)?;
    let target = smooth_target()?;
    let mut opt = AdamW::new(
        vars.all_vars(),
        ParamsAdamW {
            lr: 1e-4,
            weight_decay: 0.0,
            ..Default::default()
        },
    )?;
    let loss_of =
        |e: &Estimator| -> Result<Tensor> { (e.forward(&x)? - &target)?.abs()?.mean_all() };
    let mut losses = Vec::new();
    for _ in 0..8 {
        let loss = loss_of(&e)?;
        losses.push(loss.to_scalar::<f32>()?);
        opt.backward_step(&loss)?;
    }
    losses.push(loss_of(&e)?.to_scalar::<f32>()?);
    // Measured with these seeds: 0.477 → 0.369, falling at every step. The bound leaves room
    // for rounding differences between machines yet fails if any layer stops learning.
    assert!(
        losses.windows(2).all(|w| w[1] < w[0]),
        "L1 must fall at every step: {losses:?}"
    );
    let (initial, last) = (losses[0], losses[losses.len() - 1]);
    assert!(
        last < 0.85 * initial,
        "L1 went from {initial} to {last}: {losses:?}"
    );
    Ok(())
}

#[test]
fn estimator_gradient_reaches_every_parameter() -> Result<()> {
    // No layer is detached from the loss (a wrong or missing backward in the graph would leave
    // a zero or absent gradient).
    let (e, vars) = estimator(EstimatorConfig::default())?;
    let loss = e
        .forward(&pseudo_random((1, 32, 32, 32), 7)?)?
        .sqr()?
        .mean_all()?;
    let grads = loss.backward()?;
    let data = vars.data().lock().expect("varmap lock");
    for (name, var) in data.iter() {
        let g = grads
            .get(var.as_tensor())
            .unwrap_or_else(|| panic!("no gradient for {name}"));
        assert!(max_abs(g)? > 0.0, "zero gradient for {name}");
    }
    Ok(())
}

#[test]
fn estimator_rejects_sizes_that_are_not_multiples_of_32() -> Result<()> {
    let (e, _vars) = estimator(EstimatorConfig::default())?;
    let err = e
        .forward(&Tensor::zeros((1, 32, 48, 64), DType::F32, &Device::Cpu)?)
        .expect_err("48");
    assert!(err.to_string().contains("multiples of 32"), "{err}");
    let err = e
        .forward(&Tensor::zeros((1, 16, 32, 32), DType::F32, &Device::Cpu)?)
        .expect_err("16 ch");
    assert!(
        err.to_string().contains("expected 32 feature channels"),
        "{err}"
    );
    Ok(())
}

#[test]
fn estimator_config_validation_names_the_problem() {
    let bad = EstimatorConfig {
        decoder_channels: vec![64, 32],
        ..Default::default()
    };
    let err = bad
        .validate()
        .expect_err("5 encoder levels, 2 decoder levels")
        .to_string();
    assert!(err.contains("need 4 decoder levels"), "{err}");
    assert!(estimator(bad).is_err(), "Estimator::new validates");
    let bad = EstimatorConfig {
        leaky_slope: -0.2,
        ..Default::default()
    };
    assert!(
        bad.validate()
            .expect_err("negative slope")
            .to_string()
            .contains("leaky_slope")
    );
    assert!(EstimatorConfig::default().validate().is_ok());
}

#[test]
fn estimator_small_config_follows_the_same_rules() -> Result<()> {
    // A 3-level, narrow variant (what a CPU user might train): stride 8, n = 5.
    let cfg = EstimatorConfig {
        encoder_channels: vec![8, 16, 16],
        decoder_channels: vec![16, 8],
        out_channels: 5,
        ..Default::default()
    };
    assert_eq!(cfg.total_stride(), 8);
    let (e, vars) = estimator(cfg.clone())?;
    let counted: usize = vars.all_vars().iter().map(|v| v.elem_count()).sum();
    assert_eq!(counted, cfg.num_parameters());
    let x = pseudo_random((1, 32, 16, 24), 8)?;
    let y = e.forward(&x)?;
    assert_eq!(y.dims4()?, (1, 5, 16, 24));
    let diff = max_abs_diff(
        &e.forward(&x.roll(8, 2)?.roll(-16, 3)?)?,
        &y.roll(8, 2)?.roll(-16, 3)?,
    )?;
    assert!(diff < 1e-4 * max_abs(&y)?.max(1.0));
    Ok(())
}

#[test]
fn estimator_variables_mirror_the_documented_names() -> Result<()> {
    let (_e, vars) = estimator(EstimatorConfig::default())?;
    let data = vars.data().lock().expect("varmap lock");
    let shape = |name: &str| -> Vec<usize> {
        data.get(name)
            .map(|v| v.dims().to_vec())
            .unwrap_or_default()
    };
    assert_eq!(shape("enc0.down.weight"), [32, 32, 4, 4]);
    assert_eq!(shape("enc4.conv.weight"), [256, 256, 3, 3]);
    assert_eq!(shape("dec0.conv1.weight"), [256, 512, 3, 3]);
    assert_eq!(shape("dec3.conv2.bias"), [32]);
    assert_eq!(shape("head.weight"), [8, 32, 3, 3]);
    Ok(())
}

#[test]
fn the_reference_fits_the_limits_and_an_oversized_config_is_refused() {
    use photomat_estimator::unet::{MAX_CHANNELS, MAX_PARAMETERS};
    let reference = EstimatorConfig::default();
    reference.validate().unwrap();
    assert!(reference.num_parameters() < MAX_PARAMETERS / 4);
    let wide = EstimatorConfig {
        encoder_channels: vec![1_000_000; 5],
        ..EstimatorConfig::default()
    };
    let err = wide.validate().unwrap_err().to_string();
    assert!(err.contains("1000000") && err.contains("limit"), "{err}");
    // Every width at the channel limit: each 3×3 conv alone has 151 M weights.
    let heavy = EstimatorConfig {
        encoder_channels: vec![MAX_CHANNELS; 5],
        decoder_channels: vec![MAX_CHANNELS; 4],
        ..EstimatorConfig::default()
    };
    let err = heavy.validate().unwrap_err().to_string();
    assert!(err.contains("parameters exceed the limit"), "{err}");
}
