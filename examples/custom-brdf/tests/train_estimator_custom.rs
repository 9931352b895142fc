//! A user plugin trains like a built-in one: `train-estimator --brdf blinn_phong_gloss` through
//! `photomat_cli::run_with_output` in a crate that links the plugin (the same code path as
//! the `photomat-custom` binary) gives an estimator whose head has the plugin's 10 channels
//! and which loads back by name, adapters included (`height(blinn_phong_gloss)`, 8 channels).

use photomat_brdfs as _;
use photomat_custom_brdf_example as _;

use candle_core::Device;
use photomat_estimator::EstimatorModel;
use photomat_generator::{GanModel, GeneratorConfig};

#[test]
fn train_estimator_works_for_a_user_plugin() -> Result<(), Box<dyn std::error::Error>> {
    let dir = tempfile::tempdir()?;
    let gan_dir = dir.path().join("gan");
    let cfg = GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        relight_hidden: 8,
        ..Default::default()
    };
    GanModel::new(&cfg, 1, &Device::Cpu)?.save(&gan_dir, serde_json::Value::Null)?;
    for (spec, channels) in [("blinn_phong_gloss", 10), ("height(blinn_phong_gloss)", 8)] {
        let run = dir.path().join(spec.replace(['(', ')'], "_"));
        let mut out = Vec::new();
        photomat_cli::run_with_output(
            [
                "photomat",
                "train-estimator",
                "--gan",
                gan_dir.to_str().unwrap(),
                "--brdf",
                spec,
                "--out",
                run.to_str().unwrap(),
                "--steps",
                "1",
                "--finetune-steps",
                "1",
                "--batch",
                "1",
                "--width",
                "0.125",
            ],
            &mut out,
        )?;
        let model = EstimatorModel::load(&run, &Device::Cpu)?;
        assert_eq!(model.estimator().config().out_channels, channels, "{spec}");
        assert!(model.brdf().name().starts_with(spec.trim_end_matches(')')));
        let features = GanModel::load(&run, &Device::Cpu)?.features_for_seeds(&[2], 1.0)?;
        let maps = model.estimate(&features)?;
        assert!(maps.contains("glossiness"), "{spec}: {:?}", maps.names());
    }
    Ok(())
}
