//! `photomat_capture::capture_with_prior` with the bundled model folder's generator prior: the
//! inversion's loss falls, its decoded maps start the refinement, the steps are reported in
//! order, capture.json records the prior, and the folder's estimators decide which models the
//! prior can serve, and `capture_auto` chooses among them.

use std::path::PathBuf;

use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _; // link the built-in models
use photomat_capture::{
    CaptureOptions, Exports, GanPrior, PriorOptions, TRAINING_FOV_DEGREES, capture_auto,
    capture_with_prior, write_capture,
};
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::image_io::{PlanarImage, PngBits, encode_png, png_header};
use photomat_core::render::render_radiance_with;
use photomat_core::{FlashGeometry, Highlight, MaterialMaps, encode_display, lookup};

const SIZE: usize = 64;

fn bundled_model() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("models")
        .join("demo")
}

/// A rough, striped `ggx` material photographed with the flash above pixel (30, 34) on the
/// training data's square of side 2: PNG bytes.
fn photo() -> Vec<u8> {
    let brdf = lookup("ggx").unwrap();
    let device = Device::Cpu;
    let mut maps = MaterialMaps::defaults(brdf.params(), 1, SIZE, DType::F32, &device).unwrap();
    let stripes: Vec<f32> = (0..3 * SIZE * SIZE)
        .map(|i| 0.3 + 0.2 * (((i % SIZE) / 4) % 2) as f32 + 0.05 * (i / (SIZE * SIZE)) as f32)
        .collect();
    maps.insert(
        "diffuse",
        Tensor::from_vec(stripes, (1, 3, SIZE, SIZE), &device).unwrap(),
    );
    let maps = maps.with_texel_size(Some(PHOTO_SIDE / SIZE as f64));
    let light = Highlight::from_pixel_on(30.0, 34.0, SIZE, PHOTO_SIDE);
    let geometry =
        FlashGeometry::with_side(&[light], SIZE, PHOTO_SIDE, DType::F32, &device).unwrap();
    let image = encode_display(&render_radiance_with(brdf.as_ref(), &maps, &geometry).unwrap())
        .unwrap()
        .squeeze(0)
        .unwrap();
    encode_png(&PlanarImage::from_tensor(&image).unwrap(), PngBits::Eight).unwrap()
}

fn options(size: usize) -> CaptureOptions {
    CaptureOptions {
        size,
        steps: 10,
        fov_degrees: Some(TRAINING_FOV_DEGREES),
        ..CaptureOptions::default()
    }
}

#[test]
fn the_prior_inverts_the_generator_and_starts_the_refinement() {
    let brdf = lookup("height(ggx, scale=0.02)").unwrap();
    let prior = GanPrior::open(&bundled_model(), &brdf, &Device::Cpu)
        .unwrap()
        .expect("the bundled model has an estimator for height(ggx, scale=0.02)");
    assert_eq!(prior.size_multiple(), 32, "E's stride");
    let prior_options = PriorOptions {
        steps: 12,
        ..PriorOptions::default()
    };
    let mut steps = Vec::new();
    let result = capture_with_prior(
        &photo(),
        "rendered.png",
        &brdf,
        &options(SIZE),
        Some((&prior, &prior_options)),
        &mut |step, _| steps.push(step),
    )
    .unwrap();
    // Inversion steps first, then the refinement's, counted on.
    assert_eq!(steps, (1..=22).collect::<Vec<_>>());
    let used = result.prior.as_ref().expect("the prior was used");
    let losses = &used.inversion.losses;
    assert_eq!(losses.len(), 12);
    assert!(
        losses[11] < losses[0],
        "inversion loss {} → {}",
        losses[0],
        losses[11]
    );
    // E's maps are the model's maps at the capture's size, and the refinement starts there:
    // its first loss is their render's error (plus the TV prior), not a constant material's.
    for spec in brdf.params() {
        let map = used.maps.get(spec.name).unwrap();
        assert_eq!(map.dims(), &[1, spec.channels, SIZE, SIZE], "{}", spec.name);
    }
    let (before, after) = (result.losses[0], *result.losses.last().unwrap());
    assert!(after < before, "refinement loss {before} → {after}");

    let dir = tempfile::tempdir().unwrap();
    let textures = write_capture(&result, dir.path(), Exports::default()).unwrap();
    // A height model's capture still gives renderers a normal map: the derived one.
    assert_eq!(textures.normal.as_deref(), Some("normal.png"));
    let (_, height, width) = png_header(&dir.path().join("export/normal.png")).unwrap();
    assert_eq!((height, width), (SIZE, SIZE));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["prior"]["steps"], 12);
    let recorded_first = record["prior"]["loss_first"].as_f64().unwrap();
    assert!((recorded_first - losses[0]).abs() < 1e-12);
    // The sheet has five panels: photo | M's relighting | E's maps | re-render | error.
    let tiles = vec![PlanarImage::filled(3, SIZE, SIZE, 0.0); 5];
    let expected = photomat_core::sheet::grid(&[tiles], 0.0).unwrap();
    let (_, height, width) = png_header(&dir.path().join("sheet.png")).unwrap();
    assert_eq!((height, width), (expected.height, expected.width));
}

