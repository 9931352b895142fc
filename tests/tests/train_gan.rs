//! `photomat train-gan` through `photomat_cli::run_with_output` on tiny simulated data: a run
//! writes its state, GAN model folder, log and samples; `--resume` continues byte-identically
//! to an uninterrupted run and refuses contradicting flags; bad inputs fail naming the
//! problem.

use photomat_tests::cli_fixtures::{path_str, photomat, photomat_error, simulated_dataset};

use std::path::Path;

/// The flags of a tiny 32² model.
const TINY: [&str; 6] = [
    "--size",
    "32",
    "--multiplier",
    "0.015625",
    "--latent-dim",
    "16",
];

/// The flags of the tiny model followed by `extra`.
fn tiny_with<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    TINY.iter().copied().chain(extra.iter().copied()).collect()
}

fn train(data: Option<&str>, run: &Path, extra: &[&str]) -> anyhow::Result<String> {
    let mut args = vec!["train-gan", "--out", run.to_str().unwrap()];
    if let Some(d) = data {
        args.extend(["--data", d]);
    }
    args.extend(extra);
    photomat(&args)
}

#[test]
fn train_gan_runs_resumes_identically_and_refuses_contradictions() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulated_dataset(dir.path(), 64);
    let data = path_str(&data).to_string();
    let whole = dir.path().join("whole");
    let flags = tiny_with(&[
        "--steps",
        "3",
        "--sample-every",
        "2",
        "--seed",
        "5",
        "--swd-every",
        "3",
        "--swd-count",
        "8",
    ]);
    let out = train(Some(&data), &whole, &flags).unwrap();
    assert!(out.contains("trained 3 steps"), "{out}");
    for f in [
        "train.json",
        "train_state.safetensors",
        "gan.json",
        "gan.safetensors",
        "log.csv",
        "samples/step-000002.png",
        "samples/step-000003.png",
    ] {
        assert!(whole.join(f).is_file(), "{f} missing");
    }
    // Five materials × (four lights + one real crop) of 32², 4-pixel gaps.
    let (c, h, w) =
        photomat_core::image_io::png_header(&whole.join("samples/step-000003.png")).unwrap();
    assert_eq!((c, h, w), (3, 5 * 32 + 16, 5 * 32 + 16));
    let log = std::fs::read_to_string(whole.join("log.csv")).unwrap();
    let rows: Vec<&str> = log.lines().collect();
    assert_eq!(rows.len(), 4, "{log}");
    assert!(rows[0].starts_with("step,kimg,loss_g,loss_d"));
    assert!(rows[3].starts_with("3,0.012,"), "{log}");
    // SWD (column 10) on step 3 only.
    let swd: Vec<&str> = rows[1..]
        .iter()
        .map(|r| r.split(',').nth(9).unwrap())
        .collect();
    assert_eq!(&swd[..2], ["", ""], "{log}");
    assert!(swd[2].parse::<f64>().unwrap() > 0.0, "{log}");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(whole.join("gan.json")).unwrap()).unwrap();
    assert_eq!(manifest["provenance"]["step"], 3);
    assert_eq!(manifest["architecture"]["resolution"], 32);

    // 2 steps, then resume to 3: the same bytes as the uninterrupted run.
    let split = dir.path().join("split");
    let short = tiny_with(&["--steps", "2", "--seed", "5"]);
    train(Some(&data), &split, &short).unwrap();
    let out = train(None, &split, &["--resume", "--steps", "3"]).unwrap();
    assert!(out.contains("trained 1 steps (3 in total"), "{out}");
    for f in ["train_state.safetensors", "gan.safetensors"] {
        assert!(
            std::fs::read(whole.join(f)).unwrap() == std::fs::read(split.join(f)).unwrap(),
            "{f} differs between the resumed and the uninterrupted run"
        );
    }
    let resumed_log = std::fs::read_to_string(split.join("log.csv")).unwrap();
    assert_eq!(resumed_log.lines().count(), 4, "{resumed_log}");

    // Contradicting flags name the field; a second fresh run into the folder is refused.
    let err = photomat_error(&[
        "train-gan",
        "--out",
        split.to_str().unwrap(),
        "--resume",
        "--steps",
        "4",
        "--size",
        "64",
    ]);
    assert!(err.contains("generator.resolution"), "{err}");
    let err = photomat_error(&[
        "train-gan",
        "--out",
        split.to_str().unwrap(),
        "--resume",
        "--steps",
        "4",
        "--relight-lr-multiplier",
        "0.5",
    ]);
    assert!(err.contains("generator.relight_lr_multiplier"), "{err}");
    let err = train(Some(&data), &split, &short).unwrap_err().to_string();
    assert!(err.contains("--resume"), "{err}");

    // A data set moved since the run started: without --data the resume names the old
    // folder; with --data it continues and the new path is saved.
    let moved = dir.path().join("moved-data");
    std::fs::rename(&data, &moved).unwrap();
    let err = train(None, &split, &["--resume", "--steps", "4"])
        .unwrap_err()
        .to_string();
    assert!(err.contains("training data"), "{err}");
    let out = train(moved.to_str(), &split, &["--resume", "--steps", "4"]).unwrap();
    assert!(out.contains("4 in total"), "{out}");
    let saved: serde_json::Value =
        serde_json::from_slice(&std::fs::read(split.join("train.json")).unwrap()).unwrap();
    let saved_data = std::path::PathBuf::from(saved["data"].as_str().unwrap());
    assert_eq!(saved_data, std::fs::canonicalize(&moved).unwrap());
}

