//! `photomat_library::import` on a package the test makes: a Cube 2 `.cfg` pairing textures
//! (with a tinted copy, a cut-out, a 4:1 strip, a glowing panel and a missing normal map), a pk3
//! archive of suffix-named textures, and a DEP-5 copyright file; and a damaged archive.

use std::io::Write;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use photomat_core::image_io::{PlanarImage, PngBits, encode_png};
use photomat_library::convert::{ConvertOptions, Rejection, RoughnessSource};
use photomat_library::import::{ImportOptions, import};
use photomat_library::index::{LibraryIndex, folders};
use photomat_library::material::Provenance;
// The registry's models (`ggx`, `height`): a test that never names the plugin crate sees none.
use photomat_brdfs as _;

const SIDE: usize = 32;

/// A periodic height on the test's grid: `kx` and `ky` cycles of a product of waves.
fn height(kx: f64, ky: f64) -> Vec<f64> {
    let tau = std::f64::consts::TAU;
    (0..SIDE * SIDE)
        .map(|i| {
            let (r, c) = (
                (i / SIDE) as f64 / SIDE as f64,
                (i % SIDE) as f64 / SIDE as f64,
            );
            2.0 * (tau * kx * c).sin() * (tau * ky * r).cos() + (tau * (c + 2.0 * r)).sin()
        })
        .collect()
}

/// The DirectX-style (green = −y) normal map of `h` (texel units), RGB.
fn directx_normals(h: &[f64]) -> PlanarImage {
    let n = SIDE;
    let at = |r: usize, c: usize| h[(r % n) * n + c % n];
    let mut data = vec![0.0f32; 3 * n * n];
    for r in 0..n {
        for c in 0..n {
            let dx = 0.5 * (at(r, c + 1) - at(r, c + n - 1));
            let dy_up = 0.5 * (at(r + n - 1, c) - at(r + 1, c));
            let (x, y, z) = (-dx, -dy_up, 1.0);
            let l = (x * x + y * y + z * z).sqrt();
            let i = r * n + c;
            data[i] = (0.5 + 0.5 * x / l) as f32;
            data[n * n + i] = (0.5 - 0.5 * y / l) as f32;
            data[2 * n * n + i] = (0.5 + 0.5 * z / l) as f32;
        }
    }
    PlanarImage::new(3, n, n, data).unwrap()
}

/// A base colour: `tint` times a pattern following `h`.
fn base(h: &[f64], tint: [f32; 3], width: usize) -> PlanarImage {
    let mut data = Vec::new();
    for t in tint {
        for r in 0..SIDE {
            for c in 0..width {
                data.push(t * (0.5 + 0.1 * h[r * SIDE + c % SIDE]) as f32);
            }
        }
    }
    PlanarImage::new(3, SIDE, width, data).unwrap()
}

fn png(image: &PlanarImage) -> Vec<u8> {
    encode_png(image, PngBits::Eight).unwrap()
}

