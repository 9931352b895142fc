//! The lens a photo's EXIF records, as a field of view (docs/conventions.md, "A photo's field
//! of view"): read from phone photos, and written into the simulator's so that a capture of
//! them needs no `--fov`.
//!
//! Two records give it (EXIF 2.3, CIPA DC-008):
//!
//! - the exact one, the focal length f (`FocalLength`, mm) with the sensor's pixel pitch
//!   (`FocalPlaneXResolution` pixels per `FocalPlaneResolutionUnit`): the longer side of a
//!   `w × h` photo spans `long / resolution` on the sensor, so
//!   `fov = 2 · atan(long / resolution / 2 / f)`. Cameras and this project's simulator write
//!   it; phones rarely do, and a photo resized after it was taken no longer matches it;
//! - the 35 mm equivalent f₃₅ (`FocalLengthIn35mmFilm`, whole mm), which phones write: the
//!   focal length that gives a 36 × 24 mm frame the photo's *diagonal* field of view. Across
//!   the longer side the half-width is then the frame's half-diagonal, 21.63 mm, times
//!   `long / √(w² + h²)`, so `fov = 2 · atan(21.63 · long / √(w² + h²) / f₃₅)` (4:3 at
//!   26 mm: 67.3°; 13 mm ultra-wide: 106°; 77 mm telephoto: 25°). Cropped or digitally zoomed
//!   photos record the equivalent of what they show. Whole millimetres round it: a square at
//!   15 mm is 91.1°, not 90°.
//!
//! Pixels are taken as square (the Y resolution is not read), so the record does not depend on
//! the EXIF orientation.

use std::io::Cursor;

use serde::Serialize;

/// Half the diagonal of the 36 × 24 mm frame the 35 mm equivalent refers to, in mm.
const FULL_FRAME_HALF_DIAGONAL_MM: f64 = 21.633_307_652_783_937; // √(18² + 12²)

/// Millimetres per inch and per centimetre, EXIF's `FocalPlaneResolutionUnit` 2 and 3.
const MM_PER_INCH: f64 = 25.4;
const MM_PER_CM: f64 = 10.0;

/// The focal length the simulator's EXIF records, in mm: any value gives the same field of
/// view once the pixel pitch is chosen to match; this is a phone main camera's.
const WRITTEN_FOCAL_LENGTH_MM: f64 = 6.0;

/// Denominator of the rationals written: the pixel pitch to 10⁻⁶ pixel per cm.
const RATIONAL_DENOMINATOR: u32 = 1_000_000;

/// What a photo's EXIF says of its lens.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "record")]
pub enum LensRecord {
    /// Focal length and the sensor's pixel pitch (module docs: the exact record).
    FocalPlane {
        /// `FocalLength`, mm.
        focal_length_mm: f64,
        /// `FocalPlaneXResolution` converted to pixels per mm.
        pixels_per_mm: f64,
    },
    /// The 35 mm equivalent focal length, mm (`FocalLengthIn35mmFilm`).
    Equivalent35mm {
        /// `FocalLengthIn35mmFilm`, mm.
        focal_length_35mm: f64,
    },
}

impl LensRecord {
    /// Degrees across the longer side of a `width × height` photo (module docs).
    pub fn fov_degrees(&self, width: usize, height: usize) -> f64 {
        match *self {
            LensRecord::FocalPlane {
                focal_length_mm,
                pixels_per_mm,
            } => {
                let half_long_mm = width.max(height) as f64 / pixels_per_mm / 2.0;
                2.0 * (half_long_mm / focal_length_mm).atan().to_degrees()
            }
            LensRecord::Equivalent35mm { focal_length_35mm } => {
                fov_from_35mm_equivalent(focal_length_35mm, width, height)
            }
        }
    }
}

impl std::fmt::Display for LensRecord {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LensRecord::FocalPlane {
                focal_length_mm,
                pixels_per_mm,
            } => write!(
                f,
                "{focal_length_mm} mm at {pixels_per_mm:.4} pixels per mm of sensor"
            ),
            LensRecord::Equivalent35mm { focal_length_35mm } => {
                write!(f, "{focal_length_35mm} mm equivalent")
            }
        }
    }
}

/// Degrees across the longer side of a `width × height` photo taken at a 35 mm equivalent
/// focal length of `focal_length_35mm` mm (module docs).
pub fn fov_from_35mm_equivalent(focal_length_35mm: f64, width: usize, height: usize) -> f64 {
    let half_long = full_frame_half_long_side_mm(width, height);
    2.0 * (half_long / focal_length_35mm).atan().to_degrees()
}

/// Half the longer side, in mm, of the 36 × 24 mm frame's diagonal laid on a `width × height`
/// photo: the half-diagonal times `long / √(w² + h²)` (module docs).
fn full_frame_half_long_side_mm(width: usize, height: usize) -> f64 {
    let (w, h) = (width as f64, height as f64);
    FULL_FRAME_HALF_DIAGONAL_MM * w.max(h) / w.hypot(h)
}

