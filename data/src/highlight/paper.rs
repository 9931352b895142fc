//! `paper`: the light detector of PhotoMat, exactly as the paper describes it (§"Dataset
//! collection"; `docs/neural-models.md`, "Light detector").
//!
//! 1. intensity = per-pixel min(R, G, B), linearised with gamma 2.2;
//! 2. threshold = the mean intensity;
//! 3. highlight = intensity-weighted centroid of the pixel centres whose intensity is above
//!    the threshold.
//!
//! The paper sets the light "manually" to the image centre where detection is wrong. Here the
//! failure rule is automatic, and every rule falls back to the centre with its reason:
//! - **flat**: no pixel lies above the mean (a constant or black image);
//! - **too spread**: more than [`PaperDetector::max_spread`] (60 %) of the pixels lie above
//!   the mean, i.e. no compact bright lobe stands out of the image;
//! - **too far**: the centroid lies more than [`PaperDetector::max_offset`] (35 % of the width)
//!   from the centre: the photos are taken with the flash centred, and the centroid of a
//!   lobe cut by the image border is unreliable anyway.
//!
//! Known bias: the centroid of the above-mean region is pulled towards the image centre by lens
//! vignetting, by ambient light and by the border cutting the lobe; [`super::robust`] removes it.

use photomat_core::Result;
use photomat_core::image_io::PlanarImage;

use super::intensity::min_rgb_linear;
use super::{Detection, HighlightDetector};

/// The paper's detector with its failure limits.
#[derive(Debug, Clone)]
pub struct PaperDetector {
    /// Largest accepted distance of the centroid from the image centre, as a fraction of the
    /// image width (default 0.35: the flash is aimed at the centre; 35 % leaves 15 % of the
    /// width between the highlight and the border).
    pub max_offset: f64,
    /// Largest accepted fraction of pixels above the mean (default 0.6: under a centred flash
    /// on a uniform matte sample 42 % of a side-2 photo is above the mean; 60 % means no lobe).
    pub max_spread: f64,
}

impl Default for PaperDetector {
    fn default() -> Self {
        Self {
            max_offset: 0.35,
            max_spread: 0.6,
        }
    }
}

impl HighlightDetector for PaperDetector {
    fn name(&self) -> &'static str {
        "paper"
    }

    fn detect(&self, image: &PlanarImage) -> Result<Detection> {
        let intensity = min_rgb_linear(image)?;
        let (h, w) = (image.height, image.width);
        let mean = intensity.iter().sum::<f64>() / intensity.len() as f64;
        // "Above the mean" beyond the rounding of the sum (relative 1e-9 ≫ n·ε for n ≤ 10⁸),
        // so that a constant image has no pixel above its own mean.
        let threshold = mean * (1.0 + 1e-9);
        let (mut sum, mut sum_row, mut sum_col, mut above) = (0.0, 0.0, 0.0, 0usize);
        for (t, &v) in intensity.iter().enumerate() {
            if v > threshold {
                above += 1;
                sum += v;
                sum_row += v * ((t / w) as f64 + 0.5);
                sum_col += v * ((t % w) as f64 + 0.5);
            }
        }
        if above == 0 {
            return Ok(Detection::fallback(
                h,
                w,
                "no pixel is brighter than the mean intensity (flat or black image)",
            ));
        }
        let spread = above as f64 / intensity.len() as f64;
        if spread > self.max_spread {
            return Ok(Detection::fallback(
                h,
                w,
                format!(
                    "highlight too spread: {:.0} % of the pixels are above the mean intensity \
                     (limit {:.0} %)",
                    100.0 * spread,
                    100.0 * self.max_spread
                ),
            ));
        }
        let (row, col) = (sum_row / sum, sum_col / sum);
        let offset = (row - h as f64 / 2.0).hypot(col - w as f64 / 2.0) / w as f64;
        if offset > self.max_offset {
            return Ok(Detection::fallback(
                h,
                w,
                format!(
                    "centroid ({row:.1}, {col:.1}) is {:.0} % of the width from the centre \
                     (limit {:.0} %)",
                    100.0 * offset,
                    100.0 * self.max_offset
                ),
            ));
        }
        Ok(Detection::detected(row, col, h, w))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::highlight::DetectionStatus;

    /// A grey image with one bright square of `half`-pixel half-width centred at (r, c).
    fn spot(size: usize, r: usize, c: usize, half: usize) -> PlanarImage {
        let mut image = PlanarImage::filled(3, size, size, 0.2);
        for ch in 0..3 {
            for row in r - half..r + half {
                for col in c - half..c + half {
                    image.data[(ch * size + row) * size + col] = 1.0;
                }
            }
        }
        image
    }

    #[test]
    fn paper_finds_the_centre_of_a_bright_square() {
        let d = PaperDetector::default()
            .detect(&spot(64, 20, 40, 4))
            .unwrap();
        assert_eq!(d.status, DetectionStatus::Detected);
        // Pixels 16..24 have centres 16.5..23.5: their mean is 20.0.
        assert!(
            (d.row - 20.0).abs() < 1e-9 && (d.col - 40.0).abs() < 1e-9,
            "{d:?}"
        );
    }

    #[test]
    fn paper_falls_back_on_flat_spread_and_far_images() {
        let detector = PaperDetector::default();
        let flat = detector.detect(&PlanarImage::filled(3, 8, 8, 0.5)).unwrap();
        assert_eq!(flat.status, DetectionStatus::FallbackCentre);
        assert!(flat.reason.unwrap().contains("flat"));
        // Everything bright but one dark corner: 15/16 of the pixels above the mean.
        let mut spread = PlanarImage::filled(1, 4, 4, 1.0);
        spread.data[0] = 0.0;
        let d = detector.detect(&spread).unwrap();
        assert!(d.reason.unwrap().contains("too spread"));
        let far = detector.detect(&spot(64, 6, 6, 3)).unwrap();
        assert_eq!((far.row, far.col), (32.0, 32.0));
        assert!(far.reason.unwrap().contains("from the centre"));
    }
}
