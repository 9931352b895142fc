//! The relief prior's trainer on a small synthetic library: a tiny prior's validation loss
//! falls in a few steps, and a run stopped and resumed ends with the weights an uninterrupted
//! run ends with.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use candle_core::Device;
use photomat_brdfs as _;
use photomat_library::testing::tiny_library;
use photomat_prior::model_files::PRIOR_WEIGHTS_FILE;
use photomat_prior::train::{PriorSettings, PriorTraining};

fn settings(library: &Path) -> PriorSettings {
    PriorSettings {
        library: Some(library.to_path_buf()),
        brdf: Some("height(ggx)".into()),
        size: Some(32),
        batch: Some(2),
        width: Some(0.25),
        lr: Some(2e-3),
        seed: Some(3),
        checkpoint_every: Some(1),
        snapshot_every: Some(0),
        validation_count: Some(2),
        ..PriorSettings::default()
    }
}

fn train(run: &Path, settings: &PriorSettings, resume: bool, total: u64) -> PriorTraining {
    let mut training = PriorTraining::open(run, settings, resume, &Device::Cpu).unwrap();
    let stop = AtomicBool::new(false);
    training.run(total, &stop, &mut |_| {}).unwrap();
    training
}

#[test]
fn a_tiny_prior_lowers_its_validation_loss_in_a_few_steps() {
    let dir = tempfile::tempdir().unwrap();
    let library = tiny_library(dir.path(), 8, 64);
    let run = dir.path().join("run");
    let training = PriorTraining::open(&run, &settings(&library), false, &Device::Cpu).unwrap();
    let before = training.trainer().validate(2).unwrap();
    drop(training);
    let training = train(&run, &settings(&library), true, 40);
    let after = training.trainer().validate(2).unwrap();
    assert!(
        after.terms.total < 0.8 * before.terms.total,
        "validation loss {} → {}",
        before.terms.total,
        after.terms.total
    );
}

#[test]
fn a_resumed_prior_run_ends_with_the_uninterrupted_runs_weights() {
    let dir = tempfile::tempdir().unwrap();
    let library = tiny_library(dir.path(), 4, 64);
    let (whole, parts) = (dir.path().join("whole"), dir.path().join("parts"));
    train(&whole, &settings(&library), false, 4);
    train(&parts, &settings(&library), false, 2);
    // Resumed with the run's settings only: train.json supplies the rest.
    train(&parts, &PriorSettings::default(), true, 4);
    let weights = |run: &Path| std::fs::read(run.join(PRIOR_WEIGHTS_FILE)).unwrap();
    assert_eq!(weights(&whole), weights(&parts));
    let log = |run: &Path| std::fs::read_to_string(run.join("log.csv")).unwrap();
    let losses = |text: String| -> Vec<String> {
        text.lines()
            .map(|l| l.split(',').take(5).collect::<Vec<_>>().join(","))
            .collect()
    };
    assert_eq!(losses(log(&whole)), losses(log(&parts)));
    // A resume that contradicts the run names the field.
    let other = PriorSettings {
        batch: Some(3),
        ..PriorSettings::default()
    };
    let err = PriorTraining::open(&parts, &other, true, &Device::Cpu)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("--batch 3 contradicts batch = 2"), "{err}");
}
