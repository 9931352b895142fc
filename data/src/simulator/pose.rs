//! The phone's pose in a simulated photo: a camera tilted away from the plane's normal and a
//! flash beside the lens, as in hand-held photos (docs/datasets.md, "A phone held at an
//! angle"). The overhead pose, camera looking straight down with the flash in the lens, is the
//! training convention of docs/conventions.md and what the simulator uses by default.
//!
//! Frames. The untilted camera sits at `C = (hx, hy, 1)` above the jittered highlight
//! `(hx, hy)` and sees the centred square of side 2 (pixel (row, col) looks along `q − C`,
//! `q` its texel centre on that square: an off-axis pinhole whose image plane is parallel to
//! the material). A pose rotates that camera rigidly about `C` by `tilt` around the horizontal
//! axis at angle `tilt_azimuth` from +x, and puts the flash at `C + R·(ox, oy, 0)`: an offset
//! in the phone's own plane. Pixel rays become `R·(q − C)`; a tilted camera sees the plane
//! stretched and the highlight, the mirror point of the flash, moves away from the centre.
//!
//! What a pose changes is only where each pixel looks and where the light comes from: the
//! camera pipeline (vignetting, beam profile) works in the phone's frame and is the same for
//! every pose ([`super::camera`]).

use glam::{DMat3, DVec3};
use photomat_core::{Error, Highlight, Result};
use rand::Rng;

use super::random::uniform;

/// Largest tilt a pose may have, in degrees: beyond it the far corner rays of the simulator's
/// 90° view approach the horizon (a corner ray already leaves the lens 55° off the axis), and a
/// phone photo of a flat material is not taken that obliquely.
pub const MAX_TILT_DEGREES: f64 = 30.0;

/// Largest flash offset, as a fraction of the camera's height: a phone's LED sits 1–2 cm from
/// the lens, i.e. under 10 % of the 10–30 cm it is held from the material; 0.25 leaves room for
/// experiments without letting the flash leave the phone.
pub const MAX_FLASH_OFFSET: f64 = 0.25;

/// Where the phone is and which way it looks, relative to the overhead pose above the
/// highlight. Serialised as the `pose` record of `simulation.json` (absent for the overhead
/// pose, so overhead runs keep their earlier bytes).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhonePose {
    /// Angle between the optical axis and the plane's normal, degrees.
    pub tilt_degrees: f64,
    /// Direction of the tilt's rotation axis, degrees from +x in the plane.
    pub tilt_azimuth_degrees: f64,
    /// The flash's position relative to the lens in the phone's plane (x, y), world units (the
    /// camera is at height 1, so this is also a fraction of the distance).
    pub flash_offset: [f64; 2],
}

impl PhonePose {
    /// Camera looking straight down, flash in the lens: the training convention.
    pub const OVERHEAD: PhonePose = PhonePose {
        tilt_degrees: 0.0,
        tilt_azimuth_degrees: 0.0,
        flash_offset: [0.0, 0.0],
    };

    /// Whether this is [`Self::OVERHEAD`].
    pub fn is_overhead(&self) -> bool {
        *self == Self::OVERHEAD
    }

