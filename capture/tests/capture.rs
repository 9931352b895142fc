//! `photomat_capture::capture` on a photo rendered from known maps under a known flash: the
//! loss falls, the re-render matches, the highlight is found, the output folder loads back,
//! the field of view sets the geometry (the right one relights the fit closer to the truth
//! under new flash positions than a wrong one), and bad inputs fail naming the file.

use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _; // link the built-in models
use photomat_capture::{
    CaptureOptions, DEFAULT_FOV_DEGREES, Exports, FovSource, TRAINING_FOV_DEGREES, capture,
    new_flash_positions, relight, square_side, write_capture,
};
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::image_io::{PlanarImage, PngBits, encode_png, png_header};
use photomat_core::map_files::load_maps;
use photomat_core::render::render_radiance_with;
use photomat_core::{FlashGeometry, Highlight, MaterialMaps, encode_display, lookup};
use photomat_data::dataset::lens::{LensRecord, fov_from_35mm_equivalent};
use photomat_kernels::testing::max_abs_diff;

const SIZE: usize = 64;

/// A ggx material with checked albedos and rougher stripes: its maps.
fn truth() -> MaterialMaps {
    let brdf = lookup("ggx").unwrap();
    let device = Device::Cpu;
    let mut maps = MaterialMaps::defaults(brdf.params(), 1, SIZE, DType::F32, &device).unwrap();
    // 8-texel checks of two albedos (no brightness trend to pull the detector), a colour
    // per channel.
    let ramp: Vec<f32> = (0..3 * SIZE * SIZE)
        .map(|i| {
            let (c, y, x) = (i / (SIZE * SIZE), (i / SIZE) % SIZE, i % SIZE);
            let check = ((x / 8) + (y / 8)) % 2;
            0.25 + 0.1 * c as f32 + 0.15 * check as f32
        })
        .collect();
    maps.insert(
        "diffuse",
        Tensor::from_vec(ramp, (1, 3, SIZE, SIZE), &device).unwrap(),
    );
    let rough: Vec<f32> = (0..SIZE * SIZE)
        .map(|i| if (i / SIZE) % 16 < 8 { 0.25 } else { 0.45 })
        .collect();
    maps.insert(
        "roughness",
        Tensor::from_vec(rough, (1, 1, SIZE, SIZE), &device).unwrap(),
    );
    maps
}

/// [`truth`]'s maps over a square of `side` at flash height 1, rendered ×2 under `lights`:
/// (L, 3, SIZE, SIZE) display values.
fn render_truth(side: f64, lights: &[Highlight]) -> Tensor {
    let brdf = lookup("ggx").unwrap();
    let geometry = FlashGeometry::with_side(lights, SIZE, side, DType::F32, &Device::Cpu).unwrap();
    let maps = truth().with_texel_size(Some(side / SIZE as f64));
    encode_display(&(render_radiance_with(brdf.as_ref(), &maps, &geometry).unwrap() * 2.0).unwrap())
        .unwrap()
}

/// [`truth`] photographed square with the flash above pixel (28, 36), the square of `side`:
/// PNG bytes, and the highlight.
fn photo_of_side(side: f64) -> (Vec<u8>, (f64, f64)) {
    let pixel = (28.0, 36.0);
    let light = Highlight::from_pixel_on(pixel.0, pixel.1, SIZE, side);
    let image = render_truth(side, &[light]).squeeze(0).unwrap();
    let png = encode_png(&PlanarImage::from_tensor(&image).unwrap(), PngBits::Eight).unwrap();
    (png, pixel)
}

/// Mean |a − b| over every element.
fn mean_abs_difference(a: &Tensor, b: &Tensor) -> f32 {
    (a - b)
        .unwrap()
        .abs()
        .unwrap()
        .mean_all()
        .unwrap()
        .to_scalar::<f32>()
        .unwrap()
}

/// The photo in the training data's geometry (a square of side 2, a 90° field of view).
fn photo() -> (Vec<u8>, (f64, f64)) {
    photo_of_side(PHOTO_SIDE)
}

