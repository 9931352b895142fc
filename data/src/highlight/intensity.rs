//! The intensity map both detectors start from (paper §"Dataset collection"): per pixel the
//! minimum of R, G and B, linearised with gamma 2.2.
//!
//! The minimum suppresses coloured diffuse reflection relative to the (white, for dielectrics)
//! specular highlight; the gamma undoes the display encoding so that values add like light.

use photomat_core::image_io::PlanarImage;
use photomat_core::render::DISPLAY_GAMMA;
use photomat_core::{Error, Result};

/// Linear min(R, G, B) per pixel, row-major `height·width` values in [0, 1].
pub(crate) fn min_rgb_linear(image: &PlanarImage) -> Result<Vec<f64>> {
    check(image)?;
    let plane = image.texels();
    let colour = if image.channels >= 3 { 3 } else { 1 };
    let lut = gamma_lut();
    Ok((0..plane)
        .map(|t| {
            let encoded = (0..colour)
                .map(|c| image.data[c * plane + t])
                .fold(f32::INFINITY, f32::min);
            linearise(encoded, &lut)
        })
        .collect())
}

/// Number of entries of the linearisation table: 4096 steps keep the interpolated `x^2.2`
/// within 1e-6 of the exact power, far below an 8-bit or 16-bit step.
const LUT_STEPS: usize = 4096;

fn gamma_lut() -> Vec<f64> {
    (0..=LUT_STEPS)
        .map(|i| (i as f64 / LUT_STEPS as f64).powf(DISPLAY_GAMMA))
        .collect()
}

/// `clamp(v, 0, 1)^2.2` by linear interpolation in `lut` (NaN reads as 0).
fn linearise(v: f32, lut: &[f64]) -> f64 {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) } as f64 * LUT_STEPS as f64;
    let i = (v as usize).min(LUT_STEPS - 1);
    let t = v - i as f64;
    lut[i] + (lut[i + 1] - lut[i]) * t
}

fn check(image: &PlanarImage) -> Result<()> {
    if image.texels() == 0 {
        return Err(Error::Invalid(
            "highlight detection needs a non-empty image".into(),
        ));
    }
    if !matches!(image.channels, 1 | 3 | 4) {
        return Err(Error::Invalid(format!(
            "highlight detection reads grey, RGB or RGBA images, not {} channels",
            image.channels
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intensity_is_min_rgb_to_the_gamma() {
        let image = PlanarImage::new(3, 1, 2, vec![0.5, 1.0, 0.8, 0.2, 0.9, 0.7]).unwrap();
        let y = min_rgb_linear(&image).unwrap();
        assert!((y[0] - 0.5f64.powf(2.2)).abs() < 1e-6, "{y:?}");
        assert!((y[1] - 0.2f64.powf(2.2)).abs() < 1e-6, "{y:?}");
        let grey = PlanarImage::new(1, 1, 1, vec![1.0]).unwrap();
        assert_eq!(min_rgb_linear(&grey).unwrap(), vec![1.0]);
        assert!(min_rgb_linear(&PlanarImage::filled(2, 1, 1, 0.5)).is_err());
    }
}