    /// Check the ranges ([`MAX_TILT_DEGREES`], [`MAX_FLASH_OFFSET`]); errors name the field.
    pub fn validate(&self) -> Result<()> {
        let fields = [
            self.tilt_degrees,
            self.tilt_azimuth_degrees,
            self.flash_offset[0],
            self.flash_offset[1],
        ];
        if fields.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!("pose {self:?} is not finite")));
        }
        if !(0.0..=MAX_TILT_DEGREES).contains(&self.tilt_degrees) {
            return Err(Error::Invalid(format!(
                "pose tilt_degrees = {} is out of range [0, {MAX_TILT_DEGREES}]",
                self.tilt_degrees
            )));
        }
        let offset = DVec3::new(self.flash_offset[0], self.flash_offset[1], 0.0).length();
        if offset > MAX_FLASH_OFFSET {
            return Err(Error::Invalid(format!(
                "pose flash_offset of length {offset} is beyond {MAX_FLASH_OFFSET} (a fraction \
                 of the camera's height)"
            )));
        }
        Ok(())
    }

    /// The rotation R of the phone.
    fn rotation(&self) -> DMat3 {
        let azimuth = self.tilt_azimuth_degrees.to_radians();
        let axis = DVec3::new(azimuth.cos(), azimuth.sin(), 0.0);
        DMat3::from_axis_angle(axis, self.tilt_degrees.to_radians())
    }

    /// The lens, `C`, for a photo whose untilted camera is above `highlight`.
    pub fn camera(&self, highlight: Highlight) -> DVec3 {
        highlight.flash_position()
    }

    /// The flash, `C + R·(ox, oy, 0)`.
    pub fn flash(&self, highlight: Highlight) -> DVec3 {
        let [ox, oy] = self.flash_offset;
        self.camera(highlight) + self.rotation() * DVec3::new(ox, oy, 0.0)
    }

    /// Where pixel (row, col) of an S×S photo (spanning `side` when overhead) looks: the
    /// point on the plane z = 0 its centre ray hits. Continuous coordinates, so (row + ½,
    /// col + ½) is the centre of pixel (row, col).
    pub fn plane_point(
        &self,
        highlight: Highlight,
        (row, col): (f64, f64),
        size: usize,
        side: f64,
    ) -> Result<DVec3> {
        let camera = self.camera(highlight);
        let on_untilted = Highlight::from_pixel_on(row, col, size, side);
        let untilted = DVec3::new(on_untilted.x, on_untilted.y, 0.0) - camera;
        let ray = self.rotation() * untilted;
        // A ray at least ~0.06° below the horizon: anything flatter meets the plane beyond
        // 1000 camera heights, which no photo of a material shows.
        if ray.z >= -1e-3 * ray.length() {
            return Err(Error::Invalid(format!(
                "pose {self:?}: pixel ({row}, {col}) of a {size}² photo looks at the horizon, \
                 not at the material"
            )));
        }
        Ok(camera + ray * (-camera.z / ray.z))
    }

    /// The pixel (row, col), continuous, that sees `point` on the plane: the inverse of
    /// [`Self::plane_point`].
    pub fn pixel_of(
        &self,
        highlight: Highlight,
        point: DVec3,
        size: usize,
        side: f64,
    ) -> (f64, f64) {
        let camera = self.camera(highlight);
        let untilted = self.rotation().transpose() * (point - camera);
        let on_plane = camera + untilted * (-camera.z / untilted.z);
        Highlight::new(on_plane.x, on_plane.y).to_pixel_on(size, side)
    }

    /// The highlight: the mirror point of the flash on the plane as the lens sees it, where a
    /// flat mirror would show the flash (the line from `C` to the flash reflected below the
    /// plane crosses z = 0 there).
    pub fn mirror_point(&self, highlight: Highlight) -> DVec3 {
        let camera = self.camera(highlight);
        let flash = self.flash(highlight);
        let mirrored = DVec3::new(flash.x, flash.y, -flash.z);
        camera + (mirrored - camera) * (camera.z / (camera.z + flash.z))
    }

    /// The plane points the pixel centres of an S×S photo look at, row-major.
    pub fn plane_points(&self, highlight: Highlight, size: usize, side: f64) -> Result<Vec<DVec3>> {
        let mut points = Vec::with_capacity(size * size);
        for row in 0..size {
            for col in 0..size {
                let centre = (row as f64 + 0.5, col as f64 + 0.5);
                points.push(self.plane_point(highlight, centre, size, side)?);
            }
        }
        Ok(points)
    }
}

/// A distribution of phone poses: tilt uniform in `[0, max_tilt_degrees]` about a uniformly
/// random horizontal axis, flash offset of uniform length in `flash_offset` in a uniformly
/// random direction of the phone's plane. The default is the overhead pose only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseJitter {
    /// Largest tilt, degrees (≤ [`MAX_TILT_DEGREES`]).
    pub max_tilt_degrees: f64,
    /// Range of the flash's distance from the lens, fraction of the camera's height
    /// (≤ [`MAX_FLASH_OFFSET`]).
    pub flash_offset: (f64, f64),
}

impl Default for PoseJitter {
    fn default() -> Self {
        Self {
            max_tilt_degrees: 0.0,
            flash_offset: (0.0, 0.0),
        }
    }
}

impl PoseJitter {
    /// Tilts and flash offsets like the independent validation photos (`validation/`: tilt
    /// 0–12°, flash 3–7 % of the distance off the lens).
    pub const HAND_HELD: PoseJitter = PoseJitter {
        max_tilt_degrees: 12.0,
        flash_offset: (0.03, 0.07),
    };

    /// Whether every draw is the overhead pose (then nothing is drawn).
    pub fn is_overhead(&self) -> bool {
        self.max_tilt_degrees == 0.0 && self.flash_offset == (0.0, 0.0)
    }

