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
//! Each axis is one product with a constant banded matrix (`out = M · x`), built here once per
//! call as compressed rows ([`photomat_kernels::AxisMatrix`]: 2 or 4 taps per row) and applied
//! by photomat-kernels' sparse separable pass ([`photomat_kernels::separable`]): one pass per
//! axis costing as many multiply-adds per output as the filter has taps, linear, so its
//! backward is the pass of the transposed matrix and it is differentiable to any order (R1
//! through D's blur and downsampling). Inside [`photomat_kernels::with_reference_ops`] (and on
//! other devices) the same matrices are applied densely with candle's `matmul` ([`apply_separable`]),
//! whose first and second derivatives are exact in candle 0.11, where `upsample_nearest2d`'s
//! backward is wrong and depthwise convolution is ≈ 80× slower (`docs/candle-notes.md`).

use candle_core::{DType, Device, Result, Tensor};
use photomat_kernels::AxisMatrix;

use crate::padding::Padding;

/// The 1-D taps of the filter, before normalisation.
pub const FIR_TAPS: [f64; 4] = [1.0, 3.0, 3.0, 1.0];
/// Sum of [`FIR_TAPS`] (the normalisation).
pub const FIR_SUM: f64 = 8.0;

/// Builds the `rows` × `n` matrix whose row `r`, with `(start, taps) = row(r)`, applies
/// `taps` to the inputs `start`, `start + 1`, …: indices outside 0 … n − 1 wrapped for
/// circular padding (adding onto the texel they land on), dropped for zero padding.
fn banded<'a>(
    rows: usize,
    n: usize,
    row: impl Fn(usize) -> (isize, &'a [f64]),
    mode: Padding,
) -> Result<AxisMatrix> {
    let len = n as isize;
    let rows: Vec<Vec<(usize, f64)>> = (0..rows)
        .map(|r| {
            let (start, taps) = row(r);
            taps.iter()
                .enumerate()
                .filter_map(|(k, &t)| {
                    let col = start + k as isize;
                    match ((0..len).contains(&col), mode) {
                        (true, _) => Some((col as usize, t)),
                        (false, Padding::Circular) => Some((col.rem_euclid(len) as usize, t)),
                        (false, Padding::Zeros) => None,
                    }
                })
                .collect()
        })
        .collect();
    AxisMatrix::from_rows(n, &rows)
}

/// The ×2 upsampling matrix of one axis as compressed rows (see [`upsample_matrix`]).
pub fn upsample_axis(n: usize, mode: Padding) -> Result<AxisMatrix> {
    // Zero-stuffing then filtering with gain 2 leaves two taps per output: row 2i reads
    // x[i − 1], x[i] with 2·1/8, 2·3/8; row 2i + 1 reads x[i], x[i + 1] with 2·3/8, 2·1/8.
    let g = 2.0 / FIR_SUM;
    let even = [FIR_TAPS[0] * g, FIR_TAPS[2] * g];
    let odd = [FIR_TAPS[1] * g, FIR_TAPS[3] * g];
    banded(
        2 * n,
        n,
        |r| {
            let i = (r / 2) as isize;
            if r % 2 == 0 {
                (i - 1, &even)
            } else {
                (i, &odd)
            }
        },
        mode,
    )
}

/// The ×2 downsampling matrix of one axis as compressed rows (see [`downsample_matrix`]).
pub fn downsample_axis(n: usize, mode: Padding) -> Result<AxisMatrix> {
    if !n.is_multiple_of(2) {
        candle_core::bail!("cannot downsample an axis of odd length {n}");
    }
    let taps = FIR_TAPS.map(|t| t / FIR_SUM);
    banded(n / 2, n, |j| (2 * j as isize - 1, &taps), mode)
}

/// The blur before a stride-2 3×3 conv as compressed rows (see [`blur_matrix`]).
pub fn blur_axis(n: usize, mode: Padding) -> Result<AxisMatrix> {
    let taps = FIR_TAPS.map(|t| t / FIR_SUM);
    banded(n + 1, n, |m| (m as isize - 2, &taps), mode)
}

/// The ×2 upsampling matrix of one axis: `out = U · x`, (2n, n). Rows sum to 1 (in the
/// interior, and everywhere for circular padding); columns sum to 2 (the upsampling gain).
pub fn upsample_matrix(n: usize, mode: Padding, dtype: DType, device: &Device) -> Result<Tensor> {
    upsample_axis(n, mode)?.to_dense(dtype, device)
}

/// The ×2 downsampling matrix of one axis: `out = D · x`, (n/2, n); n must be even. Rows sum
/// to 1 (in the interior, everywhere for circular padding).
pub fn downsample_matrix(n: usize, mode: Padding, dtype: DType, device: &Device) -> Result<Tensor> {
    downsample_axis(n, mode)?.to_dense(dtype, device)
}

/// The blur applied before a stride-2 3×3 conv: (n + 1, n), row m reads x[m − 2 … m + 1].
pub fn blur_matrix(n: usize, mode: Padding, dtype: DType, device: &Device) -> Result<Tensor> {
    blur_axis(n, mode)?.to_dense(dtype, device)
}

/// Applies `m_h` to the rows and `m_w` to the columns of every plane: `M_H · X · M_Wᵀ`, with
/// dense matrices and candle's `matmul` ([`photomat_kernels::separable_reference`]).
///
/// # Shapes
/// x (B, C, H, W), m_h (H', H), m_w (W', W) → (B, C, H', W').
pub fn apply_separable(x: &Tensor, m_h: &Tensor, m_w: &Tensor) -> Result<Tensor> {
    photomat_kernels::separable_reference(x, m_h, m_w)
}

/// StyleGAN2 ×2 FIR upsampling (`upfirdn2d.upsample2d`).
///
/// # Shapes
/// (B, C, H, W) → (B, C, 2H, 2W).
pub fn upsample2d(x: &Tensor, mode: Padding) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    photomat_kernels::separable(x, &upsample_axis(h, mode)?, &upsample_axis(w, mode)?)
}

/// StyleGAN2 ×2 FIR downsampling (`upfirdn2d.downsample2d`).
///
/// # Shapes
/// (B, C, H, W) → (B, C, H/2, W/2); H and W even.
pub fn downsample2d(x: &Tensor, mode: Padding) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    photomat_kernels::separable(x, &downsample_axis(h, mode)?, &downsample_axis(w, mode)?)
}

/// The blur before a stride-2 3×3 conv (see the module docs).
///
/// # Shapes
/// (B, C, H, W) → (B, C, H + 1, W + 1).
pub fn blur_for_strided_conv(x: &Tensor, mode: Padding) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    photomat_kernels::separable(x, &blur_axis(h, mode)?, &blur_axis(w, mode)?)
}
