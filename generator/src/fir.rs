//! The [1, 3, 3, 1] FIR resampling filter of StyleGAN2 (`upfirdn2d` in the StyleGAN2-ADA code;
//! Karras et al. 2020, Appendix B "resampling with bilinear filtering", after Zhang 2019).
//!
//! Per axis the filter is `f = [1, 3, 3, 1]/8` (sum 1); 2-D filtering is separable. As in
//! StyleGAN2:
//!
//! - **×2 upsampling** inserts zeros and filters with gain 2 per axis (4 in 2-D), which gives
//!   `out[2i] = ¼·x[i − 1] + ¾·x[i]` and `out[2i + 1] = ¾·x[i] + ¼·x[i + 1]` (StyleGAN2's
//!   paddings `(2, 1)`).
//! - **×2 downsampling** filters and keeps every second sample:
//!   `out[j] = (x[2j − 1] + 3·x[2j] + 3·x[2j + 1] + x[2j + 2])/8` (paddings `(1, 1)`).
//! - **blur before a stride-2 3×3 conv** (StyleGAN2's `conv2d_resample` with `down = 2`):
//!   pads by `(2, 2)` and filters at full rate, `out[m] = (x[m − 2] + 3x[m − 1] + 3x[m] +
//!   x[m + 1])/8` for m = 0 … n, one sample longer than the input; an unpadded 3×3 stride-2
//!   conv then yields n/2 samples.
//!
//! Outside the image the signal is zero ([`Padding::Zeros`], StyleGAN2) or periodic
//! ([`Padding::Circular`], tileable G): wrapped taps then land on the opposite edge, so the
//! resampled image is one period of the resampled tiling and resampling commutes with rolls.
//!
//! # Implementation
//! Each axis is one product with a constant banded matrix (`out = M · x`), as the estimator's
//! periodic upsampling: matmul has exact first and second derivatives in candle 0.11, where
//! `upsample_nearest2d`'s backward is wrong and depthwise convolution is ≈ 80× slower
//! (DESIGN §6). Dense matrices cost O(n) multiply-adds per output instead of 4, which is
//! negligible up to 256² and still acceptable at 1024² next to the 3×3 convs.

use candle_core::{DType, Device, Result, Tensor, bail};

use crate::padding::Padding;

/// The 1-D taps of the filter, before normalisation.
pub const FIR_TAPS: [f64; 4] = [1.0, 3.0, 3.0, 1.0];
/// Sum of [`FIR_TAPS`] (the normalisation).
pub const FIR_SUM: f64 = 8.0;

/// Adds `weight` at column `col` (an index that may fall outside 0 … n − 1) of `row`:
/// wrapped for circular padding, dropped for zero padding.
fn add_tap(m: &mut [f64], n: usize, row: usize, col: isize, weight: f64, mode: Padding) {
    let inside = (0..n as isize).contains(&col);
    match (inside, mode) {
        (true, _) => m[row * n + col as usize] += weight,
        (false, Padding::Circular) => m[row * n + col.rem_euclid(n as isize) as usize] += weight,
        (false, Padding::Zeros) => {}
    }
}

/// Builds a `rows` × `n` matrix whose row `r` applies `taps` to the inputs `start(r)`,
/// `start(r) + 1`, … (indices outside the axis wrapped or dropped per `mode`).
fn banded(
    rows: usize,
    n: usize,
    start: impl Fn(usize) -> isize,
    taps: &[f64],
    mode: Padding,
    dtype: DType,
    device: &Device,
) -> Result<Tensor> {
    if n == 0 {
        bail!("cannot resample an axis of length 0");
    }
    let mut m = vec![0f64; rows * n];
    for r in 0..rows {
        for (k, &t) in taps.iter().enumerate() {
            add_tap(&mut m, n, r, start(r) + k as isize, t, mode);
        }
    }
    Tensor::from_vec(m, (rows, n), device)?.to_dtype(dtype)
}

