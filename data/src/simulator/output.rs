//! What `photomat simulate` writes (docs/datasets.md): 8-bit photos (JPEG or PNG), the
//! ground-truth material folders, and `simulation.json`.
//!
//! Photos are quantised to 8 bits by rounding (the same rule as
//! [`photomat_core::image_io::encode_png`]); JPEGs use baseline encoding at
//! [`JPEG_QUALITY`] with the `image` crate's encoder, which is deterministic, so equal
//! pictures give equal bytes. Every file is written atomically. Photos carry EXIF recording the
//! simulator's lens ([`TRAINING_FOV_DEGREES`] across, [`crate::dataset::lens`]), so that
//! `photomat capture` reads the field of view they were taken with, as it does from a phone's.

use std::io::Cursor;
use std::path::Path;

use image::codecs::jpeg::JpegEncoder;
use image::{ExtendedColorType, ImageEncoder};
use photomat_core::flash::TRAINING_FOV_DEGREES;
use photomat_core::image_io::{PlanarImage, PngBits, encode_png_with_exif, write_atomic};
use photomat_core::{Error, Result};

use super::camera::CameraModel;
use super::pose::PhonePose;
use crate::dataset::lens::exif_for_field_of_view;

/// JPEG quality of simulated photos: a phone camera's default.
pub const JPEG_QUALITY: u8 = 92;

/// File name of the run's record inside the output folder.
pub const SIMULATION_FILE: &str = "simulation.json";

/// Value of `simulation.json`'s `format` field.
pub const FORMAT_TAG: &str = "photomat-simulation";

/// `simulation.json` version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// Folder of the photos inside the output folder.
pub const PHOTOS_DIR: &str = "photos";

/// Folder of the ground-truth material folders inside the output folder.
pub const TRUTH_DIR: &str = "truth";

/// File format of the simulated photos.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PhotoFormat {
    /// Baseline JPEG at [`JPEG_QUALITY`] (what phones write).
    #[default]
    Jpeg,
    /// Lossless 8-bit PNG.
    Png,
}

impl PhotoFormat {
    /// File extension without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            PhotoFormat::Jpeg => "jpg",
            PhotoFormat::Png => "png",
        }
    }
}

/// `photo` (3, S, S display values in [0, 1]) as 8-bit RGB bytes in `format`.
pub fn encode_photo(photo: &PlanarImage, format: PhotoFormat) -> Result<Vec<u8>> {
    if photo.channels != 3 {
        return Err(Error::Invalid(format!(
            "a photo has 3 channels, got {}",
            photo.channels
        )));
    }
    let exif = exif_for_field_of_view(TRAINING_FOV_DEGREES, photo.width, photo.height);
    match format {
        PhotoFormat::Png => encode_png_with_exif(photo, PngBits::Eight, &exif),
        PhotoFormat::Jpeg => {
            let plane = photo.texels();
            // Interleave to HWC; round to the nearest level (`as` maps NaN to 0).
            let bytes: Vec<u8> = (0..plane)
                .flat_map(|t| (0..3).map(move |c| c * plane + t))
                .map(|i| (photo.data[i].clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect();
            let mut out = Cursor::new(Vec::new());
            let mut encoder = JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY);
            encoder
                .set_exif_metadata(exif)
                .map_err(|e| Error::Invalid(format!("JPEG EXIF: {e}")))?;
            encoder
                .write_image(
                    &bytes,
                    photo.width as u32,
                    photo.height as u32,
                    ExtendedColorType::Rgb8,
                )
                .map_err(|e| Error::Invalid(format!("JPEG encoding failed: {e}")))?;
            Ok(out.into_inner())
        }
    }
}

/// Write `photo` to `path` in `format`, atomically; errors name the file.
pub fn write_photo(path: &Path, photo: &PlanarImage, format: PhotoFormat) -> Result<()> {
    let bytes = encode_photo(photo, format).map_err(|e| Error::file(path, e))?;
    write_atomic(path, &bytes)
}

/// `simulation.json`: the run's parameters and, per photo, its files and ground truth.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationManifest {
    /// Always [`FORMAT_TAG`].
    pub format: String,
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// The run's `--seed`.
    pub seed: u64,
    /// Photo side S in pixels.
    pub size: usize,
    /// One record per photo, in index order.
    pub photos: Vec<SimulatedPhoto>,
}

/// One photo of a [`SimulationManifest`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulatedPhoto {
    /// Photo file, relative to the output folder (`photos/000000.jpg`).
    pub photo: String,
    /// Ground-truth material folder, relative to the output folder (`truth/000000`).
    pub truth: String,
    /// Procedural family the material comes from.
    pub family: String,
    /// The family's seed: `family.generate(size, family_seed)` regenerates the material.
    pub family_seed: u64,
    /// What the family says the material is, when it says more than its seed (a library
    /// family: the material ids and how they were seen).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
    /// True highlight, continuous (row, col) pixel coordinates in the S×S photo.
    pub highlight_px: [f64; 2],
    /// True highlight (x, y) in photo-plane coordinates (the photo spans side 2).
    pub highlight: [f64; 2],
    /// The camera that took the photo.
    pub camera: CameraModel,
    /// The phone's tilt and flash offset; absent for the overhead pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose: Option<PhonePose>,
}

