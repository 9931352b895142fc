//! Files whose header claims more pixels than `photomat_core::image_io::MAX_PIXELS`: a
//! 100000×100000 PNG of a few dozen bytes is an error naming the file and the limit before
//! any pixel buffer exists (a map read and `prepare`), and `prepare` still indexes the good
//! photo next to it.

use std::path::Path;

use photomat_core::image_io::{MAX_PIXELS, read_png};
use photomat_tests::cli_fixtures::{path_str, photomat};

/// CRC-32 (ISO 3309, the PNG chunk checksum), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A PNG chunk: length, type, data, CRC of type + data.
fn chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut out = (data.len() as u32).to_be_bytes().to_vec();
    let body: Vec<u8> = kind.iter().chain(data).copied().collect();
    out.extend(&body);
    out.extend(crc32(&body).to_be_bytes());
    out
}

/// Signature, an IHDR claiming `side`×`side` 8-bit RGB, an empty IDAT and IEND.
fn huge_png(side: u32) -> Vec<u8> {
    let mut ihdr = side.to_be_bytes().to_vec();
    ihdr.extend(side.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend(chunk(b"IHDR", &ihdr));
    png.extend(chunk(b"IDAT", &[]));
    png.extend(chunk(b"IEND", &[]));
    png
}

/// `photomat prepare --photos PHOTOS --out DATA --size 32`, then the index it wrote.
fn prepare_index(photos: &Path, data: &Path) -> serde_json::Value {
    photomat(&[
        "prepare",
        "--photos",
        path_str(photos),
        "--out",
        path_str(data),
        "--size",
        "32",
    ])
    .unwrap();
    serde_json::from_str(&std::fs::read_to_string(data.join("index.json")).unwrap()).unwrap()
}

#[test]
fn crc32_is_the_png_checksum() {
    // The IEND chunk's CRC every PNG ends with.
    assert_eq!(crc32(b"IEND"), 0xAE42_6082);
}

#[test]
fn a_huge_png_header_is_refused_naming_the_file_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.png");
    std::fs::write(&path, huge_png(100_000)).unwrap();
    let err = read_png(&path).unwrap_err().to_string();
    assert!(err.contains("huge.png"), "{err}");
    assert!(
        err.contains("100000×100000") && err.contains(&MAX_PIXELS.to_string()),
        "{err}"
    );
}

#[test]
fn prepare_indexes_the_good_photo_next_to_a_huge_header() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, photos, data) = (
        dir.path().join("sim"),
        dir.path().join("photos"),
        dir.path().join("data"),
    );
    photomat(&[
        "simulate",
        "--count",
        "1",
        "--size",
        "64",
        "--seed",
        "3",
        "--format",
        "png",
        "--out",
        path_str(&sim),
    ])
    .unwrap();
    std::fs::create_dir(&photos).unwrap();
    let good = std::fs::read_dir(sim.join("photos"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    std::fs::copy(&good, photos.join("good.png")).unwrap();
    std::fs::write(photos.join("huge.png"), huge_png(100_000)).unwrap();
    let index = prepare_index(&photos, &data);
    let photos = index["photos"].as_array().unwrap();
    assert_eq!(photos.len(), 1, "{index}");
    assert!(photos[0]["source"].as_str().unwrap().contains("good.png"));
    let rejected = index["rejected"].as_array().unwrap();
    assert_eq!(rejected.len(), 1, "{index}");
    assert!(rejected[0]["source"].as_str().unwrap().contains("huge.png"));
    let reason = rejected[0]["reason"].as_str().unwrap();
    assert!(reason.contains(&MAX_PIXELS.to_string()), "{reason}");
}

#[test]
fn a_small_jpeg_claiming_65000_squared_is_rejected_by_prepare() {
    let dir = tempfile::tempdir().unwrap();
    let (photos, data) = (dir.path().join("photos"), dir.path().join("data"));
    std::fs::create_dir(&photos).unwrap();
    // A real 64² JPEG whose SOF0 header is patched to claim 65000×65000.
    let mut jpeg = Vec::new();
    image::RgbImage::from_pixel(64, 64, image::Rgb([120, 90, 60]))
        .write_to(
            &mut std::io::Cursor::new(&mut jpeg),
            image::ImageFormat::Jpeg,
        )
        .unwrap();
    let sof = jpeg
        .windows(2)
        .position(|w| w == [0xFF, 0xC0])
        .expect("a baseline JPEG has SOF0");
    jpeg[sof + 5..sof + 9].copy_from_slice(&[0xFD, 0xE8, 0xFD, 0xE8]);
    std::fs::write(photos.join("bomb.jpg"), &jpeg).unwrap();
    let index = prepare_index(&photos, &data);
    let rejected = index["rejected"].as_array().unwrap();
    assert_eq!(rejected.len(), 1, "{index}");
    let reason = rejected[0]["reason"].as_str().unwrap();
    assert!(
        reason.contains("65000×65000") && reason.contains(&MAX_PIXELS.to_string()),
        "{reason}"
    );
}
