//! The GAN trainer on a tiny configuration and tiny simulated data (the data crate's
//! simulator + `prepare`): D learns to separate reals from fakes without a non-finite value,
//! runs are deterministic under their seed, a resumed run is bit-identical to an uninterrupted
//! one (path-length regularisation included), resuming another configuration names the
//! field, a state kept without its optimisers resumes the networks exactly with fresh Adam
//! moments (and one with part of them is refused), and the NaN guard skips poisoned updates and stops a diverged run, whose last
//! checkpoint stays the last good state.
//!
//! No test sets an environment variable: the R1 and path-length double backwards keep the
//! graph of their inner pass themselves.

mod training_data;
use training_data::{simulated_dataset, snapshot};

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Result;
// Link the built-in BRDF plugins: the simulator renders with them.
use candle_core::Device;
use photomat_brdfs as _;
use photomat_data::source::DatasetSource;
use photomat_generator::GeneratorConfig;
use photomat_generator::train::state::{
    OPTIMISER_PREFIXES, Restored, STATE_FILE, write_without_optimiser,
};
use photomat_generator::train::{
    FlashPlacement, GanEvent, GanTraining, RealBatch, RunPlan, TrainConfig, Trainer, TrainingData,
};

fn tiny_config(data: &Path, tileable: bool) -> TrainConfig {
    let generator = GeneratorConfig {
        resolution: 32,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        relight_hidden: 8,
        tileable,
        ..Default::default()
    };
    let mut c = TrainConfig::new(generator, data.to_path_buf(), 4, 11);
    // R1 every other step so that short runs exercise it; a higher lr so that a few steps
    // move a model this small.
    c.r1_interval = 2;
    c.lr = 0.01;
    c
}

/// A trainer of `config` after `steps` steps on `data`, its state saved to the folder `run`.
fn trained_and_saved(
    config: &TrainConfig,
    data: &DatasetSource,
    steps: usize,
    run: &Path,
) -> Result<Trainer> {
    let mut trainer = Trainer::new(config.clone(), &Device::Cpu)?;
    for _ in 0..steps {
        trainer.step(data)?;
    }
    trainer.save_state(run)?;
    Ok(trainer)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn discriminator_learns_and_nothing_is_non_finite() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 8, 3)?;
    let config = tiny_config(&data_dir, false);
    let data = DatasetSource::open(&data_dir, 32)?;
    let mut trainer = Trainer::new(config, &Device::Cpu)?;
    let mut gaps = Vec::new();
    for _ in 0..16 {
        let s = trainer.step(&data)?;
        assert!(s.skipped.is_empty(), "step {}: {:?}", s.step, s.skipped);
        for v in [s.loss_g, s.loss_d, s.real_logit, s.fake_logit] {
            assert!(v.is_finite(), "{s:?}");
        }
        assert_eq!(s.r1.is_some(), s.step % 2 == 0, "{s:?}");
        gaps.push(s.real_logit - s.fake_logit);
    }
    let (first, last) = (mean(&gaps[..4]), mean(&gaps[12..]));
    assert!(
        last > first + 0.1 && last > 0.0,
        "D's real−fake logit gap did not grow: {gaps:?}"
    );
    // G_ema: parameters averaged (differ from G after training), w_avg copied.
    let g = snapshot(trainer.model().vars());
    let ema = snapshot(trainer.ema_model().vars());
    let find =
        |s: &[(String, Vec<f64>)], n: &str| s.iter().find(|(k, _)| k == n).unwrap().1.clone();
    assert_eq!(find(&g, "g.mapping.w_avg"), find(&ema, "g.mapping.w_avg"));
    assert_ne!(
        find(&g, "g.mapping.fc0.weight"),
        find(&ema, "g.mapping.fc0.weight")
    );
    assert!(find(&g, "g.mapping.w_avg").iter().any(|v| *v != 0.0));
    // The saved inference model loads and generates finite features.
    trainer.save_model(&dir.path().join("run"), serde_json::json!({"step": 16}))?;
    let model = photomat_generator::GanModel::load(&dir.path().join("run"), &Device::Cpu)?;
    let f = model.features_for_seeds(&[1, 2], 1.0)?;
    assert!(f.abs()?.max_all()?.to_scalar::<f32>()?.is_finite());
    Ok(())
}