#[test]
fn the_prior_serves_only_the_models_the_folder_has_estimators_for() {
    let dir = bundled_model();
    for (spec, has) in [
        ("height(ggx, scale=0.02)", true),
        ("lambert", true),
        ("coated", true),
        ("ggx", false),
        ("height(ggx, scale=0.05)", false), // another scale is another model
    ] {
        let brdf = lookup(spec).unwrap();
        let prior = GanPrior::open(&dir, &brdf, &Device::Cpu).unwrap();
        assert_eq!(prior.is_some(), has, "{spec}");
    }
}

#[test]
fn a_prior_capture_names_the_sizes_it_takes() {
    let brdf = lookup("lambert").unwrap();
    let prior = GanPrior::open(&bundled_model(), &brdf, &Device::Cpu)
        .unwrap()
        .unwrap();
    let error = capture_with_prior(
        &photo(),
        "rendered.png",
        &brdf,
        &options(48),
        Some((&prior, &PriorOptions::default())),
        &mut |_, _| {},
    )
    .err()
    .expect("48 is not a multiple of 32");
    let message = format!("{error:#}");
    assert!(
        message.contains("multiple of 32") && message.contains("--size 32 or 64"),
        "{message}"
    );
}

#[test]
fn auto_refines_the_cheapest_model_within_the_tolerance_and_records_every_candidate() {
    let prior = GanPrior::open_all(&bundled_model(), &Device::Cpu).unwrap();
    let names: Vec<String> = prior.estimators().iter().map(|e| e.brdf().name()).collect();
    // Cheapest first: 6, 8 and 11 map channels.
    assert_eq!(names, ["lambert", "height(ggx, scale=0.02)", "coated"]);
    let prior_options = PriorOptions {
        steps: 8,
        ..PriorOptions::default()
    };
    let run = |tolerance: f64| {
        capture_auto(
            &photo(),
            "rendered.png",
            &options(SIZE),
            (&prior, &prior_options),
            tolerance,
            &mut |_, _| {},
        )
        .unwrap()
    };
    // Any model passes an unbounded tolerance: the cheapest is refined.
    let loose = run(f64::INFINITY);
    let selection = loose.selection.as_ref().unwrap();
    assert_eq!(selection.chosen, "lambert");
    assert_eq!(loose.brdf.name(), "lambert");
    let errors: Vec<f64> = selection.candidates.iter().map(|c| c.l1_linear).collect();
    assert_eq!(selection.candidates.len(), 3);
    assert!(
        errors.iter().all(|e| e.is_finite() && *e > 0.0),
        "{errors:?}"
    );
    // At tolerance 0 only the best passes: the same inversion (same seed), so the same errors.
    let strict = run(0.0);
    let strict_selection = strict.selection.as_ref().unwrap();
    let strict_errors: Vec<f64> = strict_selection
        .candidates
        .iter()
        .map(|c| c.l1_linear)
        .collect();
    assert_eq!(strict_errors, errors);
    let best = errors
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .unwrap()
        .0;
    assert_eq!(strict_selection.chosen, names[best]);
    assert_eq!(strict.brdf.name(), names[best]);
    // The folder records the choice in capture.json and material.json.
    let dir = tempfile::tempdir().unwrap();
    write_capture(&strict, dir.path(), Exports::default()).unwrap();
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["selection"]["chosen"], names[best].as_str());
    let loaded = photomat_core::map_files::load_maps(&dir.path().join("material"), None).unwrap();
    assert_eq!(loaded.brdf.name(), names[best]);
    assert_eq!(
        loaded.manifest.selection.unwrap()["chosen"],
        names[best].as_str()
    );
}