/// The ×2 upsampling matrix of one axis: `out = U · x`, (2n, n). Rows sum to 1 (in the
/// interior, and everywhere for circular padding); columns sum to 2 (the upsampling gain).
pub fn upsample_matrix(n: usize, mode: Padding, dtype: DType, device: &Device) -> Result<Tensor> {
    // Zero-stuffing then filtering with gain 2 leaves two taps per output: row 2i reads
    // x[i − 1], x[i] with 2·1/8, 2·3/8; row 2i + 1 reads x[i], x[i + 1] with 2·3/8, 2·1/8.
    let mut m = vec![0f64; 2 * n * n];
    if n == 0 {
        bail!("cannot resample an axis of length 0");
    }
    for i in 0..n {
        let i = i as isize;
        add_tap(
            &mut m,
            n,
            2 * i as usize,
            i - 1,
            FIR_TAPS[0] * 2.0 / FIR_SUM,
            mode,
        );
        add_tap(
            &mut m,
            n,
            2 * i as usize,
            i,
            FIR_TAPS[2] * 2.0 / FIR_SUM,
            mode,
        );
        add_tap(
            &mut m,
            n,
            2 * i as usize + 1,
            i,
            FIR_TAPS[1] * 2.0 / FIR_SUM,
            mode,
        );
        add_tap(
            &mut m,
            n,
            2 * i as usize + 1,
            i + 1,
            FIR_TAPS[3] * 2.0 / FIR_SUM,
            mode,
        );
    }
    Tensor::from_vec(m, (2 * n, n), device)?.to_dtype(dtype)
}

/// The ×2 downsampling matrix of one axis: `out = D · x`, (n/2, n); n must be even. Rows sum
/// to 1 (in the interior, everywhere for circular padding).
pub fn downsample_matrix(n: usize, mode: Padding, dtype: DType, device: &Device) -> Result<Tensor> {
    if n % 2 != 0 {
        bail!("cannot downsample an axis of odd length {n}");
    }
    let taps = FIR_TAPS.map(|t| t / FIR_SUM);
    banded(n / 2, n, |j| 2 * j as isize - 1, &taps, mode, dtype, device)
}

/// The blur applied before a stride-2 3×3 conv: (n + 1, n), row m reads x[m − 2 … m + 1].
pub fn blur_matrix(n: usize, mode: Padding, dtype: DType, device: &Device) -> Result<Tensor> {
    let taps = FIR_TAPS.map(|t| t / FIR_SUM);
    banded(n + 1, n, |m| m as isize - 2, &taps, mode, dtype, device)
}

/// Applies `m_h` to the rows and `m_w` to the columns of every plane: `M_H · X · M_Wᵀ`.
///
/// # Shapes
/// x (B, C, H, W), m_h (H', H), m_w (W', W) → (B, C, H', W').
pub fn apply_separable(x: &Tensor, m_h: &Tensor, m_w: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    let (h2, _) = m_h.dims2()?;
    let (w2, _) = m_w.dims2()?;
    // Columns: one large (B·C·H, W) · (W, W') product over contiguous rows.
    let y = x.contiguous()?.reshape((b * c * h, w))?.matmul(&m_w.t()?)?;
    // Rows: (H', H) · (H, W') per plane, the matrix broadcast with batch stride 0.
    let y = y.reshape((b * c, h, w2))?;
    let y = m_h.broadcast_left(b * c)?.matmul(&y)?;
    y.reshape((b, c, h2, w2))
}

/// StyleGAN2 ×2 FIR upsampling (`upfirdn2d.upsample2d`).
///
/// # Shapes
/// (B, C, H, W) → (B, C, 2H, 2W).
pub fn upsample2d(x: &Tensor, mode: Padding) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    let m_h = upsample_matrix(h, mode, x.dtype(), x.device())?;
    let m_w = upsample_matrix(w, mode, x.dtype(), x.device())?;
    apply_separable(x, &m_h, &m_w)
}

/// StyleGAN2 ×2 FIR downsampling (`upfirdn2d.downsample2d`).
///
/// # Shapes
/// (B, C, H, W) → (B, C, H/2, W/2); H and W even.
pub fn downsample2d(x: &Tensor, mode: Padding) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    let m_h = downsample_matrix(h, mode, x.dtype(), x.device())?;
    let m_w = downsample_matrix(w, mode, x.dtype(), x.device())?;
    apply_separable(x, &m_h, &m_w)
}

/// The blur before a stride-2 3×3 conv (see the module docs).
///
/// # Shapes
/// (B, C, H, W) → (B, C, H + 1, W + 1).
pub fn blur_for_strided_conv(x: &Tensor, mode: Padding) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    let m_h = blur_matrix(h, mode, x.dtype(), x.device())?;
    let m_w = blur_matrix(w, mode, x.dtype(), x.device())?;
    apply_separable(x, &m_h, &m_w)
}
