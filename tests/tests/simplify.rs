//! Only the maps a material requires (`photomat_core::simplify`, `sample --simplify`):
//! - the simplifier keeps a constant or grey form exactly when the material's error stays
//!   within the tolerance, judged on the final maps;
//! - a compact folder stores a constant map as a value and a grey map as one channel, loads
//!   back bit for bit, is smaller by what `folder_bytes` says, and refuses inconsistent entries
//!   naming the manifest;
//! - `photomat sample --simplify` records the steps, the error and the bytes.

use std::path::Path;

use candle_core::{DType, Device, Tensor};
use photomat_core::image_io::{PlanarImage, png_header};
use photomat_core::map_files::{MANIFEST_FILE, SaveOptions, folder_bytes, load_maps, save_maps};
use photomat_core::simplify::{MapForm, constant_value, is_grey, simplify};
use photomat_core::{Brdf, Highlight, MaterialMaps, render};
use photomat_tests::cli_fixtures::{
    path_str as s, photomat, tiny_estimator_config, tiny_gan_config,
};
use photomat_tests::model;
use serde_json::Value;

const SIZE: usize = 16;

/// A (1, C, SIZE, SIZE) f32 map with value `f(channel, row, col)`.
fn map(channels: usize, f: impl Fn(usize, usize, usize) -> f32) -> Tensor {
    let data = (0..channels * SIZE * SIZE)
        .map(|i| f(i / (SIZE * SIZE), (i / SIZE) % SIZE, i % SIZE))
        .collect();
    PlanarImage::new(channels, SIZE, SIZE, data)
        .unwrap()
        .to_tensor(&Device::Cpu)
        .unwrap()
}

/// A `ggx` material: a coloured checkerboard diffuse, a specular grey up to a `tint` of red in
/// every other row, a
/// roughness of 0.5 up to `wobble`, a normal of +z tilted by up to `wobble`.
fn ggx_maps(tint: f32, wobble: f32) -> MaterialMaps {
    let ripple = |r: usize, c: usize| wobble * (((r * 7 + c * 3) % 5) as f32 / 4.0 - 0.5);
    let normal = map(3, |ch, r, c| match ch {
        0 => ripple(r, c),
        1 => ripple(c, r),
        _ => 1.0,
    });
    MaterialMaps::new()
        .with(
            "diffuse",
            map(3, |ch, r, c| match ((r / 4 + c / 4) % 2, ch) {
                (0, 0) => 0.7,
                (0, _) => 0.2,
                (_, 2) => 0.6,
                _ => 0.1,
            }),
        )
        .with(
            "specular",
            map(3, |ch, r, _| {
                0.04 + if ch == 0 { tint * (r % 2) as f32 } else { 0.0 }
            }),
        )
        .with("roughness", map(1, |_, r, c| 0.5 + ripple(r, c)))
        .with(
            "normal",
            photomat_core::vecops::normalize3(&normal).unwrap(),
        )
}

/// Display-encoded renders of `maps` under three flash positions.
fn renders(brdf: &Brdf, maps: &MaterialMaps) -> Tensor {
    let lights = [
        Highlight::CENTER,
        Highlight { x: 0.3, y: 0.4 },
        Highlight { x: 0.7, y: 0.6 },
    ];
    render(brdf.as_ref(), maps, &lights).unwrap()
}

fn l1(a: &Tensor, b: &Tensor) -> f64 {
    (a - b)
        .unwrap()
        .abs()
        .unwrap()
        .mean_all()
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap()
        .to_scalar::<f64>()
        .unwrap()
}

#[test]
fn simplify_keeps_the_forms_that_stay_within_the_tolerance() {
    let brdf = model("ggx");
    // The reference: a grey specular, a constant roughness, a flat normal.
    let reference = renders(&brdf, &ggx_maps(0.0, 0.0));
    let maps = ggx_maps(0.01, 0.02);
    let mut calls = 0;
    let mut error_of = |m: &MaterialMaps| {
        calls += 1;
        Ok::<_, photomat_core::Error>(vec![l1(&renders(&brdf, m), &reference)])
    };
    let out = simplify(brdf.as_ref(), &maps, 0.1, &mut error_of).unwrap();
    assert!(out.error_before[0] > 0.0);
    assert!(out.error_after[0] <= out.error_before[0] * 1.1);
    let forms: Vec<(&str, &MapForm)> = out
        .steps
        .iter()
        .map(|s| (s.map.as_str(), &s.form))
        .collect();
    // The checkerboard diffuse stays a texture; the near-reference maps are simplified.
    assert!(!forms.iter().any(|(m, _)| *m == "diffuse"), "{forms:?}");
    assert!(
        forms.contains(&("specular", &MapForm::Grey))
            || matches!(
                forms.iter().find(|(m, _)| *m == "specular"),
                Some((_, MapForm::Constant(_)))
            ),
        "{forms:?}"
    );
    assert!(
        forms.iter().any(|(m, f)| *m == "roughness"
            && matches!(f, MapForm::Constant(v) if (v[0] - 0.5).abs() < 0.01)),
        "{forms:?}"
    );
    assert!(
        forms
            .iter()
            .any(|(m, f)| *m == "normal" && matches!(f, MapForm::Constant(_))),
        "{forms:?}"
    );
    for step in &out.steps {
        let simplified = out.maps.get(&step.map).unwrap();
        match &step.form {
            MapForm::Constant(v) => {
                assert_eq!(constant_value(simplified).unwrap().as_ref(), Some(v))
            }
            MapForm::Grey => assert!(is_grey(simplified).unwrap()),
        }
    }
    assert!(
        constant_value(out.maps.get("diffuse").unwrap())
            .unwrap()
            .is_none()
    );
    // The error of the final maps is the last step's, and the one error_of reported.
    assert_eq!(error_of(&out.maps).unwrap(), out.error_after);
    assert_eq!(out.steps.last().unwrap().error, out.error_after);

    assert!(calls > 4);

    // Every error must stay within its bound: a second error against the maps themselves
    // (0 as they are, so any change breaks it) keeps every map as it is.
    let own = renders(&brdf, &maps);
    let both = simplify(brdf.as_ref(), &maps, 0.1, |m: &MaterialMaps| {
        let r = renders(&brdf, m);
        Ok::<_, photomat_core::Error>(vec![l1(&r, &reference), l1(&r, &own)])
    })
    .unwrap();
    assert!(both.steps.is_empty(), "{:?}", both.steps);
    assert_eq!(both.error_after, both.error_before);
    assert_eq!(both.error_after[1], 0.0);
}

