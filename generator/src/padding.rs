//! Spatial padding of NCHW tensors: zeros (StyleGAN2) or wrap-around (tileable G).
//!
//! The tileable generator follows TileGen (Zhou et al. 2022), which PhotoMat uses for its
//! tileable F (paper §4 "Implementation"): every convolution pads its input by wrapping around
//! (PyTorch `padding_mode='circular'`), so each feature map is one period of an infinite
//! periodic image and the network commutes with rolls. Circular padding is the shared
//! `photomat_kernels::circular_pad_dim` (the estimator uses the same), built from `narrow` +
//! `cat`, whose first and second derivatives are exact in candle 0.11 (`docs/candle-notes.md`).
//! Zero padding uses candle's `pad_with_zeros` (also exact).

use candle_core::{Result, Tensor};

/// How a layer extends its input beyond the border.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Padding {
    /// Zeros outside the image (StyleGAN2).
    Zeros,
    /// Wrap-around: the texel left of column 0 is column W − 1 (tileable G).
    Circular,
}

impl Padding {
    /// `Circular` when `tileable`, `Zeros` otherwise.
    pub fn for_tileable(tileable: bool) -> Self {
        if tileable {
            Self::Circular
        } else {
            Self::Zeros
        }
    }
}

impl From<Padding> for photomat_kernels::PaddingMode {
    /// The same border rule for photomat-kernels' convolution.
    fn from(p: Padding) -> Self {
        match p {
            Padding::Zeros => Self::Zeros,
            Padding::Circular => Self::Circular,
        }
    }
}

/// Pads dimension `dim` with `before` elements in front and `after` behind.
///
/// # Shapes
/// Any rank; `dim` of size S becomes `before + S + after`. Circular pads must be ≤ S.
pub fn pad_dim(
    x: &Tensor,
    dim: usize,
    before: usize,
    after: usize,
    mode: Padding,
) -> Result<Tensor> {
    if before == 0 && after == 0 {
        return Ok(x.clone());
    }
    match mode {
        Padding::Zeros => x.pad_with_zeros(dim, before, after),
        Padding::Circular => photomat_kernels::circular_pad_dim(x, dim, before, after),
    }
}

/// Pads both spatial dimensions by `pad` on every side.
///
/// # Shapes
/// (B, C, H, W) → (B, C, H + 2·pad, W + 2·pad).
pub fn pad2d(x: &Tensor, pad: usize, mode: Padding) -> Result<Tensor> {
    let (_b, _c, _h, _w) = x.dims4()?;
    let x = pad_dim(x, 2, pad, pad, mode)?;
    pad_dim(&x, 3, pad, pad, mode)
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};

    use super::*;

    #[test]
    fn pad2d_wraps_or_zeros_the_border() -> Result<()> {
        let x = Tensor::arange(0f32, 6., &Device::Cpu)?.reshape((1, 1, 2, 3))?;
        let c = pad2d(&x, 1, Padding::Circular)?;
        assert_eq!(
            c.flatten_all()?.to_vec1::<f32>()?,
            [
                5., 3., 4., 5., 3., //
                2., 0., 1., 2., 0., //
                5., 3., 4., 5., 3., //
                2., 0., 1., 2., 0.,
            ]
        );
        let z = pad2d(&x, 1, Padding::Zeros)?;
        assert_eq!(z.dims4()?, (1, 1, 4, 5));
        assert_eq!(z.sum_all()?.to_scalar::<f32>()?, 15.0);
        assert!(
            pad2d(
                &Tensor::zeros((1, 1, 2, 2), DType::F32, &Device::Cpu)?,
                3,
                Padding::Circular
            )
            .is_err()
        );
        Ok(())
    }
}
