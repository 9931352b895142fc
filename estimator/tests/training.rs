//! Estimator training on a tiny frozen G/M (PhotoMat §3 "Material map estimator";
//! `docs/neural-models.md`, "Training E"): the loss goes down, the roll fine-tune keeps E tileable,
//! a resumed run is bit-identical to an uninterrupted one, and mismatched GAN/estimator shapes are
//! refused with both numbers.

use candle_core::{Device, Tensor};
use photomat_brdfs as _; // link the built-in plugins into the registry
use photomat_core::Highlight;
use photomat_estimator::train::{EstimatorTrainer, Stage, TrainConfig};
use photomat_estimator::{EstimatorConfig, EstimatorModel};
use photomat_generator::{GanModel, GeneratorConfig};

fn tiny_gan(tileable: bool) -> candle_core::Result<GanModel> {
    let cfg = GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        relight_hidden: 8,
        tileable,
        ..Default::default()
    };
    GanModel::new(&cfg, 11, &Device::Cpu)
}

fn tiny_estimator(spec: &str, levels: usize, seed: u64) -> anyhow::Result<EstimatorModel> {
    let brdf = photomat_core::lookup(spec)?;
    let cfg = EstimatorConfig {
        in_channels: 8,
        encoder_channels: vec![8; levels],
        decoder_channels: vec![8; levels - 1],
        out_channels: brdf.channels(),
        ..Default::default()
    };
    Ok(EstimatorModel::new_seeded(brdf, cfg, seed, &Device::Cpu)?)
}

fn config(steps: u64, finetune_steps: u64, lr: f64) -> TrainConfig {
    TrainConfig {
        steps,
        finetune_steps,
        batch: 2,
        lr,
        finetune_lr: lr / 2.0,
        seed: 5,
        ..Default::default()
    }
}

fn trainer(gan: &GanModel, cfg: TrainConfig, spec: &str) -> anyhow::Result<EstimatorTrainer> {
    let model = tiny_estimator(spec, 5, 3)?;
    Ok(EstimatorTrainer::new(gan.clone(), model, cfg)?)
}