#[test]
fn resumed_run_is_bit_identical_to_an_uninterrupted_one() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 8, 3)?;
    let data = DatasetSource::open(&data_dir, 32)?;
    // Tileable: the per-sample roll is part of the draws that must repeat; path-length
    // regularisation on every other step: its running mean is part of the state.
    let mut config = tiny_config(&data_dir, true);
    config.pl_weight = 2.0;
    config.g_reg_interval = 2;

    let mut whole = Trainer::new(config.clone(), &Device::Cpu)?;
    for _ in 0..5 {
        let s = whole.step(&data)?;
        assert!(s.skipped.is_empty(), "{s:?}");
        assert_eq!(s.path_length.is_some(), s.step % 2 == 0, "{s:?}");
        assert!(
            s.path_length.is_none_or(|p| p.is_finite() && p > 0.0),
            "{s:?}"
        );
    }

    let run = dir.path().join("run");
    drop(trained_and_saved(&config, &data, 3, &run)?);
    let mut resumed = Trainer::new(config.clone(), &Device::Cpu)?;
    assert_eq!(resumed.load_state(&run)?, Restored::Exactly);
    assert_eq!(resumed.steps_done(), 3);
    for _ in 0..2 {
        resumed.step(&data)?;
    }
    let (a, b) = (snapshot(whole.state_vars()), snapshot(resumed.state_vars()));
    assert_eq!(a.len(), b.len());
    for ((na, va), (nb, vb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        if na != "trainer.counters" {
            assert!(va == vb, "`{na}` differs after resuming");
        }
    }

    // Another configuration is refused, naming the field; the state is untouched.
    let mut other = config.clone();
    other.generator.channel_multiplier = 1.0 / 32.0;
    let mut wrong = Trainer::new(other, &Device::Cpu)?;
    let err = wrong.load_state(&run).err().unwrap().to_string();
    assert!(err.contains("generator.channel_multiplier"), "{err}");
    assert_eq!(wrong.steps_done(), 0);
    Ok(())
}

#[test]
fn a_state_without_optimisers_resumes_the_networks_with_fresh_adam() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 8, 3)?;
    let data = DatasetSource::open(&data_dir, 32)?;
    let config = tiny_config(&data_dir, true);
    let run = dir.path().join("run");
    let first = trained_and_saved(&config, &data, 3, &run)?;
    let portable = dir.path().join("portable");
    let bytes = write_without_optimiser(&run, &portable)?;
    let full = std::fs::metadata(run.join(STATE_FILE))?.len();
    assert!(bytes < full, "{bytes} ≥ {full}");
    assert!(portable.join("train.json").is_file());

    let mut resumed = Trainer::new(config.clone(), &Device::Cpu)?;
    assert_eq!(
        resumed.load_state(&portable)?,
        Restored::WithFreshOptimisers
    );
    assert_eq!(resumed.steps_done(), 3);
    let fresh = snapshot(Trainer::new(config.clone(), &Device::Cpu)?.state_vars());
    let (trained, loaded) = (snapshot(first.state_vars()), snapshot(resumed.state_vars()));
    let is_optimiser = |n: &str| OPTIMISER_PREFIXES.iter().any(|p| n.starts_with(p));
    let mut optimiser_tensors = 0;
    for (((name, t), (_, l)), (_, f)) in trained.iter().zip(&loaded).zip(&fresh) {
        if is_optimiser(name) {
            optimiser_tensors += 1;
            assert!(l == f, "`{name}` is not a fresh optimiser's");
        } else {
            assert!(l == t, "`{name}` differs from the saved run's");
        }
    }
    assert!(optimiser_tensors > 0);
    let s = resumed.step(&data)?;
    assert!(s.skipped.is_empty(), "{s:?}");

    // A state with one optimiser but not the other is refused and loads nothing.
    photomat_core::checkpoint::copy_checkpoint_where(
        &run.join(STATE_FILE),
        &portable.join(STATE_FILE),
        |name| !name.starts_with("opt_d."),
    )?;
    let mut partial = Trainer::new(config, &Device::Cpu)?;
    let err = partial.load_state(&portable).err().unwrap().to_string();
    assert!(err.contains("a state holds all of them or none"), "{err}");
    assert_eq!(partial.steps_done(), 0);
    Ok(())
}

