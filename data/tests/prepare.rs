//! `prepare` on a folder of good and bad files: every good photo (8- and
//! 16-bit, grey, RGBA, JPEG with an EXIF orientation) is prepared, every bad one (corrupt,
//! truncated, not an image, 1×1, CMYK, GIF, empty) is reported with its reason, re-running only
//! processes new files, and the simulator's true highlights follow the crop and resize.
//! Fixtures are written into a temporary folder by the test itself.

use std::io::Cursor;
use std::path::Path;

use image::{DynamicImage, ImageBuffer, ImageFormat, Luma, Rgb, Rgba};
use photomat_data::dataset::{
    DatasetIndex, FlashDataset, PrepareOptions, REPORT_FILE, evaluate, prepare,
};
use photomat_data::highlight::{DetectionStatus, DetectorKind};

/// Working size of the test datasets (the smallest accepted photo side is 64/4 = 16).
const SIZE: usize = 64;

fn options() -> PrepareOptions {
    PrepareOptions {
        size: SIZE,
        detector: None,
        reject_non_square: false,
        progress: false,
    }
}

/// A grey photo with a bright round highlight at (row, col), `w`×`h`.
fn flash_photo(w: u32, h: u32, row: f64, col: f64) -> image::RgbImage {
    ImageBuffer::from_fn(w, h, |x, y| {
        let d2 = (x as f64 + 0.5 - col).powi(2) + (y as f64 + 0.5 - row).powi(2);
        let v = 0.25 + 0.75 * (-d2 / (2.0 * (w.min(h) as f64 / 10.0).powi(2))).exp();
        let v = (v * 255.0).round() as u8;
        Rgb([v, v, v])
    })
}

fn encode(image: &DynamicImage, format: ImageFormat) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    image.write_to(&mut out, format).unwrap();
    out.into_inner()
}

/// A baseline JPEG whose first segment after SOI is an APP1 Exif block holding only the
/// orientation tag (0x0112) with `orientation` (big-endian TIFF, one IFD entry).
fn jpeg_with_orientation(image: &DynamicImage, orientation: u16) -> Vec<u8> {
    let jpeg = encode(image, ImageFormat::Jpeg);
    let mut tiff = b"MM\0\x2a\0\0\0\x08".to_vec(); // header, IFD at offset 8
    tiff.extend_from_slice(&1u16.to_be_bytes()); // one entry
    tiff.extend_from_slice(&0x0112u16.to_be_bytes()); // Orientation
    tiff.extend_from_slice(&3u16.to_be_bytes()); // SHORT
    tiff.extend_from_slice(&1u32.to_be_bytes()); // count 1
    tiff.extend_from_slice(&orientation.to_be_bytes());
    tiff.extend_from_slice(&[0, 0]); // value padding
    tiff.extend_from_slice(&0u32.to_be_bytes()); // no next IFD
    let mut app1 = b"Exif\0\0".to_vec();
    app1.extend_from_slice(&tiff);
    let mut out = jpeg[..2].to_vec(); // SOI
    out.extend_from_slice(&[0xFF, 0xE1]);
    out.extend_from_slice(&((app1.len() + 2) as u16).to_be_bytes());
    out.extend_from_slice(&app1);
    out.extend_from_slice(&jpeg[2..]);
    out
}

/// A CMYK JPEG written with the `jpeg-encoder` crate.
fn cmyk_jpeg() -> Vec<u8> {
    let (w, h) = (64u16, 64u16);
    let pixels: Vec<u8> = (0..w as usize * h as usize)
        .flat_map(|i| [(i % 256) as u8, 40, 80, 20])
        .collect();
    let mut out = Vec::new();
    jpeg_encoder::Encoder::new(&mut out, 90)
        .encode(&pixels, w, h, jpeg_encoder::ColorType::Cmyk)
        .unwrap();
    out
}

