//! The field of view a photo was taken with: given by the user, read from the photo's EXIF, or
//! a phone's main camera (docs/conventions.md, "A photo's field of view").
//!
//! With the camera straight down and the flash beside the lens, the field of view sets how
//! wide the photographed square is at the flash's height ([`crate::square::square_side`]), hence the
//! angles under which every texel saw the flash. A wrong one leaves a ghost of the photo's
//! highlight in the maps: a simulated fabric photo (90°) captured at 67° relit with a bright
//! crescent where the photo's highlight had been, faint at 90° (docs/benchmarks/capture.md, "The
//! capture's field of view from EXIF").
//!
//! The EXIF records of the lens, and how each gives the field of view, are
//! [`photomat_data::dataset::lens`]'s: the focal length with the sensor's pixel pitch (exact;
//! cameras and `photomat simulate` write it), else the 35 mm equivalent focal length (phones
//! write it; 26 mm on 4:3 is 67.3°).

use photomat_data::dataset::lens::{LensRecord, read_lens};
use serde::Serialize;

/// Default field of view across a photo's longer side, in degrees: a phone's main camera
/// (26 mm equivalent focal length on a 4:3 sensor: 2·atan(17.3 / 26) ≈ 67°).
pub const DEFAULT_FOV_DEGREES: f64 = 67.0;

pub use photomat_core::flash::TRAINING_FOV_DEGREES;

/// Fields of view a capture accepts, in degrees: below 5° the photo is a telescope's, above
/// 150° a fisheye's, which a pinhole straight down does not describe.
pub const FOV_RANGE: (f64, f64) = (5.0, 150.0);

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
    /// The photo's EXIF record of its lens.
    Exif { lens: LensRecord },
    /// Neither given nor in the photo: [`DEFAULT_FOV_DEGREES`].
    Default,
}

impl std::fmt::Display for FovSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FovSource::Given => f.write_str("given"),
            FovSource::Exif { lens } => write!(f, "EXIF: {lens}"),
            FovSource::Default => f.write_str("default: no focal length in the photo's EXIF"),
        }
    }
}

/// The field of view of a photo (`bytes`, `width × height` after orientation): `given` when
/// set, else from its EXIF record of the lens, else [`DEFAULT_FOV_DEGREES`]. An EXIF value outside
/// [`FOV_RANGE`] is an error naming it (a pinhole straight down does not describe such a
/// lens; `--fov` overrides it).
pub fn field_of_view(
    given: Option<f64>,
    bytes: &[u8],
    width: usize,
    height: usize,
) -> anyhow::Result<FieldOfView> {
    let fov = match (given, read_lens(bytes)) {
        (Some(degrees), _) => FieldOfView {
            degrees,
            source: FovSource::Given,
        },
        (None, Some(lens)) => FieldOfView {
            degrees: lens.fov_degrees(width, height),
            source: FovSource::Exif { lens },
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
    fn the_default_is_a_phone_main_camera() {
        // 4:3 at 26 mm, the main camera of most phones.
        let main = photomat_data::dataset::lens::fov_from_35mm_equivalent(26.0, 4032, 3024);
        assert!((main - DEFAULT_FOV_DEGREES).abs() < 0.5, "{main}");
    }

    #[test]
    fn a_given_value_wins_and_no_exif_falls_back_to_the_default() {
        let no_exif = b"not an image at all";
        assert_eq!(read_lens(no_exif), None);
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