    /// Check the ranges; errors name the setting.
    pub fn validate(&self) -> Result<()> {
        if !(self.max_tilt_degrees.is_finite()
            && (0.0..=MAX_TILT_DEGREES).contains(&self.max_tilt_degrees))
        {
            return Err(Error::Invalid(format!(
                "the largest tilt must lie in [0, {MAX_TILT_DEGREES}] degrees, got {}",
                self.max_tilt_degrees
            )));
        }
        let (lo, hi) = self.flash_offset;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi && hi <= MAX_FLASH_OFFSET) {
            return Err(Error::Invalid(format!(
                "the flash offset range must satisfy 0 ≤ lo ≤ hi ≤ {MAX_FLASH_OFFSET}, got \
                 {lo}..{hi}"
            )));
        }
        Ok(())
    }

    /// One pose (four draws: tilt, its azimuth, offset length, offset direction).
    pub fn sample(&self, rng: &mut impl Rng) -> PhonePose {
        let tilt = uniform(rng, (0.0, self.max_tilt_degrees));
        let azimuth = uniform(rng, (0.0, 360.0));
        let offset = uniform(rng, self.flash_offset);
        let direction = uniform(rng, (0.0, std::f64::consts::TAU));
        PhonePose {
            tilt_degrees: tilt,
            tilt_azimuth_degrees: azimuth,
            flash_offset: [offset * direction.cos(), offset * direction.sin()],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::random::photo_rng;
    use approx::assert_abs_diff_eq;
    use photomat_core::flash::texel_center_on;

    const SIDE: f64 = 2.0;

    fn posed() -> PhonePose {
        PhonePose {
            tilt_degrees: 12.0,
            tilt_azimuth_degrees: 37.0,
            flash_offset: [0.04, -0.03],
        }
    }

    #[test]
    fn overhead_pixels_look_at_their_texel_centres() {
        let highlight = Highlight::new(0.07, -0.05);
        let points = PhonePose::OVERHEAD
            .plane_points(highlight, 8, SIDE)
            .unwrap();
        for row in 0..8 {
            for col in 0..8 {
                let expected = texel_center_on(row, col, 8, SIDE);
                let got = points[row * 8 + col];
                assert_abs_diff_eq!(got.x, expected.x, epsilon = 1e-12);
                assert_abs_diff_eq!(got.y, expected.y, epsilon = 1e-12);
                assert_abs_diff_eq!(got.z, 0.0, epsilon = 1e-12);
            }
        }
        let mirror = PhonePose::OVERHEAD.mirror_point(highlight);
        assert_abs_diff_eq!(mirror.x, highlight.x, epsilon = 1e-12);
        assert_abs_diff_eq!(mirror.y, highlight.y, epsilon = 1e-12);
    }

    #[test]
    fn pixel_of_inverts_plane_point() {
        let highlight = Highlight::new(-0.1, 0.08);
        for (row, col) in [(0.5, 0.5), (10.25, 50.0), (63.5, 0.5), (32.0, 32.0)] {
            let p = posed()
                .plane_point(highlight, (row, col), 64, SIDE)
                .unwrap();
            assert_abs_diff_eq!(p.z, 0.0, epsilon = 1e-12);
            let (r, c) = posed().pixel_of(highlight, p, 64, SIDE);
            assert_abs_diff_eq!(r, row, epsilon = 1e-9);
            assert_abs_diff_eq!(c, col, epsilon = 1e-9);
        }
    }

    #[test]
    fn the_mirror_point_reflects_the_flash_into_the_lens() {
        let highlight = Highlight::new(0.03, 0.02);
        let pose = posed();
        let p = pose.mirror_point(highlight);
        assert_abs_diff_eq!(p.z, 0.0, epsilon = 1e-12);
        let to_camera = (pose.camera(highlight) - p).normalize();
        let to_flash = (pose.flash(highlight) - p).normalize();
        // Equal angles with the normal, and the half vector along it.
        assert_abs_diff_eq!(to_camera.z, to_flash.z, epsilon = 1e-12);
        let half = (to_camera + to_flash).normalize();
        assert_abs_diff_eq!(half.x, 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(half.y, 0.0, epsilon = 1e-12);
    }

    #[test]
    fn a_tilt_moves_the_flash_with_the_phone_and_keeps_its_distance() {
        let highlight = Highlight::CENTER;
        let pose = posed();
        let offset = pose.flash(highlight) - pose.camera(highlight);
        assert_abs_diff_eq!(offset.length(), 0.05, epsilon = 1e-12);
        // The offset lies in the tilted phone's plane: orthogonal to the tilted optical axis.
        let axis = pose.rotation() * DVec3::NEG_Z;
        assert_abs_diff_eq!(offset.dot(axis), 0.0, epsilon = 1e-12);
        assert_abs_diff_eq!(axis.z, -(12.0f64.to_radians().cos()), epsilon = 1e-12);
    }

    #[test]
    fn jitter_draws_within_its_ranges_and_validates() {
        let mut rng = photo_rng(3, 4);
        for _ in 0..200 {
            let pose = PoseJitter::HAND_HELD.sample(&mut rng);
            pose.validate().unwrap();
            assert!(pose.tilt_degrees <= 12.0);
            let length = pose.flash_offset[0].hypot(pose.flash_offset[1]);
            assert!((0.03 - 1e-12..=0.07 + 1e-12).contains(&length), "{length}");
        }
        assert!(PoseJitter::default().is_overhead());
        assert!(
            PoseJitter {
                max_tilt_degrees: 31.0,
                ..PoseJitter::default()
            }
            .validate()
            .is_err()
        );
        assert!(
            PoseJitter {
                flash_offset: (0.1, 0.05),
                ..PoseJitter::default()
            }
            .validate()
            .is_err()
        );
    }
}