/// The lens record of a photo file (JPEG, PNG, …): the exact one when the EXIF has a positive
/// focal length and pixel pitch in inches or centimetres, else the 35 mm equivalent when it is
/// not 0 (EXIF's "unknown"), else none. A file without EXIF, or whose EXIF does not parse, has
/// none.
pub fn read_lens(bytes: &[u8]) -> Option<LensRecord> {
    let exif = exif::Reader::new()
        .read_from_container(&mut Cursor::new(bytes))
        .ok()?;
    let field = |tag| exif.get_field(tag, exif::In::PRIMARY);
    let rational = |tag| match &field(tag)?.value {
        exif::Value::Rational(v) => v.first().map(|r| r.to_f64()),
        _ => None,
    };
    let focal_plane = || {
        let focal_length_mm = rational(exif::Tag::FocalLength)?;
        let per_unit = rational(exif::Tag::FocalPlaneXResolution)?;
        // The unit's default, when absent, is the inch (EXIF 2.3, 0xa210).
        let mm_per_unit = match field(exif::Tag::FocalPlaneResolutionUnit)
            .and_then(|f| f.value.get_uint(0))
            .unwrap_or(2)
        {
            2 => MM_PER_INCH,
            3 => MM_PER_CM,
            _ => return None,
        };
        let pixels_per_mm = per_unit / mm_per_unit;
        (focal_length_mm.is_finite()
            && focal_length_mm > 0.0
            && pixels_per_mm.is_finite()
            && pixels_per_mm > 0.0)
            .then_some(LensRecord::FocalPlane {
                focal_length_mm,
                pixels_per_mm,
            })
    };
    focal_plane().or_else(|| {
        let mm = field(exif::Tag::FocalLengthIn35mmFilm)?.value.get_uint(0)?;
        (mm > 0).then_some(LensRecord::Equivalent35mm {
            focal_length_35mm: mm as f64,
        })
    })
}

/// EXIF (a TIFF structure, as image encoders embed it) recording a lens of `fov_degrees`
/// across the longer side of a `width × height` photo: both records of the module docs, the
/// exact one with a 6 mm focal length and the matching pixel pitch in pixels per centimetre,
/// and the 35 mm equivalent rounded to whole mm.
///
/// # Panics
/// If `fov_degrees` is not in (0, 180) or the photo is empty.
pub fn exif_for_field_of_view(fov_degrees: f64, width: usize, height: usize) -> Vec<u8> {
    assert!(
        fov_degrees > 0.0 && fov_degrees < 180.0 && width > 0 && height > 0,
        "a lens of {fov_degrees}° over {width}×{height} pixels"
    );
    let tan_half = (fov_degrees / 2.0).to_radians().tan();
    let sensor_long_mm = 2.0 * WRITTEN_FOCAL_LENGTH_MM * tan_half;
    let pixels_per_cm = width.max(height) as f64 / sensor_long_mm * MM_PER_CM;
    let equivalent_35mm = full_frame_half_long_side_mm(width, height) / tan_half;
    let rational = |x: f64| exif::Rational {
        num: (x * RATIONAL_DENOMINATOR as f64).round() as u32,
        denom: RATIONAL_DENOMINATOR,
    };
    let fields = [
        (
            exif::Tag::FocalLength,
            exif::Value::Rational(vec![rational(WRITTEN_FOCAL_LENGTH_MM)]),
        ),
        (
            exif::Tag::FocalPlaneXResolution,
            exif::Value::Rational(vec![rational(pixels_per_cm)]),
        ),
        (
            exif::Tag::FocalPlaneYResolution,
            exif::Value::Rational(vec![rational(pixels_per_cm)]),
        ),
        (
            exif::Tag::FocalPlaneResolutionUnit,
            exif::Value::Short(vec![3]),
        ),
        (
            exif::Tag::FocalLengthIn35mmFilm,
            // Whole mm, at most 65535 (a SHORT).
            exif::Value::Short(vec![equivalent_35mm.round().clamp(1.0, 65535.0) as u16]),
        ),
    ]
    .map(|(tag, value)| exif::Field {
        tag,
        ifd_num: exif::In::PRIMARY,
        value,
    });
    let mut writer = exif::experimental::Writer::new();
    for field in &fields {
        writer.push_field(field);
    }
    let mut tiff = Cursor::new(Vec::new());
    writer
        .write(&mut tiff, false)
        .expect("EXIF of five fixed fields always encodes");
    tiff.into_inner()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phone_main_camera_is_67_degrees_and_wider_lenses_are_wider() {
        // 4:3 at 26 mm: 2·atan(17.3 / 26).
        let main = fov_from_35mm_equivalent(26.0, 4032, 3024);
        assert!((main - 67.3).abs() < 0.05, "{main}");
        // Orientation does not matter: the longer side is the longer side.
        assert_eq!(main, fov_from_35mm_equivalent(26.0, 3024, 4032));
        // 3:2 at 35 mm: exactly the full frame's 36 mm side, 2·atan(18 / 35).
        let full_frame = fov_from_35mm_equivalent(35.0, 6000, 4000);
        assert!((full_frame - 2.0 * (18.0f64 / 35.0).atan().to_degrees()).abs() < 1e-9);
        // A square at f: the half-diagonal over √2 per side.
        let square = fov_from_35mm_equivalent(15.3, 512, 512);
        assert!((square - 90.0).abs() < 0.1, "{square}");
        assert!(fov_from_35mm_equivalent(13.0, 4, 3) > 100.0);
        assert!(fov_from_35mm_equivalent(77.0, 4, 3) < 30.0);
    }

    #[test]
    fn the_focal_plane_record_gives_the_sensor_width_over_twice_the_focal_length() {
        // 36 mm across the long side at 35 mm: the full frame again, now from the pitch.
        let lens = LensRecord::FocalPlane {
            focal_length_mm: 35.0,
            pixels_per_mm: 6000.0 / 36.0,
        };
        let fov = lens.fov_degrees(6000, 4000);
        assert!((fov - 2.0 * (18.0f64 / 35.0).atan().to_degrees()).abs() < 1e-9);
        assert_eq!(fov, lens.fov_degrees(4000, 6000));
    }
}