#[test]
fn train_gan_errors_name_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let run_s = run.to_str().unwrap();
    let missing = dir.path().join("no-such-data");

    let err = photomat_error(&[
        "train-gan",
        "--data",
        missing.to_str().unwrap(),
        "--out",
        run_s,
        "--steps",
        "1",
    ]);
    assert!(
        err.contains("no-such-data") && err.contains("does not exist"),
        "{err}"
    );
    assert!(!run.exists(), "a failed start left {run_s}");

    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let err = photomat_error(&[
        "train-gan",
        "--data",
        empty.to_str().unwrap(),
        "--out",
        run_s,
        "--steps",
        "1",
    ]);
    assert!(err.contains("empty") && err.contains("index.json"), "{err}");

    let err = photomat_error(&[
        "train-gan",
        "--data",
        "x",
        "--out",
        run_s,
        "--steps",
        "1",
        "--size",
        "48",
    ]);
    assert!(err.contains("--size 48"), "{err}");

    // 32² photos are too small for a 32² model (crops come from 2R × 2R).
    let data = simulated_dataset(dir.path(), 32);
    let data = path_str(&data).to_string();
    let err = photomat_error(&[
        "train-gan",
        "--data",
        &data,
        "--out",
        run_s,
        "--steps",
        "1",
        "--size",
        "32",
    ]);
    assert!(err.contains("32×32") && err.contains("64×64"), "{err}");

    let err = photomat_error(&["train-gan", "--out", run_s, "--resume", "--steps", "1"]);
    assert!(err.contains("train_state.safetensors"), "{err}");

    let err = photomat_error(&["train-gan", "--data", &data, "--out", run_s]);
    assert!(err.contains("--steps"), "{err}");
}