#[test]
fn capture_fits_a_rendered_photo_and_writes_a_loadable_folder() {
    let (png, pixel) = photo();
    let brdf = lookup("ggx").unwrap();
    let options = CaptureOptions {
        size: SIZE,
        steps: 200,
        fov_degrees: Some(TRAINING_FOV_DEGREES),
        ..CaptureOptions::default()
    };
    let result = capture(&png, "rendered.png", &brdf, &options, &mut |_, _| {}).unwrap();
    assert!((result.side - PHOTO_SIDE).abs() < 1e-12, "{}", result.side);
    // The detector finds the flash within 2 % of the width.
    let (row, col) = result.highlight.pixel;
    assert!(
        (row - pixel.0).hypot(col - pixel.1) < 0.02 * SIZE as f64,
        "{:?}",
        result.highlight
    );
    let (first, last) = (result.losses[0], *result.losses.last().unwrap());
    assert!(last < first / 4.0, "loss {first} → {last}");
    let l1 = mean_abs_difference(&result.render, &result.photo);
    assert!(l1 < 0.02, "re-render L1 {l1}");
    // The photo was exposed ×2: the gain takes part of it, not the albedo alone (gain and
    // albedo trade freely where the lobe is weak, so the split is not exact).
    assert!(result.gain > 1.1, "gain {}", result.gain);
    // No vignetting was photographed; the warm-up's fit stays small.
    let vignetting = result.vignetting.unwrap();
    assert!(vignetting < 0.1, "vignetting {vignetting}");

    let dir = tempfile::tempdir().unwrap();
    let exports = Exports {
        gltf: true,
        mtlx: true,
    };
    let textures = write_capture(&result, dir.path(), exports).unwrap();
    for file in textures.files() {
        assert!(dir.path().join("export").join(file).is_file(), "{file}");
    }
    assert!(textures.files().contains(&"normal.png"));
    for document in ["material.gltf", "material.mtlx"] {
        assert!(
            dir.path().join("export").join(document).is_file(),
            "{document}"
        );
    }
    let loaded = load_maps(&dir.path().join("material"), None).unwrap();
    assert_eq!(loaded.brdf.name(), "ggx");
    assert_eq!(loaded.manifest.resolution, SIZE);
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["steps"], 200);
    assert_eq!(record["fov_degrees"], TRAINING_FOV_DEGREES);
    // tan 45° is 1 within an ulp.
    let texel = PHOTO_SIDE / SIZE as f64;
    assert!((record["texel_size"].as_f64().unwrap() - texel).abs() < 1e-12);
    assert!((loaded.manifest.texel_size.unwrap() - texel).abs() < 1e-12);
    assert!(dir.path().join("sheet.png").is_file());
    // relit.png: one row of eight renders, laid out as the sheet grid lays out eight tiles.
    let tiles = vec![PlanarImage::filled(3, SIZE, SIZE, 0.0); 8];
    let expected = photomat_core::sheet::grid(&[tiles], 0.0).unwrap();
    let (_, height, width) = png_header(&dir.path().join("relit.png")).unwrap();
    assert_eq!((height, width), (expected.height, expected.width));
}

#[test]
fn square_side_follows_the_pinhole() {
    // 90° across a square photo: the training data's side 2 at height 1.
    assert!((square_side(90.0, 512, 512) - 2.0).abs() < 1e-12);
    // A 4:3 photo is cropped to its short side: ¾ of the long side's width.
    assert!((square_side(90.0, 4000, 3000) - 1.5).abs() < 1e-12);
    assert!((square_side(90.0, 3000, 4000) - 1.5).abs() < 1e-12);
    // 60°: 2·tan 30° = 2/√3.
    assert!((square_side(60.0, 100, 100) - 2.0 / 3f64.sqrt()).abs() < 1e-12);
    // The new flash positions ring the centre at a quarter of the side.
    for light in new_flash_positions(1.2) {
        assert!((light.x.hypot(light.y) - 0.3).abs() < 1e-12, "{light:?}");
    }
}