/// Write the fixture folder; returns the names expected to be rejected with a fragment of
/// their reason.
fn write_fixtures(dir: &Path) -> Vec<(&'static str, &'static str)> {
    let write = |name: &str, bytes: &[u8]| std::fs::write(dir.join(name), bytes).unwrap();
    let rgb = DynamicImage::ImageRgb8(flash_photo(96, 72, 30.0, 50.0));
    write("good_rgb8.png", &encode(&rgb, ImageFormat::Png));
    write("good.jpg", &encode(&rgb, ImageFormat::Jpeg));
    write(
        "good_rgb16.png",
        &encode(&DynamicImage::ImageRgb16(rgb.to_rgb16()), ImageFormat::Png),
    );
    let grey = DynamicImage::ImageLuma8(ImageBuffer::from_fn(80, 80, |x, y| {
        Luma([(255.0 * (1.0 - ((x as f64 - 40.0).hypot(y as f64 - 40.0) / 60.0))) as u8])
    }));
    write("good_grey.png", &encode(&grey, ImageFormat::Png));
    write(
        "good_grey16.png",
        &encode(
            &DynamicImage::ImageLuma16(grey.to_luma16()),
            ImageFormat::Png,
        ),
    );
    let rgba = DynamicImage::ImageRgba8(ImageBuffer::from_fn(64, 64, |x, y| {
        Rgba([(x * 4) as u8, (y * 4) as u8, 128, 200])
    }));
    write("good_rgba.png", &encode(&rgba, ImageFormat::Png));

    let jpeg = encode(&rgb, ImageFormat::Jpeg);
    let png = encode(&rgb, ImageFormat::Png);
    write("truncated.jpg", &jpeg[..jpeg.len() / 2]);
    write("truncated.png", &png[..png.len() / 2]);
    // SOI, a 1-byte quantisation table segment, then no marker where the next must be.
    let mut corrupt_jpeg = vec![0xFF, 0xD8, 0xFF, 0xDB, 0x00, 0x03, 0x00];
    corrupt_jpeg.extend(std::iter::repeat_n(0x5A, 300));
    write("corrupt.jpg", &corrupt_jpeg);
    let mut corrupt_png = png[..16].to_vec();
    corrupt_png.extend(std::iter::repeat_n(0xA5, 300));
    write("corrupt.png", &corrupt_png);
    write(
        "notes.txt",
        b"these are my flash photos of the kitchen floor\n",
    );
    write("empty.jpg", b"");
    let one = DynamicImage::ImageRgb8(ImageBuffer::from_pixel(1, 1, Rgb([200, 200, 200])));
    write("one_pixel.png", &encode(&one, ImageFormat::Png));
    write("cmyk.jpg", &cmyk_jpeg());
    write("animation.gif", b"GIF89a\x01\x00\x01\x00\x00\x00\x00;");
    vec![
        ("truncated.jpg", "truncated JPEG"),
        ("truncated.png", "PNG"),
        ("corrupt.jpg", "corrupt JPEG"),
        ("corrupt.png", "corrupt PNG"),
        ("notes.txt", "not an image"),
        ("empty.jpg", "empty file"),
        ("one_pixel.png", "too small: 1×1"),
        ("cmyk.jpg", "CMYK"),
        ("animation.gif", "unsupported image format GIF"),
    ]
}