#[test]
fn simplify_refuses_a_bad_tolerance_or_error() {
    let brdf = model("ggx");
    let maps = ggx_maps(0.01, 0.02);
    let ok = |_: &MaterialMaps| Ok::<_, photomat_core::Error>(vec![0.1]);
    let e = simplify(brdf.as_ref(), &maps, -0.5, ok).unwrap_err();
    assert!(e.to_string().contains("tolerance"), "{e}");
    let nan = |_: &MaterialMaps| Ok::<_, photomat_core::Error>(vec![0.1, f64::NAN]);
    let e = simplify(brdf.as_ref(), &maps, 0.1, nan).unwrap_err();
    assert!(e.to_string().contains("NaN"), "{e}");
}

/// The maps of `ggx_maps` with a constant roughness and a grey specular, as simplify makes them.
fn compactable() -> MaterialMaps {
    let mut maps = ggx_maps(0.0, 0.02);
    maps.insert("roughness", map(1, |_, _, _| 0.375));
    maps.insert("specular", map(3, |_, r, c| 0.02 + 0.001 * (r + c) as f32));
    maps
}

#[test]
fn compact_folders_store_values_and_grey_maps_and_load_back_exactly() {
    let brdf = model("ggx");
    let maps = compactable();
    let temp = tempfile::tempdir().unwrap();
    let (full, compact) = (temp.path().join("full"), temp.path().join("compact"));
    let options = SaveOptions {
        compact: true,
        ..SaveOptions::default()
    };
    let written_full = save_maps(&full, brdf.as_ref(), &maps, &SaveOptions::default()).unwrap();
    let written = save_maps(&compact, brdf.as_ref(), &maps, &options).unwrap();
    // folder_bytes predicts what save_maps writes, which is what is on disk.
    assert_eq!(
        written,
        folder_bytes(brdf.as_ref(), &maps, &options).unwrap()
    );
    assert_eq!(
        written_full,
        folder_bytes(brdf.as_ref(), &maps, &SaveOptions::default()).unwrap()
    );
    let on_disk: u64 = std::fs::read_dir(&compact)
        .unwrap()
        .map(|e| e.unwrap().metadata().unwrap().len())
        .sum();
    assert_eq!(on_disk, written);
    assert!(written < written_full);

    let manifest: Value =
        serde_json::from_str(&std::fs::read_to_string(compact.join(MANIFEST_FILE)).unwrap())
            .unwrap();
    let entry = |name: &str| {
        manifest["maps"]
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["name"] == name)
            .unwrap()
            .clone()
    };
    assert_eq!(entry("roughness")["value"], serde_json::json!([0.375]));
    assert!(entry("roughness").get("exr").is_none());
    assert!(!compact.join("roughness.exr").exists() && !compact.join("roughness.png").exists());
    assert_eq!(entry("specular")["grey"], true);
    assert_eq!(png_header(&compact.join("specular.png")).unwrap().0, 1);
    assert!(entry("diffuse").get("grey").is_none() && entry("diffuse").get("value").is_none());

    let loaded = load_maps(&compact, None).unwrap();
    for (name, original) in maps.iter() {
        let back = loaded.maps.get(name).unwrap();
        let diff = l1(original, back);
        assert_eq!(diff, 0.0, "{name}");
    }
}