/// Every variable's values, sorted by name.
fn snapshot(vars: &candle_nn::VarMap) -> Vec<(String, Vec<f32>)> {
    let data = vars.data().lock().expect("lock");
    let mut out: Vec<_> = data
        .iter()
        .map(|(n, v)| {
            let values = v
                .as_tensor()
                .flatten_all()
                .and_then(|t| t.to_dtype(candle_core::DType::F32))
                .and_then(|t| t.to_vec1::<f32>())
                .expect("readable");
            (n.clone(), values)
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn estimator_steps_reduce_the_loss() -> anyhow::Result<()> {
    let gan = tiny_gan(false)?;
    let mut t = trainer(&gan, config(30, 0, 3e-3), "ggx")?;
    let mut totals = Vec::new();
    while !t.is_done() {
        let r = t.step()?;
        assert!(!r.skipped && r.total.is_finite(), "{r:?}");
        assert_eq!(r.stage, Stage::Aligned);
        assert!((r.total - (0.1 * r.l1 + r.gram)).abs() < 1e-5 * r.total.max(1.0));
        totals.push(r.total);
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (first, last) = (mean(&totals[..5]), mean(&totals[totals.len() - 5..]));
    assert!(
        last < 0.8 * first,
        "mean loss of the first 5 steps {first}, of the last 5 {last}: {totals:?}"
    );
    Ok(())
}

#[test]
fn finetune_step_keeps_the_maps_periodic() -> anyhow::Result<()> {
    let gan = tiny_gan(true)?;
    let mut t = trainer(&gan, config(1, 2, 1e-3), "height(ggx)")?;
    while !t.is_done() {
        t.step()?;
    }
    assert_eq!(t.steps_done(), 3);
    // A tileable F tiled 2×2 is periodic with period 32; E is circular, so its maps of the
    // tiling are the tiling of its maps: rolling by 32 leaves every map unchanged.
    let f = gan.features_for_seeds(&[1, 2], 1.0)?;
    let tiled = Tensor::cat(&[&f, &f], 2)?;
    let tiled = Tensor::cat(&[&tiled, &tiled], 3)?;
    let maps = t.model().estimate(&tiled)?;
    let direct = t.model().estimate(&f)?;
    for (name, map) in maps.iter() {
        let rolled = map.roll(32, 2)?.roll(32, 3)?;
        let d = photomat_kernels::testing::max_abs_diff(map, &rolled)?;
        let top_left = map.narrow(2, 0, 32)?.narrow(3, 0, 32)?;
        let e = photomat_kernels::testing::max_abs_diff(&top_left, direct.get(name)?)?;
        assert!(d < 1e-5 && e < 1e-5, "map {name}: roll {d}, tile {e}");
    }
    Ok(())
}

#[test]
fn resumed_training_is_bit_identical() -> anyhow::Result<()> {
    let gan = tiny_gan(false)?;
    let dir = tempfile::tempdir()?;
    let gan_dir = dir.path().join("gan");
    gan.save(&gan_dir, serde_json::Value::Null)?;
    // Four steps across the stage boundary, interrupted exactly at the boundary.
    let cfg = config(2, 2, 1e-3);
    let mut straight = trainer(&gan, cfg.clone(), "ggx")?;
    let mut reports = Vec::new();
    while !straight.is_done() {
        reports.push(straight.step()?);
    }

    let run = dir.path().join("run");
    let mut first = trainer(&gan, cfg.clone(), "ggx")?;
    first.step()?;
    first.step()?;
    first.save_checkpoint(&run, &gan_dir)?;
    drop(first);
    // A fresh process would start from another initialisation: the checkpoint overrides it.
    let mut resumed = EstimatorTrainer::new(gan.clone(), tiny_estimator("ggx", 5, 99)?, cfg)?;
    resumed.load_checkpoint(&run)?;
    assert_eq!(resumed.steps_done(), 2);
    assert_eq!(resumed.stage(), Stage::Finetune);
    let mut resumed_reports = Vec::new();
    while !resumed.is_done() {
        resumed_reports.push(resumed.step()?);
    }
    assert_eq!(resumed_reports, reports[2..]);
    assert_eq!(
        snapshot(resumed.model().vars()),
        snapshot(straight.model().vars())
    );
    assert_eq!(
        snapshot(resumed.adam().state()),
        snapshot(straight.adam().state())
    );
    // The run folder is a loadable estimator model.
    let loaded = EstimatorModel::load(&run, &Device::Cpu)?;
    assert_eq!(loaded.brdf().name(), "ggx");
    Ok(())
}

#[test]
fn checkpoint_of_another_architecture_is_refused() -> anyhow::Result<()> {
    let gan = tiny_gan(false)?;
    let dir = tempfile::tempdir()?;
    let t = trainer(&gan, config(1, 0, 1e-3), "ggx")?;
    t.save_checkpoint(dir.path(), dir.path())?;
    let mut other = EstimatorTrainer::new(gan, tiny_estimator("ggx", 4, 3)?, config(1, 0, 1e-3))?;
    let err = other.load_checkpoint(dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("train_state.safetensors") && err.contains("dec3"),
        "{err}"
    );
    Ok(())
}

#[test]
fn gan_resolution_must_be_a_multiple_of_the_estimator_stride() -> anyhow::Result<()> {
    let gan = tiny_gan(false)?;
    let model = tiny_estimator("ggx", 6, 3)?; // stride 64 > 32
    let err = EstimatorTrainer::new(gan, model, config(1, 0, 1e-3))
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("32") && err.contains("64"), "{err}");
    Ok(())
}

#[test]
fn preview_gives_both_renders_in_display_range() -> anyhow::Result<()> {
    let gan = tiny_gan(false)?;
    let t = trainer(&gan, config(1, 0, 1e-3), "coated")?;
    let p = t.preview(7, Highlight::CENTER)?;
    for img in [&p.neural, &p.analytic] {
        assert_eq!(img.dims(), [1, 3, 32, 32]);
        let v = img.flatten_all()?.to_vec1::<f32>()?;
        assert!(v.iter().all(|x| (0.0..=1.0).contains(x)));
    }
    assert!(p.maps.contains("specular2"));
    Ok(())
}

/// A feature extractor whose features are NaN: every loss it enters is NaN.
struct PoisonedFeatures;

impl photomat_estimator::loss::FeatureExtractor for PoisonedFeatures {
    fn describe(&self) -> String {
        "poisoned".into()
    }

    fn features(&self, images: &Tensor) -> candle_core::Result<Vec<Tensor>> {
        Ok(vec![(images * f64::NAN)?])
    }
}

#[test]
fn non_finite_steps_are_skipped_then_stop_naming_the_loss() -> anyhow::Result<()> {
    let gan = tiny_gan(false)?;
    let cfg = TrainConfig {
        max_nan_steps: 2,
        ..config(5, 0, 1e-3)
    };
    let mut t = EstimatorTrainer::with_extractor(
        gan,
        tiny_estimator("ggx", 5, 3)?,
        cfg,
        Box::new(PoisonedFeatures),
    )?;
    let before = snapshot(t.model().vars());
    let r = t.step()?;
    assert!(r.skipped && r.gram.is_nan() && r.l1.is_finite(), "{r:?}");
    assert_eq!(
        snapshot(t.model().vars()),
        before,
        "a skipped step changed E"
    );
    assert_eq!(t.adam().step_count(), 0);
    let err = t.step().unwrap_err().to_string();
    assert!(
        err.contains("step 2") && err.contains("Gram = NaN"),
        "{err}"
    );
    Ok(())
}
