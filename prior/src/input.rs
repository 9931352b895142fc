//! What the relief prior reads: a flash photo in linear radiance, its exposure divided out and
//! compressed, and where each texel lies from the flash (docs/neural-models.md, "Relief
//! prior").
//!
//! - **Photo** (3 channels): the display values decoded with the display gamma to linear
//!   radiance, divided by their mean (a photo's exposure is unknown; the ratio is what the
//!   material and the flash make) and compressed by `ln(1 + ·)`, so that a highlight a hundred
//!   times the mean is a value of 4.6 rather than 100.
//! - **Offset from the flash** (2 channels): `(x − h_x, y − h_y)`, the texel's plane position
//!   less the flash's (the camera and flash at height 1 above the highlight, docs/conventions.md),
//!   in world units: the tangent of the angle under which the texel sees the flash, which sets
//!   where the highlight and the falloff lie whatever the field of view.

use candle_core::{DType, Device, Result, Tensor, bail};
use photomat_core::Highlight;
use photomat_core::render::DISPLAY_GAMMA;

/// Smallest mean linear radiance a photo is divided by: a black photo (mean 0) has no
/// exposure to divide out, and 1e-4 (an 8-bit value of 0.015) keeps the ratio finite.
const MIN_MEAN: f64 = 1e-4;

/// The input of the prior (B, 5, N, N) for photos `photo` (B, 3, N, N) of display values,
/// each taken with the flash above `highlights[b]` on a square of side `side` world units.
pub fn prior_input(photo: &Tensor, highlights: &[Highlight], side: f64) -> Result<Tensor> {
    let (b, c, h, w) = photo.dims4()?;
    if c != 3 || h != w || highlights.len() != b {
        bail!(
            "the prior reads square RGB photos with one highlight each, got ({b}, {c}, {h}, {w}) \
             and {} highlights",
            highlights.len()
        );
    }
    let linear = photo
        .to_dtype(DType::F32)?
        .clamp(0.0, 1.0)?
        .powf(DISPLAY_GAMMA)?;
    let mean = linear
        .mean_keepdim(1)?
        .mean_keepdim(2)?
        .mean_keepdim(3)?
        .clamp(MIN_MEAN, f64::INFINITY)?;
    let ratio = linear.broadcast_div(&mean)?;
    let compressed = (ratio + 1.0)?.log()?;
    let offsets = flash_offsets(highlights, h, side, photo.device())?;
    Tensor::cat(&[compressed, offsets], 1)
}

/// `(x − h_x, y − h_y)` per texel of an `n × n` square of side `side` for each highlight:
/// (B, 2, n, n).
pub fn flash_offsets(
    highlights: &[Highlight],
    n: usize,
    side: f64,
    device: &Device,
) -> Result<Tensor> {
    let texel = side / n as f64;
    let mut data = Vec::with_capacity(highlights.len() * 2 * n * n);
    for hl in highlights {
        for axis in 0..2 {
            for r in 0..n {
                for c in 0..n {
                    // Texel centres: x right from the left edge, y up from the bottom edge.
                    let value = if axis == 0 {
                        (c as f64 + 0.5) * texel - side / 2.0 - hl.x
                    } else {
                        side / 2.0 - (r as f64 + 0.5) * texel - hl.y
                    };
                    data.push(value as f32);
                }
            }
        }
    }
    Tensor::from_vec(data, (highlights.len(), 2, n, n), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_input_divides_out_the_exposure_and_places_the_flash() {
        let device = Device::Cpu;
        let photo = Tensor::full(0.5f32, (1, 3, 4, 4), &device).unwrap();
        let brighter = (photo.clone() * 1.2).unwrap();
        let flash = [Highlight::new(0.25, 0.0)];
        let a = prior_input(&photo, &flash, 2.0).unwrap();
        let b = prior_input(&brighter, &flash, 2.0).unwrap();
        let diff = (a - &b).unwrap().abs().unwrap().max_all().unwrap();
        // A uniform photo's ratio is 1 at any exposure: ln 2 everywhere.
        assert!(diff.to_scalar::<f32>().unwrap() < 1e-5);
        let v: Vec<Vec<f32>> = b.squeeze(0).unwrap().get(0).unwrap().to_vec2().unwrap();
        assert!((v[0][0] - 2f32.ln()).abs() < 1e-5);
        // Offsets: texel (0, 0) of a 4² square of side 2 is at (−0.75, 0.75).
        let o: Vec<Vec<Vec<f32>>> = b
            .squeeze(0)
            .unwrap()
            .narrow(0, 3, 2)
            .unwrap()
            .to_vec3()
            .unwrap();
        assert!((o[0][0][0] - (-0.75 - 0.25)).abs() < 1e-6);
        assert!((o[1][0][0] - 0.75).abs() < 1e-6);
        assert!((o[1][3][3] + 0.75).abs() < 1e-6);
    }
}
