//! The `photomat` command line through `photomat_cli::run_with_output`: `brdfs` lists the
//! built-ins with their channel counts, `render` writes the renderer's image and orbit contact
//! sheets, `brdf-eval` matches Lambert's closed form and its gradients match finite
//! differences of its own values, `capture --fov` sets the captured square's side
//! and `capture --brdf auto` writes the model it chose.

use photomat_tests as _;

use std::f64::consts::PI;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use photomat_core::image_io::{PlanarImage, PngBits, read_png};
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::sheet::CONTACT_SHEET_GAP;
use photomat_core::{Highlight, MaterialMaps, registered_names, render};
use photomat_tests::cli_fixtures::{photomat, photomat_error};
use photomat_tests::{expected_builtins, model, random_maps, rng};
use serde_json::{Value, json};

/// A saved random `spec` material of size R in a fresh folder.
fn material(spec: &str, size: usize) -> (tempfile::TempDir, MaterialMaps) {
    let brdf = model(spec);
    let maps = random_maps(&brdf, &mut rng(11), size, 0.1, DType::F32);
    let dir = tempfile::tempdir().unwrap();
    save_maps(dir.path(), brdf.as_ref(), &maps, &SaveOptions::default()).unwrap();
    (dir, maps)
}

fn path_str(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Run brdf-eval on `cases` (a JSON value) and parse the output.
fn brdf_eval(spec: &str, cases: &Value, extra: &[&str]) -> Value {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cases.json");
    std::fs::write(&file, cases.to_string()).unwrap();
    let mut args = vec!["brdf-eval", "--brdf", spec, "--cases", path_str(&file)];
    args.extend_from_slice(extra);
    serde_json::from_str(&photomat(&args).unwrap()).unwrap()
}

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn cli_registry_has_the_builtins() {
    assert_eq!(registered_names().unwrap(), expected_builtins());
}

#[test]
fn cli_brdfs_lists_builtins_with_channel_counts() {
    let listing: Value = serde_json::from_str(&photomat(&["brdfs", "--json"]).unwrap()).unwrap();
    let models = listing["models"].as_array().unwrap();
    let names: Vec<&str> = models.iter().map(|m| m["name"].as_str().unwrap()).collect();
    assert_eq!(names, expected_builtins());
    let by_name = |name: &str| models.iter().find(|m| m["name"] == name).unwrap();
    assert_eq!(by_name("ggx")["channels"], 10);
    assert_eq!(by_name("coated")["channels"], 11);
    assert_eq!(by_name("lambert")["channels"], 6);
    let height = by_name("height");
    assert_eq!(height["adapter"], true);
    assert_eq!(height["replaces"], json!(["normal"]));
    assert_eq!(height["channels"], Value::Null);
    assert_eq!(height["example"]["spec"], "height(ggx)");
    assert_eq!(height["example"]["channels"], 8);
    assert_eq!(height["args"][0]["name"], "scale");
    assert_eq!(height["args"][0]["default"], 0.02);
    assert_eq!(height["args"][0]["range"], json!([0.0, 1.0]));
    let shadowing = &by_name("ggx")["args"][0];
    assert_eq!(shadowing["name"], "shadowing");
    assert_eq!(shadowing["default"], "separable");
    assert_eq!(
        shadowing["choices"],
        json!(["separable", "correlated", "implicit"])
    );
    assert_eq!(shadowing.get("range"), None);

    // Parameter tables: every spec field, defaults in their shortest decimal form.
    let roughness = &by_name("ggx")["params"][2];
    assert_eq!(roughness["name"], "roughness");
    assert_eq!(roughness["channels"], 1);
    assert_eq!(roughness["range"], json!([0.0, 1.0]));
    assert_eq!(roughness["encoding"], "linear");
    assert_eq!(roughness["default"], json!([0.5]));
    assert_eq!(roughness["differentiable"], true);
    assert!(roughness["doc"].as_str().unwrap().contains("roughness"));
    assert_eq!(
        by_name("ggx")["params"][1]["default"],
        json!([0.04, 0.04, 0.04])
    );

    let text = photomat(&["brdfs"]).unwrap();
    for line in [
        "coated  (n = 11)",
        "ggx  (n = 10)",
        "lambert  (n = 6)",
        "height(ggx): n = 8",
    ] {
        assert!(text.contains(line), "missing '{line}' in:\n{text}");
    }
}

#[test]
fn cli_render_light_matches_the_core_renderer() {
    let size = 24;
    let (dir, maps) = material("ggx", size);
    let out = dir.path().join("render.png");
    let printed = photomat(&[
        "render",
        "--maps",
        path_str(dir.path()),
        "--light",
        "-0.2,0.1",
        "--out",
        path_str(&out),
    ])
    .unwrap();
    assert!(printed.contains("render.png"), "{printed}");
    let (image, bits) = read_png(&out).unwrap();
    assert_eq!(bits, PngBits::Eight);
    assert_eq!((image.channels, image.height, image.width), (3, size, size));
    // The PNG is the display-encoded render, quantised to 8 bits.
    let expected = render(model("ggx").as_ref(), &maps, &[Highlight::new(-0.2, 0.1)]).unwrap();
    let expected = PlanarImage::from_tensor(&expected).unwrap();
    for (got, want) in image.data.iter().zip(&expected.data) {
        assert!((got - want).abs() <= 0.5 / 255.0 + 1e-6, "{got} vs {want}");
    }
}

#[test]
fn cli_render_flat_white_lambert_is_white_under_the_flash() {
    // A flat white Lambertian texel straight under the flash renders exactly 1
    // (`docs/conventions.md`, "Radiance").
    let size = 8;
    let brdf = model("lambert");
    let maps = MaterialMaps::defaults(brdf.params(), 1, size, DType::F32, &Device::Cpu)
        .unwrap()
        .with(
            "diffuse",
            Tensor::ones((1, 3, size, size), DType::F32, &Device::Cpu).unwrap(),
        );
    let dir = tempfile::tempdir().unwrap();
    save_maps(dir.path(), brdf.as_ref(), &maps, &SaveOptions::default()).unwrap();
    let out = dir.path().join("white.png");
    // Highlight on the centre of texel (row 2, col 5).
    let light = format!("{},{}", 5.5 / size as f64 - 0.5, 0.5 - 2.5 / size as f64);
    photomat(&[
        "render",
        "--maps",
        path_str(dir.path()),
        "--light",
        &light,
        "--out",
        path_str(&out),
    ])
    .unwrap();
    let (image, _) = read_png(&out).unwrap();
    for c in 0..3 {
        assert_eq!(image.get(c, 2, 5), 1.0);
        assert!(image.get(c, 7, 0) < 0.97, "corners are darker");
    }
}

#[test]
fn cli_render_orbit_writes_a_contact_sheet() {
    let size = 16;
    let (dir, maps) = material("height(ggx)", size);
    let out = dir.path().join("sheet.png");
    photomat(&[
        "render",
        "--maps",
        path_str(dir.path()),
        "--orbit",
        "4",
        "--out",
        path_str(&out),
    ])
    .unwrap();
    let (sheet, _) = read_png(&out).unwrap();
    let side = 2 * size + CONTACT_SHEET_GAP;
    assert_eq!((sheet.channels, sheet.height, sheet.width), (3, side, side));
    // Tile 1 (top right) is the render at θ = 135°, radius 0.35.
    let d = 0.35 / 2f64.sqrt();
    let tile = render(
        model("height(ggx)").as_ref(),
        &maps,
        &[Highlight::new(-d, d)],
    )
    .unwrap();
    let tile = PlanarImage::from_tensor(&tile).unwrap();
    let left = size + CONTACT_SHEET_GAP;
    for (row, col) in [(0, 0), (3, 7), (size - 1, size - 1)] {
        for c in 0..3 {
            let got = sheet.get(c, row, left + col);
            assert!((got - tile.get(c, row, col)).abs() <= 0.5 / 255.0 + 1e-6);
        }
    }
    // The gap is black.
    assert_eq!(sheet.get(0, 0, size), 0.0);

    // Five highlights: 3 columns, 2 rows.
    photomat(&[
        "render",
        "--maps",
        path_str(dir.path()),
        "--orbit",
        "5",
        "--radius",
        "0.2",
        "--out",
        path_str(&out),
    ])
    .unwrap();
    let (sheet, _) = read_png(&out).unwrap();
    assert_eq!(
        (sheet.height, sheet.width),
        (
            2 * size + CONTACT_SHEET_GAP,
            3 * size + 2 * CONTACT_SHEET_GAP
        )
    );
}

#[test]
fn cli_render_brdf_override_renders_a_subset_of_the_maps() {
    let (dir, maps) = material("ggx", 8);
    let out = dir.path().join("matte.png");
    photomat(&[
        "render",
        "--maps",
        path_str(dir.path()),
        "--brdf",
        "lambert",
        "--light",
        "0,0",
        "--out",
        path_str(&out),
    ])
    .unwrap();
    let (image, _) = read_png(&out).unwrap();
    let mut lambert_maps = MaterialMaps::new();
    for name in ["diffuse", "normal"] {
        lambert_maps.insert(name, maps.get(name).unwrap().clone());
    }
    let expected = render(
        model("lambert").as_ref(),
        &lambert_maps,
        &[Highlight::CENTER],
    )
    .unwrap();
    let expected = PlanarImage::from_tensor(&expected).unwrap();
    for (got, want) in image.data.iter().zip(&expected.data) {
        assert!((got - want).abs() <= 0.5 / 255.0 + 1e-6);
    }
}

#[test]
fn cli_render_bad_arguments_are_clear_errors() {
    let (dir, _) = material("lambert", 4);
    let maps = path_str(dir.path());
    let out = dir.path().join("x.png");
    let out = path_str(&out);

    let err = photomat_error(&["render", "--maps", maps, "--light", "0.1", "--out", out]);
    assert!(err.contains("expected X,Y"), "{err}");
    let err = photomat_error(&["render", "--maps", maps, "--out", out]);
    assert!(err.contains("--light") && err.contains("--orbit"), "{err}");
    let err = photomat_error(&[
        "render", "--maps", maps, "--light", "0,0", "--orbit", "3", "--out", out,
    ]);
    assert!(err.contains("cannot be used with"), "{err}");
    let err = photomat_error(&["render", "--maps", maps, "--orbit", "0", "--out", out]);
    assert!(err.contains("--orbit"), "{err}");
    let err = photomat_error(&["render", "--maps", maps, "--light", "0,0", "--out", "x.jpg"]);
    assert!(err.contains(".png"), "{err}");
    let err = photomat_error(&[
        "render", "--maps", maps, "--light", "0,0", "--brdf", "phong", "--out", out,
    ]);
    assert!(
        err.contains("--brdf") && err.contains(&expected_builtins().join(", ")),
        "{err}"
    );

    // A folder without a manifest: the chain names the folder and the manifest.
    let empty = tempfile::tempdir().unwrap();
    let err = photomat_error(&[
        "render",
        "--maps",
        path_str(empty.path()),
        "--light",
        "0,0",
        "--out",
        out,
    ]);
    assert!(err.starts_with("error: cannot load the material"), "{err}");
    assert!(
        err.contains("caused by:") && err.contains("material.json"),
        "{err}"
    );
}

#[test]
fn cli_brdf_eval_lambert_matches_closed_form() {
    let cases = json!({"cases": [
        {"wi": [0, 0, 1], "wo": [0, 0, 1], "params": {"diffuse": [1, 0.5, 0.25]}},
        {"wi": [0.3, -0.2, 0.9], "wo": [0.6, 0, 0.8], "params": {"diffuse": [0.2, 0.7, 0.9]}},
        {"wi": [0, 0.5, 0.5], "wo": [-0.1, -0.9, 0.3], "params": {"diffuse": [0.8, 0.1, 0.4]}},
        {"wi": [0, 0, 1], "wo": [0, 0.6, -0.8], "params": {"diffuse": [0.8, 0.1, 0.4]}}
    ]});
    for precision in [&[][..], &["--f64"][..]] {
        let mut extra = vec!["--grad"];
        extra.extend_from_slice(precision);
        let out = brdf_eval("lambert", &cases, &extra);
        assert_eq!(out["brdf"], "lambert");
        let tol = if precision.is_empty() { 1e-6 } else { 1e-12 };
        for (k, case) in out["cases"].as_array().unwrap().iter().enumerate() {
            let input = &cases["cases"][k];
            let wo = vec_of(&input["wo"]);
            let cos = wo[2] / wo.iter().map(|x| x * x).sum::<f64>().sqrt();
            let albedo = vec_of(&input["params"]["diffuse"]);
            let value = vec_of(&case["value"]);
            let jac = &case["grad"]["diffuse"];
            for o in 0..3 {
                let expected = if cos > 0.0 { albedo[o] / PI * cos } else { 0.0 };
                assert!((value[o] - expected).abs() <= tol, "case {k}: {value:?}");
                for c in 0..3 {
                    // ∂(ρ_o cos/π)/∂ρ_c = δ_oc·cos/π above the horizon, 0 below.
                    let want = if o == c && cos > 0.0 { cos / PI } else { 0.0 };
                    let got = jac[o][c].as_f64().unwrap();
                    assert!(
                        (got - want).abs() <= tol,
                        "case {k}: grad[{o}][{c}] = {got}"
                    );
                }
            }
            if cos > 0.0 {
                let f = vec_of(&case["f"]);
                for o in 0..3 {
                    assert!((f[o] - albedo[o] / PI).abs() <= tol);
                }
            } else {
                assert_eq!(case["f"], Value::Null);
            }
            // The default normal was used and echoed.
            assert_eq!(vec_of(&case["params"]["normal"]), [0.0, 0.0, 1.0]);
        }
    }
}

#[test]
fn cli_brdf_eval_ggx_grad_matches_finite_differences() {
    let base = json!({
        "diffuse": [0.3, 0.5, 0.7],
        "specular": [0.9, 0.6, 0.2],
        "roughness": [0.35],
        "normal": [0.1, -0.15, 0.98]
    });
    let dirs = [
        ([0.2, 0.1, 0.97], [-0.1, 0.25, 0.96]),
        ([0.5, -0.3, 0.81], [0.1, 0.4, 0.91]),
    ];
    let cases_with = |params: &Value| json!({"cases": dirs.iter().map(|(wi, wo)| json!({"wi": wi, "wo": wo, "params": params})).collect::<Vec<_>>()});
    let out = brdf_eval("ggx", &cases_with(&base), &["--grad", "--f64"]);
    // Central differences in f64: h = 1e-5 gives truncation O(h²) ≈ 1e-10 and rounding
    // O(ε/h) ≈ 1e-11, far below the 1e-6 tolerance.
    let h = 1e-5;
    let mut checked = 0;
    for (name, values) in base.as_object().unwrap() {
        for c in 0..values.as_array().unwrap().len() {
            let shifted = |delta: f64| {
                let mut p = base.clone();
                p[name][c] = json!(p[name][c].as_f64().unwrap() + delta);
                brdf_eval("ggx", &cases_with(&p), &["--f64"])
            };
            let (plus, minus) = (shifted(h), shifted(-h));
            for k in 0..dirs.len() {
                let vp = vec_of(&plus["cases"][k]["value"]);
                let vm = vec_of(&minus["cases"][k]["value"]);
                for o in 0..3 {
                    let fd = (vp[o] - vm[o]) / (2.0 * h);
                    let grad = out["cases"][k]["grad"][name][o][c].as_f64().unwrap();
                    let scale = fd.abs().max(grad.abs()).max(1e-3);
                    assert!(
                        (fd - grad).abs() <= 1e-6 * scale.max(1.0),
                        "case {k}, ∂value[{o}]/∂{name}[{c}]: autodiff {grad}, finite difference {fd}"
                    );
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 10 * 3 * dirs.len());
}

#[test]
fn cli_brdf_eval_cases_are_independent_texels() {
    // height(ggx) cases must not see each other's heights: a lone texel has no slope, so
    // every case equals plain ggx with a flat normal, whatever the heights.
    let case = |h: f64| json!({"wi": [0.3, 0.1, 0.95], "wo": [-0.2, 0.3, 0.93], "params": {"height": h, "roughness": 0.4}});
    let out = brdf_eval(
        "height(ggx, scale=1)",
        &json!({"cases": [case(0.0), case(1.0), case(0.2)]}),
        &["--f64"],
    );
    let flat = brdf_eval(
        "ggx",
        &json!({"cases": [{"wi": [0.3, 0.1, 0.95], "wo": [-0.2, 0.3, 0.93], "params": {"roughness": [0.4]}}]}),
        &["--f64"],
    );
    let want = vec_of(&flat["cases"][0]["value"]);
    for k in 0..3 {
        let got = vec_of(&out["cases"][k]["value"]);
        for o in 0..3 {
            assert!(
                (got[o] - want[o]).abs() < 1e-12,
                "case {k}: {got:?} vs {want:?}"
            );
        }
    }
    assert_eq!(out["brdf"], "height(ggx, scale=1)");
}

#[test]
fn cli_brdf_eval_echoes_defaults_and_reports_f_against_the_case_normal() {
    let out = brdf_eval(
        "ggx",
        &json!({"cases": [{"wi": [0, 0, 2], "wo": [0, 0.8, 0.6], "params": {"normal": [0, 0.6, 0.8]}}]}),
        &[],
    );
    let case = &out["cases"][0];
    assert_eq!(out["dtype"], "f32");
    assert_eq!(
        vec_of(&case["wi"]),
        [0.0, 0.0, 1.0],
        "directions are normalised"
    );
    assert_eq!(vec_of(&case["params"]["roughness"]), [0.5]);
    assert_eq!(vec_of(&case["params"]["specular"]), [0.04; 3]);
    assert!(case.get("grad").is_none());
    // cos θ_o w.r.t. the case's normal: (0, 0.6, 0.8)·(0, 0.8, 0.6) = 0.96.
    let (value, f) = (vec_of(&case["value"]), vec_of(&case["f"]));
    for o in 0..3 {
        assert!((f[o] * 0.96 - value[o]).abs() < 1e-6 * value[o].abs().max(1.0));
    }
}

#[test]
fn cli_brdf_eval_rejects_malformed_cases() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cases.json");
    let run = |cases: Value| {
        std::fs::write(&file, cases.to_string()).unwrap();
        photomat_error(&["brdf-eval", "--brdf", "ggx", "--cases", path_str(&file)])
    };
    let err = run(json!({"cases": [{"wi": [0, 1], "wo": [0, 0, 1]}]}));
    assert!(
        err.contains("case 0") && err.contains("'wi' must be a 3-vector"),
        "{err}"
    );
    let err = run(
        json!({"cases": [{"wi": [0, 0, 1], "wo": [0, 0, 1]}, {"wi": [0, 0, 1], "wo": [0, 0, 1], "params": {"difuse": [1, 1, 1]}}]}),
    );
    assert!(
        err.contains("case 1") && err.contains("unknown parameter 'difuse'"),
        "{err}"
    );
    assert!(
        err.contains("valid: diffuse, specular, roughness, normal"),
        "{err}"
    );
    let err = run(
        json!({"cases": [{"wi": [0, 0, 1], "wo": [0, 0, 1], "params": {"roughness": [0.1, 0.2]}}]}),
    );
    assert!(err.contains("'roughness' has 1 channel(s), got 2"), "{err}");
    let err =
        run(json!({"cases": [{"wi": [0, 0, 1], "wo": [0, 0, 1], "params": {"roughness": -5}}]}));
    assert!(
        err.contains("'roughness' has the value -5, outside its range [0, 1]"),
        "{err}"
    );
    let err = run(json!({"cases": [{"wi": [0, 0, 1], "wo": [0, 0, 0]}]}));
    assert!(err.contains("'wo'"), "{err}");
    let err = run(json!({"cases": []}));
    assert!(err.contains("no cases"), "{err}");
    let err = run(json!({"cases": [{"wi": [0, 0, 1], "wo": [0, 0, 1], "parms": {}}]}));
    assert!(
        err.contains("not a valid cases file") && err.contains("parms"),
        "{err}"
    );
    let err = photomat_error(&[
        "brdf-eval",
        "--brdf",
        "ggx",
        "--cases",
        "/nonexistent/cases.json",
    ]);
    assert!(err.contains("/nonexistent/cases.json"), "{err}");
}

#[test]
fn map_stats_measures_the_normal_spread_of_a_derived_normal() {
    // Heights h = ½ + A sin(2π x / N) along x: the height adapter's wrap-around central
    // difference g = (h[i+1] − h[i−1]) / (2·texel) tilts texel i's normal by atan(scale·|g|)
    // around the mean normal +z (the tilts cancel in pairs); the heights' std is A/√2.
    let brdf = model("height(ggx, scale=1)");
    let (size, amplitude) = (16, 0.05);
    let texel = 1.0 / size as f64;
    let mut maps = MaterialMaps::defaults(brdf.params(), 1, size, DType::F32, &Device::Cpu)
        .unwrap()
        .with_texel_size(Some(texel));
    let h = |x: usize| 0.5 + amplitude * (2.0 * PI * (x % size) as f64 / size as f64).sin();
    let heights: Vec<f32> = (0..size * size).map(|i| h(i % size) as f32).collect();
    maps.insert(
        "height",
        Tensor::from_vec(heights, (1, 1, size, size), &Device::Cpu).unwrap(),
    );
    let dir = tempfile::tempdir().unwrap();
    save_maps(
        &dir.path().join("wave"),
        brdf.as_ref(),
        &maps,
        &SaveOptions::default(),
    )
    .unwrap();
    let out = photomat(&["map-stats", path_str(dir.path()), "--json"]).unwrap();
    let report: Value = serde_json::from_str(&out).unwrap();
    let spread = &report["materials"][0]["spread"];
    let height = spread["maps"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["name"] == "height")
        .unwrap();
    let std = height["std"][0].as_f64().unwrap();
    assert!((std - amplitude / 2f64.sqrt()).abs() < 1e-6, "{std}");
    let tilts: Vec<f64> = (0..size)
        .map(|x| ((h(x + 1) - h(x + size - 1)) / (2.0 * texel)).abs().atan())
        .collect();
    let rms = (tilts.iter().map(|t| t * t).sum::<f64>() / size as f64)
        .sqrt()
        .to_degrees();
    let measured = spread["normal_angle_rms_deg"].as_f64().unwrap();
    assert!((measured - rms).abs() < 1e-3, "{measured}° vs {rms}°");
    assert!(spread["normal_mean_tilt_deg"].as_f64().unwrap() < 1e-3);
}

#[test]
fn cli_capture_takes_the_field_of_view_and_refuses_one_out_of_range() {
    // A 48² render of a constant ggx material with the flash above the centre, in the training
    // geometry (side 2).
    let brdf = model("ggx");
    let device = Device::Cpu;
    let size = 48;
    let maps = MaterialMaps::defaults(brdf.params(), 1, size, DType::F32, &device).unwrap();
    let geometry = photomat_core::FlashGeometry::with_side(
        &[Highlight::new(0.0, 0.0)],
        size,
        2.0,
        DType::F32,
        &device,
    )
    .unwrap();
    let radiance = render::render_radiance_with(brdf.as_ref(), &maps, &geometry).unwrap();
    let image = photomat_core::encode_display(&radiance)
        .unwrap()
        .squeeze(0)
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("photo.png");
    photomat_core::image_io::write_png(
        &photo,
        &PlanarImage::from_tensor(&image).unwrap(),
        PngBits::Eight,
    )
    .unwrap();
    let out = dir.path().join("captured");
    let printed = photomat(&[
        "capture",
        path_str(&photo),
        "--brdf",
        "ggx",
        "--out",
        path_str(&out),
        "--size",
        "32",
        "--steps",
        "3",
        "--fov",
        "60",
    ])
    .unwrap();
    assert!(
        printed.contains("from a 60.0° field of view (given)"),
        "{printed}"
    );
    let record: Value =
        serde_json::from_slice(&std::fs::read(out.join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["fov_source"]["kind"], "given", "{record}");
    let side = 2.0 * (30f64).to_radians().tan();
    assert!(
        (record["side"].as_f64().unwrap() - side).abs() < 1e-9,
        "{record}"
    );
    assert!(
        (record["texel_size"].as_f64().unwrap() - side / 32.0).abs() < 1e-9,
        "{record}"
    );
    assert!(out.join("relit.png").is_file());

    // --known: the capture's own ggx folder held in a height model, which takes its diffuse,
    // specular and roughness maps and not its normal map (a note says so); the fit keeps
    // them and capture.json lists them.
    let again = dir.path().join("again");
    let material = out.join("material");
    let printed = photomat(&[
        "capture",
        path_str(&photo),
        "--brdf",
        "height(ggx)",
        "--out",
        path_str(&again),
        "--size",
        "32",
        "--steps",
        "3",
        "--known",
        path_str(&material),
    ])
    .unwrap();
    assert!(
        printed.contains("note: --known: normal of") && printed.contains("not held"),
        "{printed}"
    );
    let record: Value =
        serde_json::from_slice(&std::fs::read(again.join("capture.json")).unwrap()).unwrap();
    assert_eq!(
        record["known_maps"],
        serde_json::json!(["diffuse", "roughness", "specular"]),
        "{record}"
    );
    let held = photomat_core::map_files::load_maps(&material, None)
        .unwrap()
        .maps;
    let fitted = photomat_core::map_files::load_maps(&again.join("material"), None)
        .unwrap()
        .maps;
    for name in ["diffuse", "roughness", "specular"] {
        let worst = photomat_kernels::testing::max_abs_diff(
            held.get(name).unwrap(),
            fitted.get(name).unwrap(),
        )
        .unwrap();
        assert!(worst < 1e-3, "{name} off by {worst}");
    }
    let err = photomat_error(&[
        "capture",
        path_str(&photo),
        "--brdf",
        "ggx",
        "--out",
        path_str(&dir.path().join("bigger")),
        "--size",
        "64",
        "--known",
        path_str(&material),
    ]);
    assert!(
        err.contains("known map") && err.contains("64, 64]"),
        "{err}"
    );

    let err = photomat_error(&[
        "capture",
        path_str(&photo),
        "--brdf",
        "ggx",
        "--out",
        path_str(&dir.path().join("other")),
        "--fov",
        "200",
    ]);
    assert!(err.contains("'200'") && err.contains("5 … 150"), "{err}");

    // --model: the bundled folder has no `ggx` estimator, so the fit starts from constant
    // maps and says so; it has a `lambert` one, whose prior capture.json records.
    let bundled = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/demo");
    let capture_with_model = |brdf: &str, out: &std::path::Path| {
        photomat(&[
            "capture",
            path_str(&photo),
            "--brdf",
            brdf,
            "--out",
            path_str(out),
            "--size",
            "32",
            "--steps",
            "2",
            "--prior-steps",
            "3",
            "--model",
            path_str(&bundled),
        ])
        .unwrap()
    };
    let no_estimator = dir.path().join("ggx-prior");
    let printed = capture_with_model("ggx", &no_estimator);
    assert!(
        printed.contains("has no estimator for ggx: fitting from constant maps"),
        "{printed}"
    );
    let record: Value =
        serde_json::from_slice(&std::fs::read(no_estimator.join("capture.json")).unwrap()).unwrap();
    assert!(record["prior"].is_null(), "{record}");
    let with_prior = dir.path().join("lambert-prior");
    let printed = capture_with_model("lambert", &with_prior);
    assert!(printed.contains("generator prior from"), "{printed}");
    let record: Value =
        serde_json::from_slice(&std::fs::read(with_prior.join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["prior"]["steps"], 3, "{record}");
    assert_eq!(record["steps"], 2, "{record}");

    // --brdf auto: the folder's three estimators are the candidates; the chosen one is the
    // model of the maps written.
    let auto = dir.path().join("auto");
    let printed = capture_with_model("auto", &auto);
    assert!(
        printed.contains("--brdf auto (tolerance 0.1):"),
        "{printed}"
    );
    let record: Value =
        serde_json::from_slice(&std::fs::read(auto.join("capture.json")).unwrap()).unwrap();
    let chosen = record["selection"]["chosen"].as_str().unwrap().to_string();
    assert_eq!(
        record["selection"]["candidates"].as_array().unwrap().len(),
        3
    );
    assert_eq!(record["brdf"], chosen.as_str(), "{record}");
    let manifest: Value = serde_json::from_slice(
        &std::fs::read(auto.join("material").join("material.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(manifest["brdf"], chosen.as_str(), "{manifest}");
}
