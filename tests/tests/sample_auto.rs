//! `photomat sample --brdf auto|SPEC` on a tiny model folder holding three estimators (the
//! root's `height(ggx)`, `estimators/lambert/`, `estimators/coated/`): auto records per
//! material the candidates' errors and picks the cheapest within the tolerance of the best
//! linear-radiance L1 (the best at tolerance 0, the cheapest at a huge one), the summary counts the choices, a named model
//! is used for every material, and an absent one is refused naming those present.

use std::path::Path;

use candle_core::Device;
use photomat_core::lookup;
use photomat_core::map_files::load_maps;
use photomat_estimator::EstimatorModel;
use photomat_generator::GanModel;
use photomat_tests::cli_fixtures::{
    path_str as s, photomat, photomat_error, tiny_estimator_config, tiny_gan_config,
};
use serde_json::Value;

/// A tiny untrained model folder with an estimator for each of `specs` (the first at the root).
fn model_with_estimators(dir: &Path, specs: &[&str]) {
    GanModel::new(&tiny_gan_config(32), 3, &Device::Cpu)
        .unwrap()
        .save(dir, Value::Null)
        .unwrap();
    for (k, spec) in specs.iter().enumerate() {
        let brdf = lookup(spec).unwrap();
        let config = tiny_estimator_config(brdf.channels());
        let folder = if k == 0 {
            dir.to_path_buf()
        } else {
            dir.join("estimators").join(spec)
        };
        EstimatorModel::new_seeded(brdf, config, 10 + k as u64, &Device::Cpu)
            .unwrap()
            .save(&folder, Value::Null)
            .unwrap();
    }
}

/// `sample` of one material of `model` into `out` in the BRDF model `brdf`.
fn sample_one<'a>(model: &'a str, out: &'a str, brdf: &'a str) -> [&'a str; 9] {
    [
        "sample", "--model", model, "--count", "1", "--out", out, "--brdf", brdf,
    ]
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn sample_auto_records_and_applies_the_choice() {
    let temp = tempfile::tempdir().unwrap();
    let model = temp.path().join("model");
    model_with_estimators(&model, &["height(ggx)", "lambert", "coated"]);
    let run = |tolerance: &str, out: &str| {
        let out = temp.path().join(out);
        let text = photomat(&[
            "sample",
            "--model",
            s(&model),
            "--count",
            "3",
            "--out",
            s(&out),
            "--brdf",
            "auto",
            "--tolerance",
            tolerance,
        ])
        .unwrap();
        (out, text)
    };

    // Tolerance 0: every material gets the model with the lowest error.
    let (out, text) = run("0", "best");
    assert!(text.contains("--brdf auto (tolerance 0)"), "{text}");
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["brdf"], "auto");
    let mut counted = 0;
    for m in summary["materials"].as_array().unwrap() {
        let folder = Path::new(m["folder"].as_str().unwrap());
        let manifest = read_json(&folder.join("material/material.json"));
        let selection = &manifest["selection"];
        let candidates = selection["candidates"].as_array().unwrap();
        let names: Vec<&str> = candidates
            .iter()
            .map(|c| c["brdf"].as_str().unwrap())
            .collect();
        // Cheapest first: lambert (6 channels), height(ggx) (8), coated (11).
        assert_eq!(names, ["lambert", "height(ggx, scale=0.02)", "coated"]);
        // Auto compares the L1 of linear radiance.
        let error = |c: &Value| c["l1_linear"].as_f64().unwrap();
        let best = candidates
            .iter()
            .min_by(|a, b| error(a).total_cmp(&error(b)))
            .unwrap();
        assert!(candidates.iter().all(|c| c["l1"].as_f64().unwrap() > 0.0));
        assert_eq!(selection["chosen"], best["brdf"]);
        assert_eq!(manifest["brdf"], best["brdf"]);
        assert_eq!(m["brdf"], best["brdf"]);
        // The folder loads back as the chosen model.
        let loaded = load_maps(&folder.join("material"), None).unwrap();
        assert_eq!(loaded.brdf.name(), best["brdf"].as_str().unwrap());
        counted += 1;
    }
    assert_eq!(counted, 3);
    let counts: u64 = summary["brdf_counts"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(counts, 3);

    // A huge tolerance: every material gets the cheapest model.
    let (out, _) = run("1000", "cheap");
    let summary = read_json(&out.join("summary.json"));
    assert_eq!(summary["brdf_counts"], serde_json::json!({ "lambert": 3 }));
}

#[test]
fn sample_named_brdf_uses_that_estimator_or_names_the_ones_present() {
    let temp = tempfile::tempdir().unwrap();
    let model = temp.path().join("model");
    model_with_estimators(&model, &["height(ggx)", "lambert"]);
    let out = temp.path().join("named");
    photomat(&sample_one(s(&model), s(&out), "lambert")).unwrap();
    let manifest = read_json(&out.join("seed-0000/material/material.json"));
    assert_eq!(manifest["brdf"], "lambert");
    assert!(manifest.get("selection").is_none());

    let err = photomat_error(&sample_one(s(&model), s(&temp.path().join("x")), "coated"));
    assert!(
        err.contains("no estimator for 'coated'")
            && err.contains("height(ggx, scale=0.02), lambert"),
        "{err}"
    );
}
