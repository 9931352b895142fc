//! Flash-plane geometry (`docs/conventions.md`, "Geometry and radiometry"; the paper's
//! §"Dataset collection" set-up).
//!
//! The material is a square of side [`PLANE_SIDE`] = 1 centred at the origin in z = 0, normal
//! +z, image row 0 at the top (+y). Camera and flash are collocated at `(lx, ly, 1)`: the
//! height equals the plane side, as the paper assumes for phone cameras. `(lx, ly)` is the
//! highlight position. Per texel, light and view direction are both `ω = normalize(L − p)`.

use candle_core::{DType, Device, Tensor};
use glam::DVec3;

use crate::{Error, Result};

/// Side length of the material square, in world units.
pub const PLANE_SIDE: f64 = 1.0;

/// Side of the material square a whole prepared flash photo spans, in world units (camera and
/// flash at height 1; its H×H training crops of the 2H×2H photo are unit squares, and a
/// spatial generator's texel is `PHOTO_SIDE / S` for S×S photos; `docs/datasets.md`).
pub const PHOTO_SIDE: f64 = 2.0;
/// Height of the collocated camera and flash above the plane.
pub const FLASH_HEIGHT: f64 = 1.0;
/// The field of view, in degrees, under which a square photo spans [`PHOTO_SIDE`] from
/// [`FLASH_HEIGHT`]: 2·atan(1) = 90°, the training data's and the simulator's camera.
pub const TRAINING_FOV_DEGREES: f64 = 90.0;
/// Smallest flash elevation cosine ω_z a texel of a whole prepared photo sees when the
/// highlight is at the photo's centre: its corner, √2 away horizontally under the flash at
/// height 1, gives 1/√3. The relighting MLP M learns from such photos (highlights near the
/// centre), so this angle is one every photo covers: a conservative bound of what M was
/// trained on. Texels lit more obliquely (a material larger than a photo under one flash) are
/// outside it; [`FlashGeometry::within_photo_reach`] marks the others.
pub const PHOTO_REACH_MIN_COS: f64 = 0.577_350_269_189_625_8;
/// Flash intensity: π, so that a flat white Lambertian texel straight under the flash
/// renders exactly its albedo (π · (1/π) · cos 0 / 1²).
pub const FLASH_INTENSITY: f64 = std::f64::consts::PI;

/// Highlight position in plane coordinates (x right, y up, the plane spans [−½, ½]²); the
/// flash sits at `(x, y, FLASH_HEIGHT)`. It may lie outside the plane.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Highlight {
    pub x: f64,
    pub y: f64,
}

impl Highlight {
    /// Flash straight above the centre of the material.
    pub const CENTER: Highlight = Highlight { x: 0.0, y: 0.0 };

    pub fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// The same place on a square `factor` times as large (both coordinates × `factor`): a
    /// position given on the unit square, put on a material of world side `factor`.
    pub fn scaled(self, factor: f64) -> Self {
        Self::new(self.x * factor, self.y * factor)
    }

    /// From continuous pixel coordinates of an R×R image of the unit material square (pixel
    /// (i, j) spans [i, i+1)×[j, j+1)): `x = col/R − ½`, `y = ½ − row/R`.
    pub fn from_pixel(row: f64, col: f64, size: usize) -> Self {
        Self::from_pixel_on(row, col, size, PLANE_SIDE)
    }

    /// Continuous pixel coordinates `(row, col)` in an R×R image; inverse of [`Self::from_pixel`].
    pub fn to_pixel(self, size: usize) -> (f64, f64) {
        self.to_pixel_on(size, PLANE_SIDE)
    }

    /// [`Self::from_pixel`] for an R×R image covering a centred square of side `side` (a whole
    /// flash photo spans side 2: its H×H training crops are unit squares).
    pub fn from_pixel_on(row: f64, col: f64, size: usize, side: f64) -> Self {
        let r = size as f64;
        Self::new((col / r - 0.5) * side, (0.5 - row / r) * side)
    }

    /// Inverse of [`Self::from_pixel_on`].
    pub fn to_pixel_on(self, size: usize, side: f64) -> (f64, f64) {
        let r = size as f64;
        ((0.5 - self.y / side) * r, (self.x / side + 0.5) * r)
    }

    /// Position of the collocated flash and camera.
    pub fn flash_position(self) -> DVec3 {
        DVec3::new(self.x, self.y, FLASH_HEIGHT)
    }
}

/// Centre of texel (row, col) of an R×R map of the unit square:
/// `((col+½)/R − ½, ½ − (row+½)/R, 0)`.
pub fn texel_center(row: usize, col: usize, size: usize) -> DVec3 {
    texel_center_on(row, col, size, PLANE_SIDE)
}

/// Centre of texel (row, col) of an R×R grid covering a centred square of side `side`.
pub fn texel_center_on(row: usize, col: usize, size: usize, side: f64) -> DVec3 {
    let r = size as f64;
    DVec3::new(
        ((col as f64 + 0.5) / r - 0.5) * side,
        (0.5 - (row as f64 + 0.5) / r) * side,
        0.0,
    )
}

/// Per-texel flash geometry of a batch of R×R maps, one highlight per batch item.
#[derive(Debug, Clone)]
pub struct FlashGeometry {
    /// Unit direction from each texel towards the flash (= towards the camera): (B, 3, R, R).
    pub omega: Tensor,
    /// Inverse squared distance texel–flash: (B, 1, R, R).
    pub inv_dist2: Tensor,
}