fn write(path: &Path, bytes: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// The test package under `root`.
fn make_package(root: &Path) {
    let data = root.join("usr/share/games/test/data");
    let brick = height(2.0, 3.0);
    write(
        &data.join("brick/brick.png"),
        &png(&base(&brick, [0.7, 0.3, 0.2], SIDE)),
    );
    write(
        &data.join("brick/brickb.png"),
        &png(&base(&brick, [0.2, 0.3, 0.7], SIDE)),
    );
    write(
        &data.join("brick/brick_n.png"),
        &png(&directx_normals(&brick)),
    );
    write(
        &data.join("brick/brick_s.png"),
        &png(&PlanarImage::filled(1, SIDE, SIDE, 0.5)),
    );
    let panel = height(1.0, 1.0);
    let mut decal = base(&panel, [0.5, 0.5, 0.5], SIDE).data;
    let alpha: Vec<f32> = (0..SIDE * SIDE)
        .map(|i| if i % 7 == 0 { 0.0 } else { 1.0 })
        .collect();
    decal.extend(alpha);
    write(
        &data.join("misc/holes.png"),
        &png(&PlanarImage::new(4, SIDE, SIDE, decal).unwrap()),
    );
    write(
        &data.join("misc/panel_n.png"),
        &png(&directx_normals(&panel)),
    );
    write(
        &data.join("misc/long.png"),
        &png(&base(&panel, [0.5; 3], 4 * SIDE)),
    );
    write(
        &data.join("misc/plain.png"),
        &png(&base(&panel, [0.4; 3], SIDE)),
    );
    write(
        &data.join("misc/lamp.png"),
        &png(&base(&panel, [0.9; 3], SIDE)),
    );
    write(
        &data.join("misc/lamp_g.png"),
        &png(&base(&panel, [1.0; 3], SIDE)),
    );
    write(
        &data.join("textures.cfg"),
        b"setshader bumpspecmapworld
texture c brick/brick.png 0 0 0 0.5
texture n brick/brick_n.png
texture s brick/brick_s.png
texture c brick/brickb.png
texture n brick/brick_n.png
setshader bumpworld
texture c misc/holes.png
texture n misc/panel_n.png
texture c misc/long.png
texture n misc/panel_n.png
texture c misc/plain.png
texture n misc/gone_n.png
setshader bumpspecglowworld
texture c misc/lamp.png
texture n misc/panel_n.png
texture g misc/lamp_g.png
",
    );
    // A pk3 of suffix-named textures: a stone with its normal and gloss maps.
    let stone = height(3.0, 1.0);
    let pk3 = std::fs::File::create(data.join("pak.pk3")).unwrap();
    let mut zip = zip::ZipWriter::new(pk3);
    let options = zip::write::SimpleFileOptions::default();
    for (name, image) in [
        ("rocks/stone.png", base(&stone, [0.6, 0.6, 0.55], SIDE)),
        ("rocks/stone_norm.png", directx_normals(&stone)),
        (
            "rocks/stone_gloss.png",
            PlanarImage::filled(1, SIDE, SIDE, 0.8),
        ),
    ] {
        zip.start_file(name, options).unwrap();
        zip.write_all(&png(&image)).unwrap();
    }
    zip.finish().unwrap();
    write(
        &root.join("usr/share/doc/testpkg/copyright"),
        b"Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/

Files: *
Copyright: The Test Team
License: CC0-1.0

Files: data/brick/*
Copyright: A Brick Maker
License: CC-BY-SA-3.0
",
    );
}

fn options(seed: u64) -> ImportOptions {
    ImportOptions {
        convert: ConvertOptions {
            min_side: 16,
            max_side: 64,
        },
        seed,
        ..ImportOptions::default()
    }
}

fn run(source: &Path, out: &Path, options: &ImportOptions) -> anyhow::Result<LibraryIndex> {
    let stop = AtomicBool::new(false);
    Ok(import(&[source.to_path_buf()], out, options, &stop, &|_| {})?.index)
}

#[test]
fn a_package_imports_with_its_pairs_filters_licences_and_conventions() {
    let dir = tempfile::tempdir().unwrap();
    let package = dir.path().join("testpkg");
    make_package(&package);
    let lib = dir.path().join("lib");
    let stop = AtomicBool::new(false);
    let report = import(
        std::slice::from_ref(&package),
        &lib,
        &options(0),
        &stop,
        &|_| {},
    )
    .unwrap();
    let index = &report.index;
    let ids: Vec<&str> = index.materials.iter().map(|m| m.id.as_str()).collect();
    assert_eq!(
        ids,
        [
            "testpkg/data-brick-brick",
            "testpkg/data-pak_pk3-rocks-stone"
        ]
    );
    let rejected = &index.packages[0].rejected;
    for reason in [
        Rejection::Duplicate,
        Rejection::Cutout,
        Rejection::Aspect,
        Rejection::Emissive,
        Rejection::Unreadable,
    ] {
        assert_eq!(
            rejected.get(&reason),
            Some(&1),
            "{reason:?} in {rejected:?}"
        );
    }
    // The missing normal map is named with the file that names it.
    assert_eq!(report.unreadable.len(), 1);
    assert!(
        report.unreadable[0].contains("textures.cfg")
            && report.unreadable[0].contains("gone_n.png"),
        "{:?}",
        report.unreadable
    );
    // Licences by file, from the copyright file's last matching paragraph.
    assert_eq!(index.materials[0].licences, ["CC-BY-SA-3.0"]);
    assert_eq!(index.materials[1].licences, ["CC0-1.0"]);
    // Both folders load; the brick's DirectX normals were flipped, the stone's gloss read.
    let brick = folders(&lib, &index.materials[0]);
    let ggx = brick.load_ggx().unwrap();
    let provenance: Provenance =
        serde_json::from_value(ggx.manifest.source.clone().unwrap()).unwrap();
    assert!(provenance.green.flipped);
    assert_eq!(provenance.package, "testpkg");
    let height = brick.load_height().unwrap();
    assert!(height.brdf.name().starts_with("height(ggx, scale="));
    assert_eq!(height.maps.texel_size(), Some(2.0 / SIDE as f64));
    let stone = folders(&lib, &index.materials[1]).load_ggx().unwrap();
    let provenance: Provenance =
        serde_json::from_value(stone.manifest.source.clone().unwrap()).unwrap();
    assert_eq!(provenance.roughness, RoughnessSource::GlossMap);
    let roughness = stone.maps.get("roughness").unwrap().mean_all().unwrap();
    let roughness = roughness.to_scalar::<f32>().unwrap();
    assert!((roughness - 0.2).abs() < 0.01, "1 − gloss 0.8: {roughness}");
    assert!(lib.join("contact_sheet.png").exists());

    // The same sources and seed give the same splits; an existing library needs --overwrite.
    let again = dir.path().join("again");
    let second = run(&package, &again, &options(0)).unwrap();
    let splits = |i: &LibraryIndex| i.materials.iter().map(|m| m.split).collect::<Vec<_>>();
    assert_eq!(splits(index), splits(&second));
    let err = run(&package, &lib, &options(0)).unwrap_err().to_string();
    assert!(
        err.contains("already holds a material library") && err.contains("--overwrite"),
        "{err}"
    );
    run(
        &package,
        &lib,
        &ImportOptions {
            overwrite: true,
            ..options(1)
        },
    )
    .unwrap();
}

#[test]
fn a_damaged_archive_fails_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let source = dir.path().join("textures");
    write(
        &source.join("pak0.pk3"),
        b"PK\x03\x04 but then nothing a zip reader wants",
    );
    let err = run(&source, &dir.path().join("lib"), &options(0))
        .unwrap_err()
        .to_string();
    assert!(err.contains("pak0.pk3"), "{err}");
    assert!(!dir.path().join("lib").exists());
}