#[test]
fn the_right_field_of_view_relights_closer_to_the_truth() {
    // A photo taken with a 60° field of view: a square of 2·tan 30° ≈ 1.155 at height 1, so
    // the flash is farther, relative to the square, than in the training geometry (side 2)
    // and the texels see it closer to the normal. Fitting it with the right geometry must predict the material
    // under new flash positions better than fitting it as if it spanned side 2.
    let fov = 60.0;
    let side = square_side(fov, SIZE, SIZE);
    let (png, _) = photo_of_side(side);
    let brdf = lookup("ggx").unwrap();
    let held_out = |fov_degrees: f64| {
        let options = CaptureOptions {
            size: SIZE,
            steps: 150,
            fov_degrees: Some(fov_degrees),
            ..CaptureOptions::default()
        };
        let fit = capture(&png, "fov60.png", &brdf, &options, &mut |_, _| {}).unwrap();
        assert!((fit.side - square_side(fov_degrees, SIZE, SIZE)).abs() < 1e-12);
        // The same flash positions relative to each square (a quarter of its side from the
        // centre), so the renders are compared at the same pixels under the truth's geometry.
        let truth = render_truth(side, &new_flash_positions(side));
        let relit = relight(&fit, &new_flash_positions(fit.side)).unwrap();
        mean_abs_difference(&relit, &truth)
    };
    let (right, wrong) = (held_out(fov), held_out(TRAINING_FOV_DEGREES));
    assert!(
        right < 0.8 * wrong,
        "held-out L1 with the right fov {right}, with 90° {wrong}"
    );
}

/// `png` re-encoded as a JPEG whose EXIF records a 35 mm equivalent focal length of `mm`, as
/// a phone writes it.
fn jpeg_with_focal_length(png: &[u8], mm: u16) -> Vec<u8> {
    let rgb = image::load_from_memory(png).unwrap().to_rgb8();
    let field = exif::Field {
        tag: exif::Tag::FocalLengthIn35mmFilm,
        ifd_num: exif::In::PRIMARY,
        value: exif::Value::Short(vec![mm]),
    };
    let mut writer = exif::experimental::Writer::new();
    writer.push_field(&field);
    let mut tiff = std::io::Cursor::new(Vec::new());
    writer.write(&mut tiff, true).unwrap();
    let mut app1 = b"Exif\0\0".to_vec();
    app1.extend(tiff.into_inner());
    let mut jpeg = Vec::new();
    let mut encoder = jpeg_encoder::Encoder::new(&mut jpeg, 95);
    encoder.add_app_segment(1, &app1).unwrap();
    let (w, h) = (rgb.width() as u16, rgb.height() as u16);
    encoder
        .encode(rgb.as_raw(), w, h, jpeg_encoder::ColorType::Rgb)
        .unwrap();
    jpeg
}

#[test]
fn the_field_of_view_comes_from_the_photos_exif_unless_given() {
    // A square photo spanning a 61° field of view: 26 mm equivalent (EXIF stores whole mm).
    let fov = fov_from_35mm_equivalent(26.0, SIZE, SIZE);
    let (png, _) = photo_of_side(square_side(fov, SIZE, SIZE));
    let jpeg = jpeg_with_focal_length(&png, 26);
    let brdf = lookup("ggx").unwrap();
    let options = CaptureOptions {
        size: SIZE,
        steps: 5,
        ..CaptureOptions::default()
    };
    let from_exif = capture(&jpeg, "phone.jpg", &brdf, &options, &mut |_, _| {}).unwrap();
    assert_eq!(
        from_exif.fov.source,
        FovSource::Exif {
            lens: LensRecord::Equivalent35mm {
                focal_length_35mm: 26.0
            }
        }
    );
    assert!((from_exif.fov.degrees - fov).abs() < 1e-12);
    assert!((from_exif.side - square_side(fov, SIZE, SIZE)).abs() < 1e-12);
    // Given, it wins over the EXIF; without EXIF (the PNG), the default.
    let given = CaptureOptions {
        fov_degrees: Some(TRAINING_FOV_DEGREES),
        ..options.clone()
    };
    let fit = capture(&jpeg, "phone.jpg", &brdf, &given, &mut |_, _| {}).unwrap();
    assert_eq!(
        (fit.fov.degrees, fit.fov.source),
        (TRAINING_FOV_DEGREES, FovSource::Given)
    );
    let fit = capture(&png, "no-exif.png", &brdf, &options, &mut |_, _| {}).unwrap();
    assert_eq!(
        (fit.fov.degrees, fit.fov.source),
        (DEFAULT_FOV_DEGREES, FovSource::Default)
    );
    // The simulator's photos record their 90° exactly (focal length and sensor pitch).
    let light = Highlight::from_pixel_on(28.0, 36.0, SIZE, PHOTO_SIDE);
    let image = render_truth(PHOTO_SIDE, &[light]).squeeze(0).unwrap();
    let simulated = photomat_data::simulator::output::encode_photo(
        &PlanarImage::from_tensor(&image).unwrap(),
        photomat_data::simulator::PhotoFormat::Jpeg,
    )
    .unwrap();
    let fit = capture(&simulated, "simulated.jpg", &brdf, &options, &mut |_, _| {}).unwrap();
    assert!(matches!(
        fit.fov.source,
        FovSource::Exif {
            lens: LensRecord::FocalPlane { .. }
        }
    ));
    assert!((fit.fov.degrees - TRAINING_FOV_DEGREES).abs() < 1e-4);
    // capture.json says where the field of view came from.
    let dir = tempfile::tempdir().unwrap();
    write_capture(&from_exif, dir.path(), Exports::default()).unwrap();
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["fov_source"]["kind"], "exif");
    assert_eq!(record["fov_source"]["lens"]["record"], "equivalent35mm");
    assert_eq!(record["fov_source"]["lens"]["focal_length_35mm"], 26.0);
}

