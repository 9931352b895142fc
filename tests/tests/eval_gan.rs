//! `photomat eval-gan` end to end: an untrained tiny GAN against a tiny simulated data set
//! gives finite, positive per-level SWD values (table and JSON agree, seeded runs repeat) far
//! above the metric's real-against-real noise floor, and a missing model folder, a missing
//! data set or a model too large for the data set's photos are errors that name the paths
//! and sizes.

use photomat_tests as _;

use photomat_tests::cli_fixtures::{
    path_str, photomat, photomat_error, simulated_dataset, tiny_gan,
};
use photomat_tests::mean_abs_difference;
use serde_json::Value;

fn eval_json(gan: &str, data: &str, seed: &str) -> Value {
    let printed = photomat(&[
        "eval-gan", "--gan", gan, "--data", data, "--count", "8", "--seed", seed, "--json",
    ])
    .unwrap();
    serde_json::from_str(&printed).unwrap_or_else(|e| panic!("{e}: {printed}"))
}

fn levels(report: &Value) -> Vec<(u64, f64)> {
    report["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| (l["side"].as_u64().unwrap(), l["swd_x1e3"].as_f64().unwrap()))
        .collect()
}

#[test]
fn eval_gan_reports_finite_levels_for_a_tiny_model() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulated_dataset(dir.path(), 64);
    let gan = tiny_gan(dir.path(), "gan", 32, 1);
    let (gan, data) = (path_str(&gan), path_str(&data));

    let report = eval_json(gan, data, "4");
    let per_level = levels(&report);
    let sides: Vec<u64> = per_level.iter().map(|&(s, _)| s).collect();
    assert_eq!(sides, [32, 16]);
    for &(side, swd) in &per_level {
        assert!(swd.is_finite() && swd > 0.0, "level {side}: {swd}");
    }
    let mean = report["mean_x1e3"].as_f64().unwrap();
    assert!((mean - (per_level[0].1 + per_level[1].1) / 2.0).abs() < 1e-9);
    assert_eq!(report["count"], 8);
    assert_eq!(report["resolution"], 32);

    // Seeded: the same seed repeats exactly, another seed draws other samples and crops.
    assert_eq!(levels(&eval_json(gan, data, "4")), per_level);
    assert_ne!(levels(&eval_json(gan, data, "5")), per_level);

    // The table prints the same values.
    let table = photomat(&[
        "eval-gan", "--gan", gan, "--data", data, "--count", "8", "--seed", "4",
    ])
    .unwrap();
    for (side, swd) in &per_level {
        let row = format!("{side}×{side}");
        let line = table
            .lines()
            .find(|l| l.trim_start().starts_with(&row))
            .unwrap_or_else(|| panic!("no {row} row in\n{table}"));
        assert!(line.contains(&format!("{swd:.3}")), "{line} vs {swd}");
    }
    assert!(table.contains(&format!("{mean:.3}")), "{table}");
}

#[test]
fn eval_gan_errors_name_the_folders_and_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulated_dataset(dir.path(), 64);
    let gan = tiny_gan(dir.path(), "gan", 32, 1);
    let (gan_s, data_s) = (path_str(&gan), path_str(&data));

    let empty = dir.path().join("empty-run");
    std::fs::create_dir_all(&empty).unwrap();
    let err = photomat_error(&["eval-gan", "--gan", path_str(&empty), "--data", data_s]);
    assert!(
        err.contains("empty-run") && err.contains("gan.json"),
        "{err}"
    );

    let weightless = tiny_gan(dir.path(), "weightless", 32, 1);
    std::fs::remove_file(weightless.join("gan.safetensors")).unwrap();
    let err = photomat_error(&["eval-gan", "--gan", path_str(&weightless), "--data", data_s]);
    assert!(err.contains("gan.safetensors"), "{err}");

    let missing = dir.path().join("no-such-data");
    let err = photomat_error(&["eval-gan", "--gan", gan_s, "--data", path_str(&missing)]);
    assert!(err.contains("no-such-data"), "{err}");

    // 64² photos are too small for a 64² model (crops come from photos resized to 2×64).
    let big = tiny_gan(dir.path(), "big", 64, 1);
    let err = photomat_error(&["eval-gan", "--gan", path_str(&big), "--data", data_s]);
    assert!(
        err.contains("64×64 model") && err.contains("photos are 64×64") && err.contains("128"),
        "{err}"
    );

    let err = photomat_error(&["eval-gan", "--gan", gan_s, "--data", data_s, "--count", "0"]);
    assert!(err.contains("--count"), "{err}");
}