impl FlashGeometry {
    /// Geometry for `highlights.len()` flash positions over an R×R map of the unit square.
    pub fn new(
        highlights: &[Highlight],
        size: usize,
        dtype: DType,
        device: &Device,
    ) -> Result<Self> {
        Self::with_side(highlights, size, PLANE_SIDE, dtype, device)
    }

    /// The f32 ω maps of `highlights` over R×R samples of the unit square: what the
    /// relighting MLP M reads next to the features F.
    ///
    /// # Shapes
    /// → (highlights.len(), 3, R, R), f32.
    pub fn omega_for(highlights: &[Highlight], size: usize, device: &Device) -> Result<Tensor> {
        Ok(Self::new(highlights, size, DType::F32, device)?.omega)
    }

    /// The geometry of lights `first .. first + n`: the same values as building it for those
    /// highlights alone, so a set built once serves light groups of any size.
    ///
    /// # Shapes
    /// (B, ·, R, R) → (n, ·, R, R).
    pub fn narrow(&self, first: usize, n: usize) -> Result<Self> {
        Ok(Self {
            omega: self.omega.narrow(0, first, n)?,
            inv_dist2: self.inv_dist2.narrow(0, first, n)?,
        })
    }

    /// 1 where a texel sees the flash at least as steeply as the corner of a whole photo under
    /// a centred flash (ω_z ≥ [`PHOTO_REACH_MIN_COS`]), 0 elsewhere: the texels whose
    /// lighting a model trained on photos has seen.
    ///
    /// # Shapes
    /// → (B, 1, R, R), the dtype of ω.
    pub fn within_photo_reach(&self) -> Result<Tensor> {
        let omega_z = self.omega.narrow(1, 2, 1)?;
        // About one f32 ULP of margin: a texel exactly √2 away is not rounded out of reach.
        let threshold = PHOTO_REACH_MIN_COS * (1.0 - f32::EPSILON as f64);
        Ok(omega_z.ge(threshold)?.to_dtype(omega_z.dtype())?)
    }

    /// Geometry over an R×R grid covering a centred square of side `side`, flash still at
    /// height [`FLASH_HEIGHT`] (side 2 is a whole photo whose H×H crops are unit squares).
    pub fn with_side(
        highlights: &[Highlight],
        size: usize,
        side: f64,
        dtype: DType,
        device: &Device,
    ) -> Result<Self> {
        if !(side.is_finite() && side > 0.0) {
            return Err(Error::Invalid(format!(
                "plane side must be positive, got {side}"
            )));
        }
        if highlights.is_empty() || size == 0 {
            return Err(Error::Invalid(
                "flash geometry needs at least one highlight and a non-empty map".into(),
            ));
        }
        if let Some(h) = highlights
            .iter()
            .find(|h| !(h.x.is_finite() && h.y.is_finite()))
        {
            return Err(Error::Invalid(format!(
                "highlight ({}, {}) is not finite",
                h.x, h.y
            )));
        }
        let plane = size * size;
        let mut omega = vec![0f64; highlights.len() * 3 * plane];
        let mut inv_dist2 = vec![0f64; highlights.len() * plane];
        for (b, h) in highlights.iter().enumerate() {
            let light = h.flash_position();
            for row in 0..size {
                for col in 0..size {
                    let to_light = light - texel_center_on(row, col, size, side);
                    let d2 = to_light.length_squared(); // ≥ FLASH_HEIGHT² > 0
                    let w = to_light / d2.sqrt();
                    let t = row * size + col;
                    omega[(b * 3) * plane + t] = w.x;
                    omega[(b * 3 + 1) * plane + t] = w.y;
                    omega[(b * 3 + 2) * plane + t] = w.z;
                    inv_dist2[b * plane + t] = 1.0 / d2;
                }
            }
        }
        let n = highlights.len();
        Ok(Self {
            omega: Tensor::from_vec(omega, (n, 3, size, size), device)?.to_dtype(dtype)?,
            inv_dist2: Tensor::from_vec(inv_dist2, (n, 1, size, size), device)?.to_dtype(dtype)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every texel of a whole photo under a centred flash is within reach; on a square twice
    /// as wide, exactly the texels whose centre lies within √2 of the highlight are.
    #[test]
    fn photo_reach_is_the_disc_of_a_photo_corner() -> Result<()> {
        let photo = FlashGeometry::with_side(
            &[Highlight::CENTER],
            64,
            PHOTO_SIDE,
            DType::F32,
            &Device::Cpu,
        )?;
        let inside = photo.within_photo_reach()?.sum_all()?.to_scalar::<f32>()?;
        assert_eq!(inside, 64.0 * 64.0);

        let highlight = Highlight::new(0.3, -0.2);
        let side = 2.0 * PHOTO_SIDE;
        let wide = FlashGeometry::with_side(&[highlight], 48, side, DType::F64, &Device::Cpu)?;
        let mask = wide.within_photo_reach()?.flatten_all()?.to_vec1::<f64>()?;
        for row in 0..48 {
            for col in 0..48 {
                let p = texel_center_on(row, col, 48, side);
                let horizontal = ((p.x - highlight.x).powi(2) + (p.y - highlight.y).powi(2)).sqrt();
                let expected = if horizontal <= 2f64.sqrt() { 1.0 } else { 0.0 };
                assert_eq!(
                    mask[row * 48 + col],
                    expected,
                    "texel ({row}, {col}) at {horizontal}"
                );
            }
        }
        Ok(())
    }
}