/// [`DatasetSource`] whose real crops are all NaN while `poison` is set.
struct Poisoned {
    inner: DatasetSource,
    poison: AtomicBool,
}

impl TrainingData for Poisoned {
    fn reals(&self, batch: usize, seed: u64, device: &Device) -> candle_core::Result<RealBatch> {
        let mut r = self.inner.reals(batch, seed, device)?;
        if self.poison.load(Ordering::SeqCst) {
            r.images = (r.images * f64::NAN)?;
        }
        Ok(r)
    }

    fn fake_lights(&self, batch: usize, seed: u64) -> candle_core::Result<Vec<FlashPlacement>> {
        self.inner.fake_lights(batch, seed)
    }

    fn sample_side(&self) -> f64 {
        self.inner.sample_side()
    }

    fn sample_side_texels(&self) -> usize {
        self.inner.sample_side_texels()
    }
}

#[test]
fn nan_guard_skips_poisoned_updates_and_stops_a_diverged_run() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 8, 3)?;
    let mut config = tiny_config(&data_dir, false);
    config.nan_limit = 3;
    let data = Poisoned {
        inner: DatasetSource::open(&data_dir, 32)?,
        poison: AtomicBool::new(false),
    };
    let mut trainer = Trainer::new(config, &Device::Cpu)?;
    trainer.step(&data)?;

    data.poison.store(true, Ordering::SeqCst);
    let d_before = snapshot(trainer.discriminator_vars());
    let g_before = snapshot(trainer.model().vars());
    let s = trainer.step(&data)?;
    assert_eq!(s.skipped, ["D loss is NaN"], "{s:?}");
    assert!(s.loss_g.is_finite());
    assert_eq!(
        snapshot(trainer.discriminator_vars()),
        d_before,
        "D was updated"
    );
    assert_ne!(
        snapshot(trainer.model().vars()),
        g_before,
        "G was not updated"
    );

    // A clean step resets the streak; then three poisoned steps in a row stop the run.
    data.poison.store(false, Ordering::SeqCst);
    assert!(trainer.step(&data)?.skipped.is_empty());
    data.poison.store(true, Ordering::SeqCst);
    trainer.step(&data)?;
    trainer.step(&data)?;
    let err = trainer.step(&data).err().unwrap().to_string();
    assert!(
        err.contains("step 6") && err.contains("D loss is NaN") && err.contains("3 consecutive"),
        "{err}"
    );
    Ok(())
}

