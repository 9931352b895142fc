//! `photomat train-estimator` end to end on a tiny GAN: the run folder is a model
//! folder that `EstimatorModel::load` and `GanModel::load` both read, with a log and panels;
//! `--resume` continues where the run stopped; contradicting flags and unknown models are
//! reported by name.

use photomat_tests::cli_fixtures::{photomat, photomat_error, tiny_gan_config};

use std::path::Path;

use candle_core::Device;
use photomat_core::image_io::png_header;
use photomat_estimator::EstimatorModel;
use photomat_generator::GanModel;

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

fn log_steps(run: &Path) -> Vec<u64> {
    std::fs::read_to_string(run.join("log.csv"))
        .expect("log.csv")
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect()
}

#[test]
fn train_estimator_writes_a_loadable_model_folder_and_resumes() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let (gan_dir, run) = (dir.path().join("gan"), dir.path().join("run"));
    let gan = GanModel::new(&tiny_gan_config(32), 4, &Device::Cpu)?;
    gan.save(&gan_dir, serde_json::json!({"test": true}))?;
    let common = [
        "--batch",
        "2",
        "--width",
        "0.125",
        "--seed",
        "3",
        "--panel-every",
        "2",
        "--checkpoint-every",
        "2",
    ];
    let mut args = vec![
        "train-estimator",
        "--gan",
        s(&gan_dir),
        "--brdf",
        "height(ggx)",
        "--out",
        s(&run),
        "--steps",
        "2",
        "--finetune-steps",
        "1",
    ];
    args.extend(common);
    let out = photomat(&args)?;
    assert!(out.contains("trained 3 steps"), "{out}");
    assert!(out.contains("photomat sample --model"), "{out}");

    // A model folder: E with its BRDF by name, and the GAN it decodes.
    let model = EstimatorModel::load(&run, &Device::Cpu)?;
    assert_eq!(model.brdf().name(), "height(ggx, scale=0.02)");
    assert_eq!(
        model.estimator().config().encoder_channels,
        [4, 8, 16, 32, 32]
    );
    let copied = GanModel::load(&run, &Device::Cpu)?;
    let (a, b) = (
        gan.features_for_seeds(&[9], 1.0)?,
        copied.features_for_seeds(&[9], 1.0)?,
    );
    let diff = (a - &b)?.abs()?.max_all()?.to_scalar::<f32>()?;
    assert_eq!(diff, 0.0);
    let maps = model.estimate(&b)?;
    assert_eq!(maps.get("height")?.dims(), [1, 1, 32, 32]);

    assert_eq!(log_steps(&run), [1, 2, 3]);
    for step in ["step-000002.png", "step-000003.png"] {
        let (_, h, w) = png_header(&run.join("panels").join(step))?;
        // Two rows of 32² tiles: neural | analytic | 4 maps + derived normal.
        assert_eq!((h, w), (2 * 32 + 4, 7 * 32 + 6 * 4), "{step}");
    }

    // Starting again in the same folder is refused; resuming continues at step 3.
    let err = photomat_error(&args);
    assert!(err.contains("--resume"), "{err}");
    let out = photomat(&[
        "train-estimator",
        "--out",
        s(&run),
        "--resume",
        "--finetune-steps",
        "2",
    ])?;
    assert!(out.contains("trained 1 steps (4 in total)"), "{out}");
    assert_eq!(log_steps(&run), [1, 2, 3, 4]);

    // A contradicting flag names the field.
    let err = photomat_error(&[
        "train-estimator",
        "--out",
        s(&run),
        "--resume",
        "--seed",
        "4",
    ]);
    assert!(err.contains("seed") && err.contains("train.json"), "{err}");
    let err = photomat_error(&[
        "train-estimator",
        "--out",
        s(&run),
        "--resume",
        "--brdf",
        "lambert",
    ]);
    assert!(
        err.contains("lambert") && err.contains("height(ggx"),
        "{err}"
    );
    Ok(())
}

#[test]
fn train_estimator_unknown_brdf_lists_the_known_models() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let gan_dir = dir.path().join("gan");
    GanModel::new(&tiny_gan_config(32), 4, &Device::Cpu)?
        .save(&gan_dir, serde_json::json!({"test": true}))?;
    let err = photomat_error(&[
        "train-estimator",
        "--gan",
        s(&gan_dir),
        "--brdf",
        "no_such_model",
        "--out",
        s(&dir.path().join("run")),
    ]);
    assert!(
        err.contains("no_such_model") && err.contains("ggx") && err.contains("lambert"),
        "{err}"
    );
    let err = photomat_error(&[
        "train-estimator",
        "--gan",
        s(&dir.path().join("missing")),
        "--brdf",
        "ggx",
        "--out",
        s(&dir.path().join("run")),
    ]);
    assert!(err.contains("gan.json"), "{err}");
    Ok(())
}

#[test]
fn estimator_training_driver_stops_after_the_step_the_flag_is_seen() -> anyhow::Result<()> {
    use photomat_estimator::train::{EstimatorSettings, EstimatorTraining};
    use std::sync::atomic::AtomicBool;
    let dir = tempfile::tempdir()?;
    let (gan_dir, run) = (dir.path().join("gan"), dir.path().join("run"));
    GanModel::new(&tiny_gan_config(32), 4, &Device::Cpu)?.save(&gan_dir, serde_json::json!({}))?;
    let settings = EstimatorSettings {
        gan: Some(gan_dir),
        brdf: Some("ggx".into()),
        steps: Some(3),
        finetune_steps: Some(0),
        batch: Some(1),
        width: Some(0.125),
        panel_every: Some(100),
        checkpoint_every: Some(100),
        ..EstimatorSettings::default()
    };
    let mut training = EstimatorTraining::open(&run, &settings, false, &Device::Cpu)?;
    let mut steps = Vec::new();
    let outcome = training.run(&AtomicBool::new(true), &mut |r, _| steps.push(r.step))?;
    assert!(outcome.interrupted);
    assert_eq!((outcome.steps_run, outcome.steps_done), (1, 1));
    assert_eq!(steps, [1]);
    assert_eq!(log_steps(&run), [1]);
    assert!(outcome.panel.ends_with("panels/step-000001.png"));
    // The stop flag is honoured with the checkpoint written: the run resumes to its total
    // (once the first training, which holds the folder's lock, is dropped).
    drop(training);
    let mut resumed =
        EstimatorTraining::open(&run, &EstimatorSettings::default(), true, &Device::Cpu)?;
    let outcome = resumed.run(&AtomicBool::new(false), &mut |_, _| {})?;
    assert!(!outcome.interrupted);
    assert_eq!((outcome.steps_run, outcome.steps_done), (2, 3));
    assert_eq!(log_steps(&run), [1, 2, 3]);
    Ok(())
}