#[test]
fn capture_errors_name_the_file_and_the_problem() {
    let brdf = lookup("ggx").unwrap();
    let options = CaptureOptions {
        size: SIZE,
        steps: 1,
        ..CaptureOptions::default()
    };
    let err = capture(
        b"not an image",
        "notes.txt",
        &brdf,
        &options,
        &mut |_, _| {},
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.starts_with("notes.txt:"), "{err}");
    // A uniform grey photo has no highlight.
    let grey = encode_png(&PlanarImage::filled(3, SIZE, SIZE, 0.5), PngBits::Eight).unwrap();
    let err = capture(&grey, "grey.png", &brdf, &options, &mut |_, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("grey.png") && err.contains("--highlight"),
        "{err}"
    );
    let small = CaptureOptions { size: 8, ..options };
    let err = capture(&grey, "grey.png", &brdf, &small, &mut |_, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("outside 16"), "{err}");
}

#[test]
fn uniform_maps_and_the_relief_are_fitted_as_one_value_and_unknown_names_fail() {
    let (png, pixel) = photo();
    let brdf = lookup("ggx").unwrap();
    let options = CaptureOptions {
        size: SIZE,
        steps: 40,
        fov_degrees: Some(TRAINING_FOV_DEGREES),
        highlight: Some(pixel),
        uniform_maps: vec!["roughness".into()],
        ..CaptureOptions::default()
    };
    let result = capture(&png, "rendered.png", &brdf, &options, &mut |_, _| {}).unwrap();
    // The largest max − min of any one channel of a map.
    let spread = |name: &str| {
        let v = photomat_core::testing::values(result.maps.get(name).unwrap()).unwrap();
        v.chunks(SIZE * SIZE)
            .map(|c| {
                let (lo, hi) = c
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
                hi - lo
            })
            .fold(0.0, f64::max)
    };
    // Held: one value (the decode of one raw value is exact); free: the checks show. The
    // relief is held by default.
    assert_eq!(spread("roughness"), 0.0);
    assert_eq!(spread("normal"), 0.0);
    assert!(
        spread("diffuse") > 0.05,
        "diffuse spread {}",
        spread("diffuse")
    );
    let (first, last) = (result.losses[0], *result.losses.last().unwrap());
    assert!(last < first / 2.0, "loss {first} → {last}");
    let with_relief = CaptureOptions {
        relief: true,
        ..options.clone()
    };
    let free = capture(&png, "rendered.png", &brdf, &with_relief, &mut |_, _| {}).unwrap();
    let normals = photomat_core::testing::values(free.maps.get("normal").unwrap()).unwrap();
    assert!(normals.iter().any(|&n| (n - normals[0]).abs() > 1e-4));

    let wrong = CaptureOptions {
        uniform_maps: vec!["gloss".into()],
        ..options
    };
    let err = capture(&png, "rendered.png", &brdf, &wrong, &mut |_, _| {})
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("'gloss'") && err.contains("roughness"),
        "{err}"
    );
}

