//! `photomat relight` end to end on an untrained tiny GAN: the contact sheet holds N tiles
//! that differ (the light moves), `--frames` writes the N tiles of the sheet, `--gif`
//! decodes to N frames, the output is a function of the seed, and bad inputs name the file.

use photomat_tests as _;

use std::path::Path;

use image::AnimationDecoder;
use image::codecs::gif::GifDecoder;
use photomat_core::image_io::{PlanarImage, read_png};
use photomat_core::sheet::{CONTACT_SHEET_GAP, contact_sheet_grid};
use photomat_tests::cli_fixtures::{path_str, photomat, photomat_error, tiny_gan};

const SIDE: usize = 32;

/// Tile `k` of an `n`-tile contact sheet of `SIDE`² tiles.
fn sheet_tile(sheet: &PlanarImage, n: usize, k: usize) -> PlanarImage {
    let (columns, _) = contact_sheet_grid(n);
    let (top, left) = (
        (k / columns) * (SIDE + CONTACT_SHEET_GAP),
        (k % columns) * (SIDE + CONTACT_SHEET_GAP),
    );
    let mut data = Vec::with_capacity(3 * SIDE * SIDE);
    for c in 0..3 {
        for row in 0..SIDE {
            data.extend((0..SIDE).map(|col| sheet.get(c, top + row, left + col)));
        }
    }
    PlanarImage::new(3, SIDE, SIDE, data).unwrap()
}

fn max_diff(a: &PlanarImage, b: &PlanarImage) -> f32 {
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn relight(gan: &Path, seed: &str, n: &str, out: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "relight",
        "--gan",
        path_str(gan),
        "--seed",
        seed,
        "--orbit",
        n,
        "--out",
        path_str(out),
    ];
    args.extend_from_slice(extra);
    photomat(&args).unwrap()
}

#[test]
fn relight_orbit_writes_sheet_frames_and_gif() {
    let dir = tempfile::tempdir().unwrap();
    let gan = tiny_gan(dir.path(), "gan", SIDE, 1);
    let (sheet_path, frames, gif) = (
        dir.path().join("orbit.png"),
        dir.path().join("frames"),
        dir.path().join("orbit.gif"),
    );
    let n = 5;
    let printed = relight(
        &gan,
        "7",
        "5",
        &sheet_path,
        &["--frames", path_str(&frames), "--gif", path_str(&gif)],
    );
    assert!(printed.contains("5 flash positions"), "{printed}");

    // Sheet: ⌈√5⌉ = 3 columns, 2 rows of 32² tiles with 4-pixel gaps.
    let (sheet, _) = read_png(&sheet_path).unwrap();
    assert_eq!((sheet.width, sheet.height), (3 * SIDE + 8, 2 * SIDE + 4));
    let tiles: Vec<PlanarImage> = (0..n).map(|k| sheet_tile(&sheet, n, k)).collect();
    // The light moves: every pair of positions gives a visibly different image.
    for a in 0..n {
        for b in a + 1..n {
            let d = max_diff(&tiles[a], &tiles[b]);
            assert!(d > 2.0 / 255.0, "tiles {a} and {b} differ by only {d}");
        }
    }

    // Frames: exactly the N tiles of the sheet, in order.
    let mut names: Vec<String> = std::fs::read_dir(&frames)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    let expected: Vec<String> = (0..n).map(|k| format!("frame-{k:03}.png")).collect();
    assert_eq!(names, expected);
    for (k, tile) in tiles.iter().enumerate() {
        let (frame, _) = read_png(&frames.join(&names[k])).unwrap();
        assert_eq!(max_diff(&frame, tile), 0.0, "frame {k}");
    }

    // GIF: N frames of 32², close to the tiles up to the 256-colour palette.
    let decoder =
        GifDecoder::new(std::io::BufReader::new(std::fs::File::open(&gif).unwrap())).unwrap();
    let decoded = decoder.into_frames().collect_frames().unwrap();
    assert_eq!(decoded.len(), n);
    for (k, frame) in decoded.iter().enumerate() {
        let buffer = frame.buffer();
        assert_eq!(buffer.dimensions(), (SIDE as u32, SIDE as u32));
        let mean_err = buffer
            .enumerate_pixels()
            .map(|(x, y, p)| {
                (0..3)
                    .map(|c| {
                        (p.0[c] as f32 / 255.0 - tiles[k].get(c, y as usize, x as usize)).abs()
                    })
                    .sum::<f32>()
            })
            .sum::<f32>()
            / (3 * SIDE * SIDE) as f32;
        assert!(
            mean_err < 0.02,
            "GIF frame {k} is off by {mean_err} on average"
        );
    }
}

