//! The field of view a photo was taken with: given by the user, read from the photo's EXIF, or
//! a phone's main camera (docs/conventions.md, "A photo's field of view").
//!
//! With the camera straight down and the flash beside the lens, the field of view sets how
//! wide the photographed square is at the flash's height ([`crate::square_side`]), hence the
//! angles under which every texel saw the flash. A wrong one leaves a ghost of the photo's
//! highlight in the maps: a simulated fabric photo (90°) captured at 67° relit with a bright
//! crescent where the photo's highlight had been, faint at 90° (docs/benchmarks.md, "The
//! capture's field of view from EXIF").
//!
//! Phones write the lens's 35 mm equivalent focal length f₃₅ (EXIF `FocalLengthIn35mmFilm`,
//! CIPA DC-008): the focal length that gives a 36 × 24 mm frame the photo's *diagonal* field
//! of view. Across the longer side of a `w × h` photo the half-width is then the frame's
//! half-diagonal, 21.63 mm, times `long / √(w² + h²)`, so
//!
//! `fov = 2 · atan(21.63 · long / √(w² + h²) / f₃₅)`
//!
//! (4:3, 26 mm: 67.3°, [`crate::DEFAULT_FOV_DEGREES`]; 13 mm ultra-wide: 106°; 77 mm
//! telephoto: 25°). Cropped or digitally zoomed photos record the equivalent of what they
//! show, which is what the capture needs.

use std::io::Cursor;

use serde::Serialize;

use crate::{DEFAULT_FOV_DEGREES, FOV_RANGE};

/// Half the diagonal of the 36 × 24 mm frame the 35 mm equivalent refers to, in mm.
const FULL_FRAME_HALF_DIAGONAL_MM: f64 = 21.633_307_652_783_937; // √(18² + 12²)

/// A field of view across the photo's longer side and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FieldOfView {
    /// Degrees across the longer side.
    pub degrees: f64,
    /// Where the value came from.
    pub source: FovSource,
}

/// Where a [`FieldOfView`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum FovSource {
    /// Given by the caller (`--fov`).
    Given,
    /// The photo's EXIF 35 mm equivalent focal length, in mm.
    Exif { focal_length_35mm: f64 },
    /// Neither given nor in the photo: [`DEFAULT_FOV_DEGREES`].
    Default,
}

impl std::fmt::Display for FovSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FovSource::Given => f.write_str("given"),
            FovSource::Exif { focal_length_35mm } => {
                write!(f, "EXIF: {focal_length_35mm} mm equivalent")
            }
            FovSource::Default => f.write_str("default: no focal length in the photo's EXIF"),
        }
    }
}

/// Degrees across the longer side of a `width × height` photo taken at a 35 mm equivalent
/// focal length of `focal_length_35mm` mm (module docs).
pub fn fov_from_35mm_equivalent(focal_length_35mm: f64, width: usize, height: usize) -> f64 {
    let (w, h) = (width as f64, height as f64);
    let half_long = FULL_FRAME_HALF_DIAGONAL_MM * w.max(h) / w.hypot(h);
    2.0 * (half_long / focal_length_35mm).atan().to_degrees()
}

/// The photo's EXIF 35 mm equivalent focal length in mm, when the file has EXIF with a
/// non-zero one (0 means "unknown" in EXIF). A file without EXIF, or with EXIF that does not
/// parse, has none: the capture then falls back to the default, and says so.
pub fn exif_focal_length_35mm(bytes: &[u8]) -> Option<f64> {
    let exif = exif::Reader::new()
        .read_from_container(&mut Cursor::new(bytes))
        .ok()?;
    let field = exif.get_field(exif::Tag::FocalLengthIn35mmFilm, exif::In::PRIMARY)?;
    let mm = field.value.get_uint(0)?;
    (mm > 0).then_some(mm as f64)
}

/// The field of view of a photo (`bytes`, `width × height` after orientation): `given` when
/// set, else from its EXIF focal length, else [`DEFAULT_FOV_DEGREES`]. An EXIF value outside
/// [`FOV_RANGE`] is an error naming it (a pinhole straight down does not describe such a
/// lens; `--fov` overrides it).
pub fn field_of_view(
    given: Option<f64>,
    bytes: &[u8],
    width: usize,
    height: usize,
) -> anyhow::Result<FieldOfView> {
    let fov = match (given, exif_focal_length_35mm(bytes)) {
        (Some(degrees), _) => FieldOfView {
            degrees,
            source: FovSource::Given,
        },
        (None, Some(mm)) => FieldOfView {
            degrees: fov_from_35mm_equivalent(mm, width, height),
            source: FovSource::Exif {
                focal_length_35mm: mm,
            },
        },
        (None, None) => FieldOfView {
            degrees: DEFAULT_FOV_DEGREES,
            source: FovSource::Default,
        },
    };
    let (lo, hi) = FOV_RANGE;
    if !(lo..=hi).contains(&fov.degrees) {
        anyhow::bail!(
            "field of view {:.1}° ({}) is outside {lo} … {hi}°",
            fov.degrees,
            fov.source
        );
    }
    Ok(fov)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_phone_main_camera_gives_the_default_and_wider_lenses_wider_views() {
        // 4:3 at 26 mm: 2·atan(17.3 / 26), the default's definition, to its rounding.
        let main = fov_from_35mm_equivalent(26.0, 4032, 3024);
        assert!((main - 67.3).abs() < 0.05, "{main}");
        assert!((main - DEFAULT_FOV_DEGREES).abs() < 0.5);
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
    fn a_given_value_wins_and_no_exif_falls_back_to_the_default() {
        let no_exif = b"not an image at all";
        assert_eq!(exif_focal_length_35mm(no_exif), None);
        let given = field_of_view(Some(80.0), no_exif, 4, 3).unwrap();
        assert_eq!((given.degrees, given.source), (80.0, FovSource::Given));
        let default = field_of_view(None, no_exif, 4, 3).unwrap();
        assert_eq!(
            (default.degrees, default.source),
            (DEFAULT_FOV_DEGREES, FovSource::Default)
        );
        let err = field_of_view(Some(170.0), no_exif, 4, 3).unwrap_err();
        assert!(err.to_string().contains("170.0°"), "{err}");
    }
}
