//! `photomat_capture::capture` on a photo rendered from known maps under a known flash: the
//! loss falls, the re-render matches, the highlight is found, the output folder loads back,
//! and bad inputs fail naming the file.

use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _; // link the built-in models
use photomat_capture::{CaptureOptions, capture, write_capture};
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::image_io::{PlanarImage, PngBits, encode_png};
use photomat_core::map_files::load_maps;
use photomat_core::render::render_radiance_with;
use photomat_core::{FlashGeometry, Highlight, MaterialMaps, encode_display, lookup};

const SIZE: usize = 64;

/// A ggx material with checked albedos and rougher stripes, photographed with the flash
/// above pixel (28, 36): PNG bytes, and the highlight.
fn photo() -> (Vec<u8>, (f64, f64)) {
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
    let pixel = (28.0, 36.0);
    let light = Highlight::from_pixel_on(pixel.0, pixel.1, SIZE, PHOTO_SIDE);
    let geometry =
        FlashGeometry::with_side(&[light], SIZE, PHOTO_SIDE, DType::F32, &device).unwrap();
    let maps = maps.with_texel_size(Some(PHOTO_SIDE / SIZE as f64));
    let image = encode_display(
        &(render_radiance_with(brdf.as_ref(), &maps, &geometry).unwrap() * 2.0).unwrap(),
    )
    .unwrap()
    .squeeze(0)
    .unwrap();
    let png = encode_png(&PlanarImage::from_tensor(&image).unwrap(), PngBits::Eight).unwrap();
    (png, pixel)
}

#[test]
fn capture_fits_a_rendered_photo_and_writes_a_loadable_folder() {
    let (png, pixel) = photo();
    let brdf = lookup("ggx").unwrap();
    let options = CaptureOptions {
        size: SIZE,
        steps: 200,
        ..CaptureOptions::default()
    };
    let result = capture(&png, "rendered.png", &brdf, &options, &mut |_, _| {}).unwrap();
    // The detector finds the flash within 2 % of the width.
    let (row, col) = result.highlight.pixel;
    assert!(
        (row - pixel.0).hypot(col - pixel.1) < 0.02 * SIZE as f64,
        "{:?}",
        result.highlight
    );
    let (first, last) = (result.losses[0], *result.losses.last().unwrap());
    assert!(last < first / 4.0, "loss {first} → {last}");
    let l1 = (&result.render - &result.photo)
        .unwrap()
        .abs()
        .unwrap()
        .mean_all()
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert!(l1 < 0.02, "re-render L1 {l1}");
    // The photo was exposed ×2: the gain takes it, not the albedo alone.
    assert!(result.gain > 1.2, "gain {}", result.gain);

    let dir = tempfile::tempdir().unwrap();
    write_capture(&result, dir.path()).unwrap();
    let loaded = load_maps(&dir.path().join("material"), None).unwrap();
    assert_eq!(loaded.brdf.name(), "ggx");
    assert_eq!(loaded.manifest.resolution, SIZE);
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("capture.json")).unwrap()).unwrap();
    assert_eq!(record["steps"], 200);
    assert!(dir.path().join("sheet.png").is_file());
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