#[test]
fn relight_is_a_function_of_the_seed() {
    let dir = tempfile::tempdir().unwrap();
    let gan = tiny_gan(dir.path(), "gan", SIDE, 2);
    let paths: Vec<_> = ["a.png", "b.png", "c.png"]
        .iter()
        .map(|name| dir.path().join(name))
        .collect();
    relight(&gan, "11", "3", &paths[0], &[]);
    relight(&gan, "11", "3", &paths[1], &[]);
    relight(&gan, "12", "3", &paths[2], &[]);
    let read = |p: &Path| read_png(p).unwrap().0;
    let (a, b, c) = (read(&paths[0]), read(&paths[1]), read(&paths[2]));
    assert_eq!(a.data, b.data, "same seed, same sheet");
    assert!(
        max_diff(&a, &c) > 2.0 / 255.0,
        "another seed is another material"
    );
}

#[test]
fn relight_bad_inputs_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("not-a-run");
    std::fs::create_dir_all(&empty).unwrap();
    let out = dir.path().join("o.png");
    let err = photomat_error(&[
        "relight",
        "--gan",
        path_str(&empty),
        "--out",
        path_str(&out),
    ]);
    assert!(
        err.contains("not-a-run") && err.contains("gan.json"),
        "{err}"
    );
    let gan = tiny_gan(dir.path(), "gan", SIDE, 3);
    for (extra, expected) in [
        (vec!["--out", "sheet.jpg"], "--out must name a .png"),
        (
            vec!["--out", path_str(&out), "--gif", "anim.png"],
            "--gif must name a .gif",
        ),
        (vec!["--out", path_str(&out), "--radius", "-1"], "--radius"),
        (vec!["--out", path_str(&out), "--orbit", "0"], "orbit"),
    ] {
        let mut args = vec!["relight", "--gan", path_str(&gan)];
        args.extend(extra);
        let err = photomat_error(&args);
        assert!(err.contains(expected), "{expected}: {err}");
    }
    assert!(!out.exists(), "no output after a failure");
}

/// A tiny untrained spatial GAN (R = 32, cells of 8 texels) whose texels are those of 64²
/// photos (2/64 world units), saved in `dir/name`.
fn tiny_spatial_gan(dir: &Path, name: &str, texel_size: Option<f64>) -> std::path::PathBuf {
    use candle_core::Device;
    use photomat_generator::{GanModel, SpatialConfig};
    let config = photomat_generator::GeneratorConfig {
        tileable: true,
        spatial: Some(SpatialConfig {
            local_dim: 4,
            texel_size,
            ..SpatialConfig::default()
        }),
        ..photomat_tests::cli_fixtures::tiny_gan_config(32)
    };
    let path = dir.join(name);
    GanModel::new(&config, 5, &Device::Cpu)
        .unwrap()
        .save(&path, serde_json::json!({ "test": true }))
        .unwrap();
    path
}

#[test]
fn relight_spatial_model_at_any_multiple_of_its_cell() {
    let dir = tempfile::tempdir().unwrap();
    let gan = tiny_spatial_gan(dir.path(), "spatial", Some(2.0 / 64.0));
    // Default: the spatial models' 512² (a multiple of the 8-texel cell).
    let out = dir.path().join("native.png");
    relight(&gan, "1", "1", &out, &[]);
    let (sheet, _) = read_png(&out).unwrap();
    assert_eq!(
        (sheet.height, sheet.width),
        (
            photomat_generator::DEFAULT_SPATIAL_SAMPLE_SIDE,
            photomat_generator::DEFAULT_SPATIAL_SAMPLE_SIDE
        )
    );
    // Any multiple of the 8-texel cell, e.g. 40 (not a power of two).
    let out = dir.path().join("forty.png");
    relight(&gan, "1", "2", &out, &["--size", "40"]);
    let (sheet, _) = read_png(&out).unwrap();
    assert_eq!(sheet.height, 40);
    // 44 is not a multiple of the cell: the error names the cell size.
    let err = photomat_error(&[
        "relight",
        "--gan",
        path_str(&gan),
        "--size",
        "44",
        "--out",
        path_str(&dir.path().join("bad.png")),
    ]);
    assert!(err.contains("44") && err.contains('8'), "{err}");
}

#[test]
fn relight_spatial_model_without_texel_size_says_how_to_record_it() {
    let dir = tempfile::tempdir().unwrap();
    let gan = tiny_spatial_gan(dir.path(), "old", None);
    let err = photomat_error(&[
        "relight",
        "--gan",
        path_str(&gan),
        "--out",
        path_str(&dir.path().join("x.png")),
    ]);
    assert!(err.contains("texel_size"), "{err}");
}

#[test]
fn relight_fixed_size_model_refuses_another_size() {
    let dir = tempfile::tempdir().unwrap();
    let gan = tiny_gan(dir.path(), "fixed", SIDE, 2);
    let err = photomat_error(&[
        "relight",
        "--gan",
        path_str(&gan),
        "--size",
        "64",
        "--out",
        path_str(&dir.path().join("x.png")),
    ]);
    assert!(err.contains("64"), "{err}");
}
