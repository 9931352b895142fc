//! The GAN trainer with a spatial G on native-scale patches (tiny configuration, tiny
//! simulated data): losses stay finite, fakes and reals have the patch size, a resumed run is
//! bit-identical to an uninterrupted one, and the saved model samples at other sizes.
//!
//! No test sets an environment variable: the R1 and path-length double backwards keep the
//! graph of their inner pass themselves.

mod training_data;
use training_data::{simulated_dataset, snapshot};
mod tiny_spatial;
use tiny_spatial::{tiny_spatial_config, with_spatial};

use std::path::Path;

use anyhow::Result;
use candle_core::Device;
use photomat_data::source::{DatasetSource, SourceMode};
use photomat_generator::GanModel;
use photomat_generator::train::{TrainConfig, Trainer, TrainingData};

fn tiny_training_config(data: &Path) -> TrainConfig {
    // Periodic waves: their straight-through rounding and their path-length double backward
    // are part of every step.
    let generator = with_spatial(tiny_spatial_config(), |s| s.waves = 2);
    let mut c = TrainConfig::new(generator, data.to_path_buf(), 4, 13);
    c.r1_interval = 2;
    c.lr = 0.01;
    c
}

#[test]
fn spatial_training_on_patches_is_finite_and_resumes_bit_identically() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 6, 5)?;
    let mut config = tiny_training_config(&data_dir);
    // Path-length regularisation on every other step: its running mean and the spatial
    // generation of its fakes are part of the state that must repeat.
    config.pl_weight = 2.0;
    config.g_reg_interval = 2;
    let patches = config
        .patches
        .clone()
        .expect("a spatial config trains on patches");
    assert_eq!(patches.margin_cells, 1);
    let data = DatasetSource::for_training(&config)?;
    assert!(matches!(data.mode(), SourceMode::Patches(p) if p.size == 32));
    // 32² patches of 64² photos cover a square of side 2·32/64 = 1.
    assert_eq!(data.sample_side(), 1.0);
    let reals = data.reals(2, 7, &Device::Cpu)?;
    assert_eq!(reals.images.dims4()?, (2, 3, 32, 32));

    let mut whole = Trainer::new(config.clone(), &Device::Cpu)?;
    for _ in 0..5 {
        let s = whole.step(&data)?;
        assert!(s.skipped.is_empty(), "{s:?}");
        for v in [s.loss_g, s.loss_d, s.real_logit, s.fake_logit] {
            assert!(v.is_finite(), "{s:?}");
        }
        assert_eq!(s.r1.is_some(), s.step % 2 == 0, "{s:?}");
        assert!(
            s.path_length.is_none_or(|p| p.is_finite() && p > 0.0),
            "{s:?}"
        );
    }

    let run = dir.path().join("run");
    let mut first = Trainer::new(config.clone(), &Device::Cpu)?;
    for _ in 0..3 {
        first.step(&data)?;
    }
    first.save_state(&run)?;
    drop(first);
    let mut resumed = Trainer::new(config.clone(), &Device::Cpu)?;
    resumed.load_state(&run)?;
    assert_eq!(resumed.steps_done(), 3);
    for _ in 0..2 {
        resumed.step(&data)?;
    }
    let (a, b) = (snapshot(whole.state_vars()), snapshot(resumed.state_vars()));
    assert_eq!(a.len(), b.len());
    assert!(
        a.iter()
            .any(|(n, _)| n.starts_with("g.synthesis.b4.input."))
    );
    for ((na, va), (nb, vb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        if na != "trainer.counters" {
            assert!(va == vb, "`{na}` differs after resuming");
        }
    }

    // The run folder's train.json records the patch settings; the inference model samples
    // materials larger than its patches.
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("train.json"))?)?;
    assert_eq!(saved["patches"]["margin_cells"], 1);
    whole.save_model(&dir.path().join("model"), serde_json::Value::Null)?;
    let model = GanModel::load(&dir.path().join("model"), &Device::Cpu)?;
    let f = model.features_for_seeds_at(&[1], 1.0, 96)?;
    assert_eq!(f.dims4()?, (1, 8, 96, 96));
    assert!(f.abs()?.max_all()?.to_scalar::<f32>()?.is_finite());
    Ok(())
}

#[test]
fn patch_settings_need_a_spatial_generator_and_back() -> Result<()> {
    let mut config = tiny_training_config(Path::new("data"));
    config.validate()?;
    let patches = config.patches.take();
    assert!(
        config
            .validate()
            .unwrap_err()
            .to_string()
            .contains("patches")
    );
    config.patches = patches;
    config.generator.spatial = None;
    assert!(
        config
            .validate()
            .unwrap_err()
            .to_string()
            .contains("spatial")
    );
    Ok(())
}