#[test]
fn train_gan_resume_keeps_the_cadence_may_lower_the_lr_and_the_folder_is_locked() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulated_dataset(dir.path(), 64);
    let data = path_str(&data).to_string();
    let run = dir.path().join("run");
    let flags = tiny_with(&["--steps", "2", "--sample-every", "1", "--swd-every", "0"]);
    train(Some(&data), &run, &flags).unwrap();
    // Resumed without the cadence flags: a sample grid after every step still.
    train(None, &run, &["--resume", "--steps", "4"]).unwrap();
    assert!(run.join("samples/step-000003.png").is_file());

    // A lower learning rate is what a diverged run's message recommends: allowed on resume,
    // and log.csv says from which step it applies.
    train(None, &run, &["--resume", "--steps", "5", "--lr", "0.001"]).unwrap();
    let log = std::fs::read_to_string(run.join("log.csv")).unwrap();
    let header: Vec<&str> = log.lines().next().unwrap().split(',').collect();
    let lr_column = header.iter().position(|c| *c == "lr").unwrap();
    let lrs: Vec<&str> = log
        .lines()
        .skip(1)
        .map(|r| r.split(',').nth(lr_column).unwrap())
        .collect();
    assert_eq!(
        lrs,
        ["0.0025", "0.0025", "0.0025", "0.0025", "0.001"],
        "{log}"
    );

    // While another process holds the run folder, a second train-gan fails at once.
    let _held = photomat_core::FolderLock::acquire(&run, "photomat train-gan").unwrap();
    let err = train(None, &run, &["--resume", "--steps", "6"])
        .unwrap_err()
        .to_string();
    assert!(err.contains("is in use by process"), "{err}");
}

/// `eval-gan --discriminator` on a run folder reports D's logits per kind of image, seeded and
/// finite, at the run's step; on a GAN folder without D it names what it needs.
#[test]
fn eval_gan_discriminator_probe_reads_the_runs_d() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulated_dataset(dir.path(), 64);
    let data = path_str(&data).to_string();
    let run = dir.path().join("run");
    let flags = tiny_with(&["--steps", "2"]);
    train(Some(&data), &run, &flags).unwrap();
    // `eval-gan --discriminator` on `gan` with `seed`, as JSON or as the table.
    let eval = |gan: &Path, seed: &str, json: bool| {
        let mut args = vec![
            "eval-gan",
            "--gan",
            path_str(gan),
            "--data",
            &data,
            "--count",
            "4",
            "--seed",
            seed,
            "--discriminator",
        ];
        if json {
            args.push("--json");
        }
        photomat(&args)
    };
    let probe = |seed: &str| -> serde_json::Value {
        let printed = eval(&run, seed, true).unwrap();
        serde_json::from_str::<serde_json::Value>(&printed).unwrap()["discriminator"].clone()
    };
    let p = probe("1");
    assert_eq!(p["step"], 2);
    assert_eq!(p["count"], 4);
    let rows = ["reals", "reals_other_lights", "fakes", "fakes_other_lights"];
    for row in rows {
        assert!(p[row].as_f64().unwrap().is_finite(), "{row}: {p}");
    }
    let blurred: Vec<f64> = p["reals_blurred"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(blurred.len(), 2);
    // Blurring changes what D sees; the seed fixes every draw.
    assert!(
        blurred.iter().all(|&b| b != p["reals"].as_f64().unwrap()),
        "{p}"
    );
    assert_eq!(probe("1"), p);
    assert_ne!(probe("2")["reals"], p["reals"]);

    let table = eval(&run, "1", false).unwrap();
    assert!(table.contains("what D looks at (step 2"), "{table}");
    assert!(table.contains("texture gap"), "{table}");

    // A GAN model folder without the run's state has no D to probe.
    let gan_only = dir.path().join("gan-only");
    std::fs::create_dir_all(&gan_only).unwrap();
    for f in ["gan.json", "gan.safetensors"] {
        std::fs::copy(run.join(f), gan_only.join(f)).unwrap();
    }
    let err = format!("{:#}", eval(&gan_only, "1", false).unwrap_err());
    assert!(err.contains("train-gan` run folder"), "{err}");
}