#[test]
fn eval_gan_untrained_model_is_far_from_the_data() {
    // Two independent draws of real crops set the metric's noise floor; the smooth colour
    // blobs of an untrained G/M must lie far above it. Measured: floor 92, model 277.
    use candle_core::Device;
    use photomat_data::source::DatasetSource;
    use photomat_generator::GanModel;
    use photomat_generator::swd::model::real_crops;
    use photomat_generator::swd::{FakeWindows, SwdConfig, model_swd, sliced_wasserstein};

    let dir = tempfile::tempdir().unwrap();
    let data = DatasetSource::open(&simulated_dataset(dir.path(), 64), 32).unwrap();
    let config = SwdConfig::default();
    let count = 32;
    let reals_a = real_crops(&data, count, 1, &Device::Cpu, &mut |_| {}).unwrap();
    let reals_b = real_crops(&data, count, 2, &Device::Cpu, &mut |_| {}).unwrap();
    let floor = sliced_wasserstein(&reals_a, &reals_b, &config, 1)
        .unwrap()
        .mean;
    let model = GanModel::new(
        &photomat_tests::cli_fixtures::tiny_gan_config(32),
        5,
        &Device::Cpu,
    )
    .unwrap();
    let fakes = model_swd(
        &model,
        &data,
        count,
        1,
        FakeWindows::Native,
        &config,
        &mut |_, _| {},
    )
    .unwrap()
    .mean;
    eprintln!("SWD×1e3 real/real {floor:.1}, untrained model/real {fakes:.1}");
    assert!(fakes > 2.0 * floor, "model {fakes} vs floor {floor}");
}

#[test]
fn size_generalisation_fakes_are_windows_of_larger_samples() {
    use candle_core::Device;
    use photomat_data::source::DatasetSource;
    use photomat_generator::swd::FakeWindows;
    use photomat_generator::swd::model::relit_samples;
    use photomat_generator::{GanModel, GeneratorConfig, SpatialConfig};

    let dir = tempfile::tempdir().unwrap();
    let config = GeneratorConfig {
        tileable: true,
        spatial: Some(SpatialConfig {
            texel_size: Some(1.0 / 32.0),
            ..SpatialConfig::default()
        }),
        ..photomat_tests::cli_fixtures::tiny_gan_config(32)
    };
    let data = DatasetSource::for_model(&simulated_dataset(dir.path(), 64), &config).unwrap();
    let model = GanModel::new(&config, 5, &Device::Cpu).unwrap();
    let fakes = |side: Option<usize>| {
        let windows = side.map_or(FakeWindows::Native, |side| FakeWindows::OfLargerSamples {
            side,
        });
        relit_samples(&model, &data, 3, 7, windows, &mut |_| {})
    };
    let native = fakes(None).unwrap();
    assert_eq!(native.dims(), [3, 3, 32, 32]);
    // Side R is the default; a larger side gives windows of the same shape from other,
    // larger materials (the same seeds, so equal only if the size did not matter at all).
    let same = (fakes(Some(32)).unwrap() - &native).unwrap().abs().unwrap();
    assert_eq!(same.max_all().unwrap().to_scalar::<f32>().unwrap(), 0.0);
    let larger = fakes(Some(96)).unwrap();
    assert_eq!(larger.dims(), [3, 3, 32, 32]);
    let moved = (larger - &native)
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap();
    assert!(moved.to_scalar::<f32>().unwrap() > 0.0);
    let err = fakes(Some(16)).unwrap_err().to_string();
    assert!(err.contains("smaller than the model's 32×32"), "{err}");
}

/// A fixed-size model stretched to native patches: where the photos' texel is the model's
/// (64² photos, side 2, and a 32² unit-square model: both 1/32), the stretch is the identity
/// and the fakes are the model's own relit materials; on 128² photos (texel 1/64) each
/// material spans 64 texels and the fakes are its centre 32² windows, smoother than its own.
#[test]
fn stretched_fakes_are_the_fixed_model_at_the_photos_texel_size() {
    use candle_core::Device;
    use photomat_data::patch::PatchOptions;
    use photomat_data::source::DatasetSource;
    use photomat_generator::GanModel;
    use photomat_generator::swd::FakeWindows;
    use photomat_generator::swd::model::relit_samples;

    let dir = tempfile::tempdir().unwrap();
    let model = GanModel::new(
        &photomat_tests::cli_fixtures::tiny_gan_config(32),
        5,
        &Device::Cpu,
    )
    .unwrap();
    let patches = |photos| {
        let options = PatchOptions {
            size: 32,
            highlight_prob: 0.5,
        };
        let path = simulated_dataset(&dir.path().join(format!("p{photos}")), photos);
        DatasetSource::open_patches(&path, options).unwrap()
    };
    let at_model_scale = patches(64);
    let fakes = |data: &DatasetSource, windows| {
        relit_samples(&model, data, 3, 7, windows, &mut |_| {}).unwrap()
    };
    let native = fakes(&at_model_scale, FakeWindows::Native);
    let stretched = fakes(&at_model_scale, FakeWindows::Stretched);
    assert_eq!(stretched.dims(), [3, 3, 32, 32]);
    let diff = (&stretched - &native)
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap();
    assert!(diff.to_scalar::<f32>().unwrap() < 1e-5);

    // Stretched ×2, F varies half as fast per texel: the relit windows are smoother than
    // the model's own materials under the same lights.
    let finer = patches(128);
    let twice = fakes(&finer, FakeWindows::Stretched);
    assert_eq!(twice.dims(), [3, 3, 32, 32]);
    let step = |t: &candle_core::Tensor| {
        let w = t.dim(3).unwrap();
        mean_abs_difference(
            &t.narrow(3, 1, w - 1).unwrap(),
            &t.narrow(3, 0, w - 1).unwrap(),
        )
    };
    let (stretched_step, native_step) = (step(&twice), step(&fakes(&finer, FakeWindows::Native)));
    assert!(
        stretched_step < 0.75 * native_step,
        "neighbour step {stretched_step} stretched vs {native_step} native"
    );
}
