//! SSIM, the structural similarity index of Wang, Bovik, Sheikh and Simoncelli 2004 ("Image
//! Quality Assessment: From Error Visibility to Structural Similarity"), as the trade study's
//! structure-aware image metric next to L1.
//!
//! The paper's standard form: local means, variances and covariance under an 11×11 Gaussian
//! window of σ = 1.5, `SSIM = (2μxμy + C1)(2σxy + C2) / ((μx² + μy² + C1)(σx² + σy² + C2))` with
//! `C1 = (0.01 L)²`, `C2 = (0.03 L)²` and dynamic range L = 1 (display-encoded images in
//! [0, 1]), averaged over the window positions that lie fully inside the image (no padding),
//! per channel and then over the three channels.
//!
//! Shapes: images (B, 3, H, W) with H, W ≥ 11 → one SSIM per image (B).

use candle_core::{DType, Tensor};

/// Side of the Gaussian window.
pub const WINDOW: usize = 11;
/// Standard deviation of the window, in pixels.
pub const SIGMA: f64 = 1.5;
/// `(K1·L)²` with K1 = 0.01, L = 1: keeps the luminance term finite on black regions.
const C1: f64 = 1e-4;
/// `(K2·L)²` with K2 = 0.03, L = 1: keeps the contrast term finite on flat regions.
const C2: f64 = 9e-4;

/// The normalised 1-D Gaussian window (sums to 1).
fn gaussian_window() -> Vec<f64> {
    let centre = (WINDOW / 2) as f64;
    let raw: Vec<f64> = (0..WINDOW)
        .map(|i| (-((i as f64 - centre).powi(2)) / (2.0 * SIGMA * SIGMA)).exp())
        .collect();
    let sum: f64 = raw.iter().sum();
    raw.into_iter().map(|w| w / sum).collect()
}

/// Each channel filtered by the separable window, valid positions only:
/// (N, 1, H, W) → (N, 1, H − 10, W − 10).
fn filter(x: &Tensor, window: &Tensor) -> candle_core::Result<Tensor> {
    let rows = window.reshape((1, 1, WINDOW, 1))?;
    let cols = window.reshape((1, 1, 1, WINDOW))?;
    x.conv2d(&rows, 0, 1, 1, 1)?.conv2d(&cols, 0, 1, 1, 1)
}

/// SSIM of each image pair, in f64 (B). `a`, `b`: (B, C, H, W), values in [0, 1].
pub fn ssim(a: &Tensor, b: &Tensor) -> candle_core::Result<Vec<f64>> {
    let (batch, channels, height, width) = a.dims4()?;
    if height < WINDOW || width < WINDOW {
        candle_core::bail!("SSIM needs images of at least {WINDOW}×{WINDOW}, got {height}×{width}");
    }
    let x = a
        .to_dtype(DType::F64)?
        .reshape((batch * channels, 1, height, width))?;
    let y = b
        .to_dtype(DType::F64)?
        .reshape((batch * channels, 1, height, width))?;
    let window = Tensor::new(gaussian_window(), a.device())?;
    let mu_x = filter(&x, &window)?;
    let mu_y = filter(&y, &window)?;
    let var_x = (filter(&x.sqr()?, &window)? - mu_x.sqr()?)?;
    let var_y = (filter(&y.sqr()?, &window)? - mu_y.sqr()?)?;
    let cov = (filter(&(&x * &y)?, &window)? - (&mu_x * &mu_y)?)?;
    let luminance = (((&mu_x * &mu_y)? * 2.0)? + C1)?.div(&((mu_x.sqr()? + mu_y.sqr()?)? + C1)?)?;
    let structure = ((cov * 2.0)? + C2)?.div(&((var_x + var_y)? + C2)?)?;
    (luminance * structure)?
        .reshape((batch, ()))?
        .mean(1)?
        .to_vec1()
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    fn image(values: Vec<f64>, side: usize) -> Tensor {
        Tensor::from_vec(values, (1, 1, side, side), &Device::Cpu).unwrap()
    }

    #[test]
    fn ssim_of_an_image_with_itself_is_one() {
        let side = 24;
        let values: Vec<f64> = (0..side * side)
            .map(|i| ((i * 37) % 101) as f64 / 100.0)
            .collect();
        let a = image(values, side).repeat((2, 3, 1, 1)).unwrap();
        for s in ssim(&a, &a).unwrap() {
            assert!((s - 1.0).abs() < 1e-12, "{s}");
        }
    }

    #[test]
    fn ssim_of_two_flat_images_is_the_luminance_term() {
        // Flat images have zero variance, so SSIM = (2ab + C1)/(a² + b² + C1) in closed form.
        let (a, b, side) = (0.3, 0.7, 16);
        let x = image(vec![a; side * side], side);
        let y = image(vec![b; side * side], side);
        let expected = (2.0 * a * b + C1) / (a * a + b * b + C1);
        let got = ssim(&x, &y).unwrap()[0];
        assert!((got - expected).abs() < 1e-12, "{got} vs {expected}");
    }

    #[test]
    fn ssim_falls_with_noise_but_not_with_a_small_offset() {
        // SSIM is built to weigh structure over a uniform shift: a +0.02 offset keeps it near
        // 1, a checkerboard of ±0.02 (same L1) lowers it much more.
        let side = 32;
        let base: Vec<f64> = (0..side * side)
            .map(|i| 0.5 + 0.3 * ((i % side) as f64 / side as f64 - 0.5))
            .collect();
        let shifted: Vec<f64> = base.iter().map(|v| v + 0.02).collect();
        let noisy: Vec<f64> = base
            .iter()
            .enumerate()
            .map(|(i, v)| v + if (i + i / side) % 2 == 0 { 0.02 } else { -0.02 })
            .collect();
        let x = image(base, side);
        let s_shift = ssim(&x, &image(shifted, side)).unwrap()[0];
        let s_noise = ssim(&x, &image(noisy, side)).unwrap()[0];
        assert!(s_shift > 0.99, "{s_shift}");
        assert!(s_noise < s_shift - 0.05, "{s_noise} vs {s_shift}");
    }

    #[test]
    fn ssim_rejects_images_smaller_than_the_window() {
        let x = image(vec![0.5; 64], 8);
        assert!(ssim(&x, &x).is_err());
    }
}