#[test]
fn compact_manifest_entries_are_checked_naming_the_manifest() {
    let brdf = model("ggx");
    let temp = tempfile::tempdir().unwrap();
    let dir = temp.path();
    let options = SaveOptions {
        compact: true,
        ..SaveOptions::default()
    };
    save_maps(dir, brdf.as_ref(), &compactable(), &options).unwrap();
    let original = std::fs::read_to_string(dir.join(MANIFEST_FILE)).unwrap();
    let error_after = |edit: &dyn Fn(&mut Value)| {
        let mut manifest: Value = serde_json::from_str(&original).unwrap();
        edit(&mut manifest);
        std::fs::write(dir.join(MANIFEST_FILE), manifest.to_string()).unwrap();
        load_maps(dir, None)
            .err()
            .expect("must be refused")
            .to_string()
    };
    let index = |m: &Value, name: &str| {
        m["maps"]
            .as_array()
            .unwrap()
            .iter()
            .position(|e| e["name"] == name)
            .unwrap()
    };
    let e = error_after(&|m| {
        let i = index(m, "roughness");
        m["maps"][i]["value"] = serde_json::json!([0.1, 0.2]);
    });
    assert!(
        e.contains("2 number(s) for 1 channel(s)") && e.contains(MANIFEST_FILE),
        "{e}"
    );
    let e = error_after(&|m| {
        let i = index(m, "roughness");
        m["maps"][i]["value"] = serde_json::json!([7.0]);
    });
    assert!(e.contains("roughness") && e.contains(MANIFEST_FILE), "{e}");
    let e = error_after(&|m| {
        let i = index(m, "roughness");
        m["maps"][i]["exr"] = "roughness.exr".into();
    });
    assert!(
        e.contains("keep one of them") && e.contains(MANIFEST_FILE),
        "{e}"
    );
    let e = error_after(&|m| {
        let i = index(m, "normal");
        m["maps"][i]["grey"] = true.into();
    });
    assert!(e.contains("'grey'") && e.contains(MANIFEST_FILE), "{e}");
    // A grey entry whose files have three channels: the file is named.
    let e = error_after(&|m| {
        let i = index(m, "diffuse");
        m["maps"][i]["grey"] = true.into();
    });
    assert!(e.contains("diffuse.png") && e.contains("a grey map"), "{e}");
}

#[test]
fn sample_simplify_records_the_steps_errors_and_bytes() {
    let temp = tempfile::tempdir().unwrap();
    let model_dir = temp.path().join("model");
    photomat_generator::GanModel::new(&tiny_gan_config(32), 3, &Device::Cpu)
        .unwrap()
        .save(&model_dir, Value::Null)
        .unwrap();
    let brdf = model("height(ggx)");
    photomat_estimator::EstimatorModel::new_seeded(
        brdf.clone(),
        tiny_estimator_config(brdf.channels()),
        3,
        &Device::Cpu,
    )
    .unwrap()
    .save(&model_dir, Value::Null)
    .unwrap();
    let run = |tolerance: &str, out: &Path| {
        photomat(&[
            "sample",
            "--model",
            s(&model_dir),
            "--count",
            "2",
            "--out",
            s(out),
            "--simplify",
            "--tolerance",
            tolerance,
            "--gltf",
        ])
        .unwrap()
    };
    let read =
        |p: &Path| -> Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };

    // A huge tolerance accepts a form for every map: all constant.
    let out = temp.path().join("all");
    let text = run("1000", &out);
    assert!(text.contains("--simplify (tolerance 1000)"), "{text}");
    let summary = read(&out.join("summary.json"));
    let totals = &summary["simplification"];
    for name in ["diffuse", "specular", "roughness", "height"] {
        assert_eq!(totals["counts"][format!("{name}: constant")], 2, "{totals}");
    }
    assert!(totals["bytes_after"].as_u64().unwrap() * 4 < totals["bytes_before"].as_u64().unwrap());
    for m in summary["materials"].as_array().unwrap() {
        let folder = Path::new(m["folder"].as_str().unwrap());
        let manifest = read(&folder.join("material/material.json"));
        let record = &manifest["simplification"];
        assert_eq!(record["steps"].as_array().unwrap().len(), 4, "{record}");
        assert!(
            manifest["maps"]
                .as_array()
                .unwrap()
                .iter()
                .all(|e| e.get("value").is_some())
        );
        // The folder loads, and its renders are what the summary's L1 was measured on.
        let loaded = load_maps(&folder.join("material"), None).unwrap();
        assert!(
            loaded
                .maps
                .iter()
                .all(|(_, t)| constant_value(t).unwrap().is_some())
        );
        // Constant maps export as factors: no texture at all.
        let gltf = read(&folder.join("export/material.gltf"));
        assert!(gltf.get("images").is_none(), "{gltf}");
    }

    // Tolerance 0: only forms that add no error; the record says the error did not grow.
    let out = temp.path().join("strict");
    run("0", &out);
    for m in read(&out.join("summary.json"))["materials"]
        .as_array()
        .unwrap()
    {
        let r = &m["simplification"];
        assert_eq!(r["metrics"], serde_json::json!(["l1_linear", "l1_display"]));
        for i in 0..2 {
            let (before, after) = (&r["error_before"][i], &r["error_after"][i]);
            assert!(after.as_f64().unwrap() <= before.as_f64().unwrap(), "{r}");
        }
    }
}