/// `train-gan --snapshot-every` keeps G_ema + M of each cadence step as a model folder, and
/// `rank-snapshots` orders them by the mean over seeds of the figure `eval-gan` reports for
/// each seed, writes the ranking into the run and copies the best snapshot out.
#[test]
fn snapshots_are_kept_and_ranked_by_eval_gan_over_seeds() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulated_dataset(dir.path(), 64);
    let data = path_str(&data).to_string();
    let run = dir.path().join("run");
    let flags = tiny_with(&["--steps", "3", "--snapshot-every", "1", "--swd-every", "0"]);
    train(Some(&data), &run, &flags).unwrap();
    let snapshot = |step: u64| run.join(format!("snapshots/step-{step:06}"));
    for step in 1..=3 {
        let manifest: serde_json::Value =
            serde_json::from_slice(&std::fs::read(snapshot(step).join("gan.json")).unwrap())
                .unwrap();
        assert_eq!(manifest["provenance"]["step"], step);
    }
    // The last snapshot is the model the run ends with.
    assert_eq!(
        std::fs::read(snapshot(3).join("gan.safetensors")).unwrap(),
        std::fs::read(run.join("gan.safetensors")).unwrap()
    );

    let best = dir.path().join("best");
    let printed = photomat(&[
        "rank-snapshots",
        path_str(&run),
        "--seeds",
        "2",
        "--count",
        "8",
        "--best-to",
        path_str(&best),
        "--json",
    ])
    .unwrap();
    let report: serde_json::Value = serde_json::from_str(&printed).unwrap();
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("snapshots/ranking.json")).unwrap())
            .unwrap();
    assert_eq!(report, written);
    let ranking = report["ranking"].as_array().unwrap();
    assert_eq!(ranking.len(), 3);
    let means: Vec<f64> = ranking
        .iter()
        .map(|r| r["mean"].as_f64().unwrap())
        .collect();
    assert!(means.windows(2).all(|m| m[0] <= m[1]), "{means:?}");
    for entry in ranking {
        let folder = entry["folder"].as_str().unwrap();
        let per_seed: Vec<f64> = entry["swd_per_seed"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        for (seed, value) in per_seed.iter().enumerate() {
            let eval: serde_json::Value = serde_json::from_str(
                &photomat(&[
                    "eval-gan",
                    "--gan",
                    folder,
                    "--data",
                    &data,
                    "--count",
                    "8",
                    "--seed",
                    &seed.to_string(),
                    "--json",
                ])
                .unwrap(),
            )
            .unwrap();
            assert_eq!(
                eval["mean_x1e3"].as_f64().unwrap(),
                *value,
                "{folder} seed {seed}"
            );
        }
        let mean = per_seed.iter().sum::<f64>() / 2.0;
        assert!((entry["mean"].as_f64().unwrap() - mean).abs() < 1e-12);
    }
    let best_folder = Path::new(ranking[0]["folder"].as_str().unwrap());
    assert_eq!(
        std::fs::read(best.join("gan.safetensors")).unwrap(),
        std::fs::read(best_folder.join("gan.safetensors")).unwrap()
    );

    // --best-to never replaces a model without asking, nor writes into a folder holding more
    // than a GAN model (a model folder with its estimators, such as a copy of the bundled one).
    let best_again = [
        "rank-snapshots",
        path_str(&run),
        "--seeds",
        "1",
        "--count",
        "8",
    ];
    let err = photomat_error(&[&best_again[..], &["--best-to", path_str(&best)]].concat());
    assert!(
        err.contains("already holds a GAN model") && err.contains("--overwrite"),
        "{err}"
    );
    photomat(
        &[
            &best_again[..],
            &["--best-to", path_str(&best), "--overwrite"],
        ]
        .concat(),
    )
    .unwrap();
    let model = dir.path().join("model");
    std::fs::create_dir(&model).unwrap();
    std::fs::write(model.join("estimator.json"), "{}").unwrap();
    let err = photomat_error(
        &[
            &best_again[..],
            &["--best-to", path_str(&model), "--overwrite"],
        ]
        .concat(),
    );
    assert!(
        err.contains("estimator.json") && err.contains("does not write"),
        "{err}"
    );
    assert!(!model.join("gan.json").exists());
    // A damaged train.json is reported as what it is, not as a missing --data.
    let damaged = dir.path().join("damaged");
    std::fs::create_dir_all(damaged.join("snapshots")).unwrap();
    std::fs::write(damaged.join("train.json"), "{ not json").unwrap();
    copy_folder(&snapshot(1), &damaged.join("snapshots/step-000001"));
    let err = photomat_error(&["rank-snapshots", path_str(&damaged)]);
    assert!(
        err.contains("train.json") && !err.contains("give the data set"),
        "{err}"
    );

    // Every measurement is kept in its snapshot: ranking again with a third seed measures only
    // that one (a kept value, altered here, is reported as kept), and other weights in the
    // folder discard what was kept for the old ones.
    let first = snapshot(1);
    let kept_path = first.join("swd_scores.json");
    let mut kept: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&kept_path).unwrap()).unwrap();
    let scores = kept["swd"].as_object_mut().unwrap();
    assert_eq!(scores.len(), 2, "{scores:?}");
    let seed0 = scores
        .keys()
        .find(|k| k.ends_with("seed=0"))
        .unwrap()
        .clone();
    scores.insert(seed0, serde_json::json!(1.5));
    std::fs::write(&kept_path, serde_json::to_vec(&kept).unwrap()).unwrap();
    let rank = |seeds: &str| -> serde_json::Value {
        let printed = photomat(&[
            "rank-snapshots",
            path_str(&run),
            "--seeds",
            seeds,
            "--count",
            "8",
            "--json",
        ])
        .unwrap();
        serde_json::from_str(&printed).unwrap()
    };
    let per_seed = |report: &serde_json::Value, step: u64| -> Vec<f64> {
        report["ranking"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["step"] == step)
            .unwrap()["swd_per_seed"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let three = rank("3");
    assert_eq!(per_seed(&three, 1).len(), 3);
    assert_eq!(per_seed(&three, 1)[0], 1.5);
    std::fs::copy(
        snapshot(2).join("gan.safetensors"),
        first.join("gan.safetensors"),
    )
    .unwrap();
    let measured = rank("1");
    assert_eq!(per_seed(&measured, 1), per_seed(&measured, 2));

    // A snapshot that cannot be read is reported and left out; the others are still ranked.
    std::fs::write(snapshot(2).join("gan.safetensors"), b"not weights").unwrap();
    let partial = rank("1");
    assert_eq!(partial["ranking"].as_array().unwrap().len(), 2, "{partial}");
    let unscored = partial["unscored"].as_array().unwrap();
    assert_eq!(unscored.len(), 1, "{partial}");
    assert!(
        unscored[0]["folder"]
            .as_str()
            .unwrap()
            .ends_with("step-000002"),
        "{partial}"
    );

    // A resume removes the snapshots after its checkpoint (here one planted at step 9, as a
    // run killed past its last checkpoint leaves them) and keeps taking them.
    std::fs::create_dir_all(snapshot(9)).unwrap();
    std::fs::copy(snapshot(3).join("gan.json"), snapshot(9).join("gan.json")).unwrap();
    train(None, &run, &["--resume", "--steps", "4"]).unwrap();
    assert!(!snapshot(9).exists());
    assert!(snapshot(4).join("gan.safetensors").is_file());

    // A run without snapshots says how to keep them.
    let plain = dir.path().join("plain");
    let flags = tiny_with(&["--steps", "1"]);
    train(Some(&data), &plain, &flags).unwrap();
    let err = photomat_error(&["rank-snapshots", path_str(&plain)]);
    assert!(err.contains("--snapshot-every"), "{err}");
}

/// Copies the files of the folder `from` into `to` (created).
fn copy_folder(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
}