/// A uniform ggx material photographed with the flash above pixel (30, 34) through the
/// camera terms `lens` (vignetting, ambient light): PNG bytes and the highlight.
fn uniform_photo(lens: &photomat_capture::CameraTerms) -> (Vec<u8>, (f64, f64)) {
    let brdf = lookup("ggx").unwrap();
    let device = Device::Cpu;
    let maps = MaterialMaps::defaults(brdf.params(), 1, SIZE, DType::F32, &device)
        .unwrap()
        .with_texel_size(Some(PHOTO_SIDE / SIZE as f64));
    let pixel = (30.0, 34.0);
    let light = Highlight::from_pixel_on(pixel.0, pixel.1, SIZE, PHOTO_SIDE);
    let geometry =
        FlashGeometry::with_side(&[light], SIZE, PHOTO_SIDE, DType::F32, &device).unwrap();
    let radiance = render_radiance_with(brdf.as_ref(), &maps, &geometry).unwrap();
    let reflectance = maps.ambient_reflectance().unwrap();
    let rho2 = photomat_capture::camera::rho_squared(SIZE).unwrap();
    let exposed = lens.expose(&radiance, reflectance.as_ref(), &rho2).unwrap();
    let image = encode_display(&exposed).unwrap();
    let png = encode_png(
        &PlanarImage::from_tensor(&image.squeeze(0).unwrap()).unwrap(),
        PngBits::Eight,
    )
    .unwrap();
    (png, pixel)
}

/// The warm-up (150 steps, one refinement step) of [`uniform_photo`] through `lens`, fitting
/// the vignetting and the ambient light as asked.
fn warm_up(
    lens: &photomat_capture::CameraTerms,
    vignetting: bool,
    ambient: bool,
) -> photomat_capture::Capture {
    let (png, pixel) = uniform_photo(lens);
    let options = CaptureOptions {
        size: SIZE,
        steps: 1,
        fov_degrees: Some(TRAINING_FOV_DEGREES),
        highlight: Some(pixel),
        warmup_steps: 150,
        vignetting,
        ambient,
        ..CaptureOptions::default()
    };
    let brdf = lookup("ggx").unwrap();
    capture(&png, "uniform.png", &brdf, &options, &mut |_, _| {}).unwrap()
}

#[test]
fn the_warm_up_recovers_the_vignetting_of_a_uniform_material() {
    // A lens that loses 30 % in the corners, in a dark room; fitted with and without the
    // ambient term, which must then stay near zero.
    let lens = photomat_capture::CameraTerms::new(0.0, Some(0.3), None).unwrap();
    for ambient in [false, true] {
        let result = warm_up(&lens, true, ambient);
        let fitted = result.vignetting.unwrap();
        assert!((fitted - 0.3).abs() < 0.05, "fitted vignetting {fitted}");
        assert_eq!(result.ambient.is_some(), ambient);
        if let Some(c) = result.ambient {
            // The recovery test's tolerance below (a fifth of a 3 % room); the fit lands at
            // 0.0048–0.0053 depending on the renderer's f32 rounding.
            assert!(c < 0.006, "ambient {c} fitted in a dark room");
        }
    }
}

#[test]
fn the_warm_up_recovers_the_ambient_light_of_a_uniform_material() {
    // A room lit at 3 % of the flash's radiance at the centre (the simulator's phone photos
    // draw 0–4 %): at the corners, √3 units from the flash, a seventh of the light. No
    // vignetting: to first order in the distance from the centre the two change the same
    // quadratic term of the photo's falloff, and fitted together on a uniform material they
    // trade one for the other (docs/capture.md, "Fit").
    let lens = photomat_capture::CameraTerms::new(0.0, None, Some(0.03)).unwrap();
    let c = warm_up(&lens, false, true).ambient.unwrap();
    assert!((c - 0.03).abs() < 0.006, "fitted ambient {c}");
}