#[test]
fn prepare_processes_good_files_and_reports_every_bad_one() {
    let tmp = tempfile::tempdir().unwrap();
    let photos = tmp.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let bad = write_fixtures(&photos);
    std::fs::write(photos.join(".hidden.png"), b"ignored").unwrap();
    let out = tmp.path().join("dataset");

    let summary = prepare(&photos, &out, &options()).unwrap();
    assert_eq!(
        (summary.added, summary.rejected),
        (6, bad.len()),
        "{summary:?}"
    );
    assert_eq!(summary.detector, DetectorKind::Robust);

    let index = DatasetIndex::read(&out).unwrap();
    let mut good: Vec<&str> = index
        .photos
        .iter()
        .map(|p| Path::new(&p.source).file_name().unwrap().to_str().unwrap())
        .collect();
    good.sort_unstable();
    assert_eq!(
        good,
        [
            "good.jpg",
            "good_grey.png",
            "good_grey16.png",
            "good_rgb16.png",
            "good_rgb8.png",
            "good_rgba.png"
        ]
    );
    let report = std::fs::read_to_string(out.join(REPORT_FILE)).unwrap();
    for (name, fragment) in &bad {
        let entry = index
            .rejected
            .iter()
            .find(|r| r.source.ends_with(name))
            .unwrap_or_else(|| panic!("{name} is not in the rejected list"));
        assert!(entry.reason.contains(fragment), "{name}: {}", entry.reason);
        assert!(
            report.contains(name) && report.contains(&entry.reason),
            "{report}"
        );
    }

    // Every image exists with the working size; the highlight of the 96×72 photo (drawn at
    // column 50, row 30) moved through the centre crop (left 12) and the ×64/72 resize.
    let dataset = FlashDataset::open(&out).unwrap();
    for i in 0..dataset.len() {
        let image = dataset.load_image(i).unwrap();
        assert_eq!((image.channels, image.height, image.width), (3, SIZE, SIZE));
        assert!(dataset.photos()[i].source.starts_with('/'));
    }
    let rgb8 = index
        .photos
        .iter()
        .find(|p| p.source.ends_with("good_rgb8.png"))
        .unwrap();
    assert_eq!(rgb8.source_size, [96, 72]);
    assert_eq!(rgb8.status, DetectionStatus::Detected);
    let scale = SIZE as f64 / 72.0;
    let (want_row, want_col) = (30.0 * scale, (50.0 - 12.0) * scale);
    let error = (rgb8.highlight_px[0] - want_row).hypot(rgb8.highlight_px[1] - want_col);
    // 2 px of 64: the drawn Gaussian blob is not the flash lobe the detector models.
    assert!(
        error < 2.0,
        "highlight {:?}, drawn at ({want_row}, {want_col})",
        rgb8.highlight_px
    );
    // 8- and 16-bit versions of the same picture prepare to the same image.
    let rgb16 = index
        .photos
        .iter()
        .find(|p| p.source.ends_with("good_rgb16.png"))
        .unwrap();
    let load = |image: &str| {
        photomat_core::image_io::read_png(&out.join(image))
            .unwrap()
            .0
    };
    assert_eq!(load(&rgb8.image), load(&rgb16.image));
}

#[test]
fn prepare_rerun_processes_only_new_files() {
    let tmp = tempfile::tempdir().unwrap();
    let photos = tmp.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let bad = write_fixtures(&photos);
    let out = tmp.path().join("dataset");
    prepare(&photos, &out, &options()).unwrap();
    let first = DatasetIndex::read(&out).unwrap();

    let again = prepare(&photos, &out, &options()).unwrap();
    assert_eq!(
        (again.added, again.rejected, again.unchanged),
        (0, 0, 6 + bad.len())
    );
    assert_eq!(DatasetIndex::read(&out).unwrap(), first);

    let new = DynamicImage::ImageRgb8(flash_photo(64, 64, 32.0, 32.0));
    std::fs::write(photos.join("new.png"), encode(&new, ImageFormat::Png)).unwrap();
    let third = prepare(&photos, &out, &options()).unwrap();
    assert_eq!((third.added, third.rejected, third.total_photos), (1, 0, 7));

    // The dataset keeps its detector and size: asking for others is an error naming both.
    let paper = PrepareOptions {
        detector: Some(DetectorKind::Paper),
        ..options()
    };
    let err = prepare(&photos, &out, &paper).unwrap_err().to_string();
    assert!(
        err.contains("index.json") && err.contains("'robust'"),
        "{err}"
    );
    let bigger = PrepareOptions {
        size: 128,
        ..options()
    };
    let err = prepare(&photos, &out, &bigger).unwrap_err().to_string();
    assert!(err.contains("size 64"), "{err}");
}

#[test]
fn prepare_applies_exif_orientation() {
    let tmp = tempfile::tempdir().unwrap();
    let photos = tmp.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    // Stored 160×96: left half red, right half blue. EXIF 6 = rotate 90° clockwise: upright
    // it is 96×160 with red on top, so its centre square is red above blue (without the
    // rotation the centre square would be red left of blue).
    let stored = DynamicImage::ImageRgb8(ImageBuffer::from_fn(160, 96, |x, _| {
        if x < 80 {
            Rgb([220, 20, 20])
        } else {
            Rgb([20, 20, 220])
        }
    }));
    std::fs::write(
        photos.join("rotated.jpg"),
        jpeg_with_orientation(&stored, 6),
    )
    .unwrap();
    let out = tmp.path().join("dataset");
    let summary = prepare(&photos, &out, &options()).unwrap();
    assert_eq!(summary.added, 1, "{summary:?}");
    let dataset = FlashDataset::open(&out).unwrap();
    assert_eq!(dataset.photos()[0].source_size, [96, 160]);
    let image = dataset.load_image(0).unwrap();
    let plane = SIZE * SIZE;
    let at = |c: usize, row: usize, col: usize| image.data[c * plane + row * SIZE + col];
    for col in [2, SIZE / 2, SIZE - 3] {
        assert!(
            at(0, 2, col) > 0.8 && at(2, 2, col) < 0.4,
            "top row is red at column {col}"
        );
        assert!(
            at(2, SIZE - 3, col) > 0.8 && at(0, SIZE - 3, col) < 0.4,
            "bottom is blue"
        );
    }
}