impl SimulationManifest {
    /// Read and check `DIR/simulation.json`; errors name the file.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join(SIMULATION_FILE);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| Error::file(&path, format!("cannot read: {e}")))?;
        let manifest: Self = serde_json::from_str(&text)
            .map_err(|e| Error::file(&path, format!("not a simulation record: {e}")))?;
        if manifest.format != FORMAT_TAG || manifest.version != FORMAT_VERSION {
            return Err(Error::file(
                &path,
                format!(
                    "format '{}' version {} is not '{FORMAT_TAG}' version {FORMAT_VERSION}",
                    manifest.format, manifest.version
                ),
            ));
        }
        Ok(manifest)
    }

    /// Write `DIR/simulation.json` (pretty JSON, trailing newline), atomically.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let path = dir.join(SIMULATION_FILE);
        let mut text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::file(&path, format!("cannot serialise: {e}")))?;
        text.push('\n');
        write_atomic(&path, text.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient(size: usize) -> PlanarImage {
        let data = (0..3 * size * size)
            .map(|i| (i % (size * size)) as f32 / (size * size) as f32)
            .collect();
        PlanarImage::new(3, size, size, data).unwrap()
    }

    #[test]
    fn simulated_photos_record_the_simulators_field_of_view_in_exif() {
        use crate::dataset::lens::{LensRecord, read_lens};
        use photomat_core::flash::{FLASH_HEIGHT, PHOTO_SIDE};
        // The constant is the geometry's: side 2 seen from height 1.
        let geometric = 2.0 * (PHOTO_SIDE / 2.0 / FLASH_HEIGHT).atan().to_degrees();
        assert!((TRAINING_FOV_DEGREES - geometric).abs() < 1e-12);
        for format in [PhotoFormat::Jpeg, PhotoFormat::Png] {
            for size in [16, 512] {
                let bytes = encode_photo(&gradient(size), format).unwrap();
                let lens = read_lens(&bytes).expect("a simulated photo has a lens record");
                assert!(matches!(lens, LensRecord::FocalPlane { .. }), "{lens:?}");
                // The rationals keep 10⁻⁶ pixel per cm: far below a thousandth of a degree.
                let fov = lens.fov_degrees(size, size);
                assert!(
                    (fov - TRAINING_FOV_DEGREES).abs() < 1e-4,
                    "{format:?} {size}: {fov}"
                );
            }
        }
    }

    #[test]
    fn photos_decode_to_what_was_encoded() {
        let photo = gradient(16);
        for format in [PhotoFormat::Png, PhotoFormat::Jpeg] {
            let bytes = encode_photo(&photo, format).unwrap();
            assert_eq!(bytes, encode_photo(&photo, format).unwrap(), "{format:?}");
            let decoded = image::load_from_memory(&bytes).unwrap().into_rgb8();
            assert_eq!(decoded.dimensions(), (16, 16));
            // PNG is exact to half a step; JPEG at quality 92 on a smooth ramp within a few.
            let tolerance = match format {
                PhotoFormat::Png => 0.5,
                PhotoFormat::Jpeg => 4.0,
            };
            for (i, p) in decoded.pixels().enumerate() {
                let want = photo.data[i] * 255.0;
                assert!(
                    (p.0[1] as f32 - want).abs() <= tolerance,
                    "{format:?} pixel {i}: {} vs {want}",
                    p.0[1]
                );
            }
        }
    }

    #[test]
    fn manifest_round_trips_and_rejects_other_formats() {
        let dir = tempfile::tempdir().unwrap();
        let manifest = SimulationManifest {
            format: FORMAT_TAG.into(),
            version: FORMAT_VERSION,
            seed: 7,
            size: 64,
            photos: vec![SimulatedPhoto {
                photo: "photos/000000.jpg".into(),
                truth: "truth/000000".into(),
                family: "tiles".into(),
                family_seed: 123,
                material: None,
                highlight_px: [30.5, 33.25],
                highlight: [0.0390625, 0.046875],
                camera: CameraModel::ideal(),
                pose: None,
            }],
        };
        manifest.write(dir.path()).unwrap();
        assert_eq!(SimulationManifest::read(dir.path()).unwrap(), manifest);
        let text = std::fs::read_to_string(dir.path().join(SIMULATION_FILE)).unwrap();
        assert!(text.contains("\"tone_curve\": \"gamma2.2\""), "{text}");
        std::fs::write(
            dir.path().join(SIMULATION_FILE),
            text.replace(FORMAT_TAG, "other"),
        )
        .unwrap();
        let err = SimulationManifest::read(dir.path())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains(SIMULATION_FILE) && err.contains("other"),
            "{err}"
        );
    }
}