#[test]
fn a_skipped_update_is_logged_and_never_checkpointed() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 8, 3)?;
    let mut config = tiny_config(&data_dir, false);
    config.cadence.checkpoint_every = 1;
    config.cadence.swd_every = 0;
    let data = Poisoned {
        inner: DatasetSource::open(&data_dir, 32)?,
        poison: AtomicBool::new(false),
    };
    let run = dir.path().join("run");
    let plan = RunPlan {
        config,
        resume: false,
        notes: Vec::new(),
    };
    let mut training = GanTraining::open(&run, plan, 2, &Device::Cpu)?;
    let mut held = Vec::new();
    let mut skipped = Vec::new();
    // Step 2's reals are NaN: D's update is skipped and its checkpoint held back.
    training.run(&data, &AtomicBool::new(false), &mut |event| match event {
        GanEvent::Step { done: 1, .. } => data.poison.store(true, Ordering::SeqCst),
        GanEvent::Skipped { step, reason } => skipped.push((step, reason.to_string())),
        GanEvent::CheckpointHeld { step, .. } => held.push(step),
        _ => {}
    })?;
    assert_eq!(skipped, [(2, "D loss is NaN".to_string())]);
    // Held after step 2 (its cadence) and at the end of the run (also step 2).
    assert_eq!(held, [2, 2]);
    let log = std::fs::read_to_string(run.join("log.csv"))?;
    let rows: Vec<&str> = log.lines().collect();
    assert!(rows[1].ends_with(",0.01,"), "{log}");
    assert!(rows[2].ends_with(",0.01,D loss is NaN"), "{log}");
    drop(training);
    // The folder holds the state after step 1, the last good one.
    let mut resumed = Trainer::new(tiny_config(&data_dir, false), &Device::Cpu)?;
    resumed.load_state(&run)?;
    assert_eq!(resumed.steps_done(), 1);
    Ok(())
}

#[test]
fn relief_switched_on_at_a_resume_starts_at_zero_and_then_trains() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let data_dir = simulated_dataset(dir.path(), 8, 3)?;
    let data = DatasetSource::open(&data_dir, 32)?;
    let config = tiny_config(&data_dir, true);
    let run = dir.path().join("run");
    let first = trained_and_saved(&config, &data, 2, &run)?;

    // The full state (optimisers included) lacks M's relief projection and its moments.
    let mut with_relief = config.clone();
    with_relief.generator.relief = true;
    let mut resumed = Trainer::new(with_relief.clone(), &Device::Cpu)?;
    assert_eq!(resumed.load_state(&run)?, Restored::Exactly);
    let (before, after) = (snapshot(first.state_vars()), snapshot(resumed.state_vars()));
    let relief: Vec<_> = after
        .iter()
        .filter(|(n, _)| n.contains("m.relief."))
        .collect();
    assert!(!relief.is_empty());
    for (name, values) in &relief {
        assert!(
            values.iter().all(|v| *v == 0.0),
            "`{name}` does not start at zero"
        );
    }
    let saved: std::collections::HashMap<_, _> = before.into_iter().collect();
    for (name, values) in after.iter().filter(|(n, _)| !n.contains("m.relief.")) {
        if name != "trainer.counters" {
            assert!(
                &saved[name] == values,
                "`{name}` differs from the saved run's"
            );
        }
    }
    // Zero relief: M relights exactly as before.
    let features = first.model().features_for_seeds(&[5], 1.0)?;
    let omega = photomat_core::FlashGeometry::new(
        &[photomat_core::Highlight { x: 0.1, y: -0.2 }],
        32,
        candle_core::DType::F32,
        &Device::Cpu,
    )?
    .omega;
    let a = first.model().relight().forward(&features, &omega)?;
    let b = resumed.model().relight().forward(&features, &omega)?;
    assert_eq!((a - b)?.abs()?.max_all()?.to_scalar::<f32>()?, 0.0);

    // The projection trains, and a run with relief cannot resume without it.
    for _ in 0..2 {
        resumed.step(&data)?;
    }
    let weight = snapshot(resumed.state_vars())
        .into_iter()
        .find(|(n, _)| n == "m.relief.weight")
        .expect("relief weight")
        .1;
    assert!(weight.iter().any(|v| *v != 0.0));
    resumed.save_state(&run)?;
    let mut without = Trainer::new(config, &Device::Cpu)?;
    let err = without.load_state(&run).err().unwrap().to_string();
    assert!(err.contains("relief"), "{err}");
    Ok(())
}