#[test]
fn prepare_reject_non_square_and_simulated_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let photos = tmp.path().join("photos");
    std::fs::create_dir(&photos).unwrap();
    let wide = DynamicImage::ImageRgb8(flash_photo(128, 96, 40.0, 70.0));
    std::fs::write(photos.join("000000.png"), encode(&wide, ImageFormat::Png)).unwrap();
    let square = DynamicImage::ImageRgb8(flash_photo(96, 96, 50.0, 44.0));
    std::fs::write(photos.join("000001.png"), encode(&square, ImageFormat::Png)).unwrap();
    // The simulator's record sits beside photos/ and names them relative to itself.
    let record = r#"{ "format": "photomat-simulation", "version": 1, "seed": 1, "size": 96,
        "photos": [
          { "photo": "photos/000000.png", "family": "wood", "highlight_px": [40.0, 70.0] },
          { "photo": "photos/000001.png", "family": "stone", "highlight_px": [50.0, 44.0] } ] }"#;
    std::fs::write(tmp.path().join("simulation.json"), record).unwrap();

    let strict = PrepareOptions {
        reject_non_square: true,
        ..options()
    };
    let out = tmp.path().join("strict");
    let summary = prepare(&photos, &out, &strict).unwrap();
    assert_eq!((summary.added, summary.rejected), (1, 1));
    let index = DatasetIndex::read(&out).unwrap();
    assert!(
        index.rejected[0].reason.contains("not square (128×96)"),
        "{:?}",
        index.rejected
    );

    let out = tmp.path().join("cropped");
    prepare(&photos, &out, &options()).unwrap();
    let index = DatasetIndex::read(&out).unwrap();
    // 128×96 → centre crop from column 16, then ×64/96.
    let s = SIZE as f64 / 96.0;
    let truth = index.photos[0].truth_highlight_px.unwrap();
    assert!(
        (truth[0] - 40.0 * s).abs() < 1e-9 && (truth[1] - 54.0 * s).abs() < 1e-9,
        "{truth:?}"
    );
    let truth = index.photos[1].truth_highlight_px.unwrap();
    assert!(
        (truth[0] - 50.0 * s).abs() < 1e-9 && (truth[1] - 44.0 * s).abs() < 1e-9,
        "{truth:?}"
    );

    // eval-detector's library side: errors per family from the record beside the sources.
    let dataset = FlashDataset::open(&out).unwrap();
    let evaluation = evaluate(&dataset, &DetectorKind::ALL, false).unwrap();
    assert_eq!(evaluation.with_truth, 2);
    for d in &evaluation.detectors {
        let families: Vec<&str> = d.families.keys().map(String::as_str).collect();
        assert_eq!(families, ["stone", "wood"]);
        assert_eq!(d.all.photos, 2);
        // The drawn blob is round and centred on the truth, though no flash falloff: both
        // detectors land within 2.5 px of 64.
        assert!(d.all.max_px < 2.5, "{:?}: {:?}", d.detector, d.all);
    }
    assert!(evaluation.table().contains("wood"));
}

#[test]
fn a_folder_with_photos_only_in_sub_folders_is_an_error_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    for sub in ["leather", "wood"] {
        std::fs::create_dir_all(photos.join(sub)).unwrap();
        let image = DynamicImage::ImageRgb8(flash_photo(64, 64, 32.0, 32.0));
        std::fs::write(
            photos.join(sub).join("a.png"),
            encode(&image, ImageFormat::Png),
        )
        .unwrap();
    }
    let err = prepare(&photos, &dir.path().join("data"), &options())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("leather, wood") && err.contains("--photos") && err.contains("no photos"),
        "{err}"
    );
    // And an empty folder says that it is empty.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let err = prepare(&empty, &dir.path().join("data2"), &options())
        .unwrap_err()
        .to_string();
    assert!(err.contains("holds no photos"), "{err}");
}
