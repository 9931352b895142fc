//! `photomat trade` end to end on a tiny GAN: the table, JSON and plot are written with one
//! entry per model, sorted by render cost with a Pareto front; estimators are reused from the
//! cache by a second study with the same settings and retrained when a setting changes; bad
//! lists fail before anything is trained.

use photomat_tests::cli_fixtures::{path_str as s, photomat, photomat_error, tiny_gan};
use serde_json::Value;

fn study(gan: &str, out: &str, cache: &str, steps: &str) -> anyhow::Result<Value> {
    photomat(&[
        "trade",
        "--gan",
        gan,
        "--brdfs",
        "lambert, ggx(shadowing=implicit), height(ggx, scale=0.05)",
        "--out",
        out,
        "--cache",
        cache,
        "--steps",
        steps,
        "--finetune-steps",
        "1",
        "--width",
        "0.125",
        "--materials",
        "2",
    ])?;
    let text = std::fs::read_to_string(std::path::Path::new(out).join("trade.json"))?;
    Ok(serde_json::from_str(&text)?)
}

fn reused(report: &Value) -> Vec<bool> {
    report["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["reused"].as_bool().unwrap())
        .collect()
}

#[test]
fn trade_writes_table_json_and_plot_and_reuses_its_estimators() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    let gan = tiny_gan(dir.path(), "gan", 32, 5);
    let cache = dir.path().join("cache");
    let first_out = dir.path().join("t1");
    let first = study(s(&gan), s(&first_out), s(&cache), "2")?;

    let entries = first["entries"].as_array().unwrap();
    let mut specs: Vec<&str> = entries
        .iter()
        .map(|e| e["spec"].as_str().unwrap())
        .collect();
    specs.sort();
    assert_eq!(
        specs,
        [
            "ggx(shadowing=implicit)",
            "height(ggx, scale=0.05)",
            "lambert"
        ]
    );
    let costs: Vec<f64> = entries
        .iter()
        .map(|e| {
            e["cost"]["render"]["eval_ms_per_megatexel"]
                .as_f64()
                .unwrap()
        })
        .collect();
    assert!(
        costs.windows(2).all(|w| w[0] <= w[1]),
        "not sorted by cost: {costs:?}"
    );
    assert!(
        entries[0]["pareto"].as_bool().unwrap(),
        "the cheapest model is always on the front"
    );
    for e in entries {
        let l1 = e["accuracy"]["l1_per_light"].as_array().unwrap();
        assert_eq!(l1.len(), 9, "5 reference + 4 held-out lights");
        assert!(e["accuracy"]["ssim_mean"].as_f64().unwrap() <= 1.0);
        assert!(e["cost"]["map_bytes"]["png"].as_u64().unwrap() > 0);
        assert_eq!(e["reused"], false);
    }
    let table = std::fs::read_to_string(first_out.join("trade.md"))?;
    assert_eq!(
        table.lines().filter(|l| l.starts_with("| `")).count(),
        3,
        "{table}"
    );
    let (_, h, w) = photomat_core::image_io::png_header(&first_out.join("trade.png"))?;
    assert_eq!((w, h), (960, 640));
    assert!(first_out.join("maps/lambert/material.json").is_file());

    // The same folder again: refused without --overwrite; with it the study is replaced
    // whole, so the first study's other models leave no maps behind.
    let lambert_only = [
        "trade",
        "--gan",
        s(&gan),
        "--brdfs",
        "lambert",
        "--out",
        s(&first_out),
        "--cache",
        s(&cache),
        "--steps",
        "2",
        "--finetune-steps",
        "1",
        "--width",
        "0.125",
        "--materials",
        "2",
    ];
    let err = photomat_error(&lambert_only);
    assert!(
        err.contains("already holds a trade study") && err.contains("--overwrite"),
        "{err}"
    );
    photomat(&[&lambert_only[..], &["--overwrite"]].concat())?;
    let maps: Vec<String> = std::fs::read_dir(first_out.join("maps"))?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<Result<_, _>>()?;
    assert_eq!(maps, ["lambert"]);

    // Same settings: every estimator comes from the cache, with the same accuracy.
    let second_out = dir.path().join("t2");
    let second = study(s(&gan), s(&second_out), s(&cache), "2")?;
    assert_eq!(reused(&second), [true, true, true]);
    let l1 = |r: &Value, spec: &str| {
        r["entries"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["spec"] == spec)
            .unwrap()["accuracy"]["l1_mean"]
            .as_f64()
            .unwrap()
    };
    assert_eq!(l1(&first, "lambert"), l1(&second, "lambert"));

    // Another budget: every estimator is trained again.
    let third = study(s(&gan), s(&dir.path().join("t3")), s(&cache), "3")?;
    assert_eq!(reused(&third), [false, false, false]);
    Ok(())
}

#[test]
fn trade_rejects_bad_lists_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let gan = tiny_gan(dir.path(), "gan", 32, 5);
    let out = dir.path().join("t");
    for (brdfs, needle) in [
        ("lambert,blinn", "unknown BRDF model 'blinn'"),
        ("lambert,ggx(", "unbalanced '('"),
        (
            "ggx, ggx(shadowing=separable)",
            "names the model 'ggx' a second time",
        ),
    ] {
        let err = photomat_error(&[
            "trade",
            "--gan",
            s(&gan),
            "--brdfs",
            brdfs,
            "--out",
            s(&out),
        ]);
        assert!(err.contains(needle), "{brdfs}: {err}");
        assert!(
            !out.join("estimators").exists(),
            "{brdfs}: something was trained"
        );
    }
}