#[test]
fn a_coarse_stage_fits_at_half_size_and_relights_as_well_as_the_full_size_fit() {
    // 150 steps on the photo box-filtered to 32², then 50 at 64², against 200 at 64²: the
    // split is recorded, the losses cover both stages, and the result fits the photo and
    // predicts the material under new flashes about as well.
    let (png, _) = photo();
    let brdf = lookup("ggx").unwrap();
    let fit = |full_size_steps: usize| {
        let options = CaptureOptions {
            size: SIZE,
            steps: 200,
            fov_degrees: Some(TRAINING_FOV_DEGREES),
            full_size_steps,
            coarse_min_size: SIZE / 2,
            ..CaptureOptions::default()
        };
        capture(&png, "rendered.png", &brdf, &options, &mut |_, _| {}).unwrap()
    };
    let (staged, whole) = (fit(50), fit(200));
    let coarse = staged.coarse.unwrap();
    assert_eq!((coarse.size, coarse.steps), (SIZE / 2, 150));
    assert!(whole.coarse.is_none());
    assert_eq!(staged.losses.len(), 200);
    let (_, size, _) = staged.maps.batch_and_size().unwrap();
    assert_eq!(size, SIZE);
    let l1 = mean_abs_difference(&staged.render, &staged.photo);
    assert!(l1 < 0.02, "re-render L1 {l1}");
    let truth = render_truth(PHOTO_SIDE, &new_flash_positions(PHOTO_SIDE));
    let held_out = |capture| {
        mean_abs_difference(
            &relight(capture, &new_flash_positions(PHOTO_SIDE)).unwrap(),
            &truth,
        )
    };
    let (staged_l1, whole_l1) = (held_out(&staged), held_out(&whole));
    assert!(
        staged_l1 < 1.25 * whole_l1,
        "held-out L1 with a coarse stage {staged_l1}, without {whole_l1}"
    );
}

#[test]
fn known_maps_are_held_at_their_values_through_both_stages_and_bad_ones_fail() {
    // The true diffuse map held: the fit ends on it (to raw_for's clamping and f32), through
    // a coarse stage at 32² (where it is held box-filtered) and the full-size steps, and
    // records it; roughness is fitted. Wrong names, shapes and a map both uniform and known
    // are errors that say so.
    let (png, pixel) = photo();
    let brdf = lookup("ggx").unwrap();
    let diffuse = truth().get("diffuse").unwrap().clone();
    let known = MaterialMaps::new().with("diffuse", diffuse.clone());
    let options = CaptureOptions {
        size: SIZE,
        steps: 60,
        fov_degrees: Some(TRAINING_FOV_DEGREES),
        highlight: Some(pixel),
        known_maps: Some(known.clone()),
        full_size_steps: 20,
        coarse_min_size: SIZE / 2,
        ..CaptureOptions::default()
    };
    let fit = capture(&png, "rendered.png", &brdf, &options, &mut |_, _| {}).unwrap();
    assert_eq!(fit.coarse.unwrap().size, SIZE / 2);
    assert_eq!(fit.known_maps, vec!["diffuse".to_string()]);
    let worst = max_abs_diff(fit.maps.get("diffuse").unwrap(), &diffuse).unwrap();
    assert!(worst < 1e-3, "held diffuse off by {worst}");
    let roughness = photomat_core::testing::values(fit.maps.get("roughness").unwrap()).unwrap();
    assert!(roughness.iter().any(|&r| (r - roughness[0]).abs() > 1e-4));

    let failing = |known: MaterialMaps, uniform: Vec<String>| {
        let options = CaptureOptions {
            known_maps: Some(known),
            uniform_maps: uniform,
            ..options.clone()
        };
        capture(&png, "rendered.png", &brdf, &options, &mut |_, _| {})
            .err()
            .unwrap()
            .to_string()
    };
    let err = failing(MaterialMaps::new().with("gloss", diffuse.clone()), vec![]);
    assert!(
        err.contains("'gloss'") && err.contains("roughness"),
        "{err}"
    );
    let small = diffuse
        .narrow(2, 0, SIZE / 2)
        .unwrap()
        .narrow(3, 0, SIZE / 2)
        .unwrap();
    let err = failing(MaterialMaps::new().with("diffuse", small), vec![]);
    assert!(
        err.contains("'diffuse'") && err.contains(&format!("{SIZE}, {SIZE}]")),
        "{err}"
    );
    let err = failing(known, vec!["diffuse".into()]);
    assert!(err.contains("'diffuse'") && err.contains("both"), "{err}");
}
