//! The sizes of one 2-D convolution, checked once: stride, padding and padding mode
//! ([`Conv2dSpec`], [`PaddingMode`]) and the `Geometry` every CPU path of [`crate::conv`]
//! reads (im2col + `gemm` in [`crate::im2col`], the direct kernels of
//! [`crate::direct_conv`] and [`crate::strided_input_grad`]), with the one rule that maps a
//! padded position back to an input texel (wrapped or zero).

use candle_core::{Result, Shape, bail};

/// How the border of the input is extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaddingMode {
    /// Zeros outside the image (candle's and PyTorch's default).
    Zeros,
    /// Wrap around: the image is one period of a tileable texture (the reference's
    /// `CircularConv2d`, PyTorch `padding_mode="circular"`).
    Circular,
}

/// Stride, padding and padding mode of a [`crate::conv2d`]; dilation 1, one group.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Conv2dSpec {
    /// Step between output texels, in input texels (≥ 1).
    pub stride: usize,
    /// Texels added on each of the four sides.
    pub padding: usize,
    /// How the added texels are filled.
    pub mode: PaddingMode,
}

impl Conv2dSpec {
    /// Zero padding.
    pub const fn zeros(stride: usize, padding: usize) -> Self {
        Self {
            stride,
            padding,
            mode: PaddingMode::Zeros,
        }
    }

    /// Circular (wrap-around) padding.
    pub const fn circular(stride: usize, padding: usize) -> Self {
        Self {
            stride,
            padding,
            mode: PaddingMode::Circular,
        }
    }
}

/// Sizes of one convolution, checked once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Geometry {
    pub(crate) b: usize,
    pub(crate) ci: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) co: usize,
    pub(crate) kh: usize,
    pub(crate) kw: usize,
    pub(crate) stride: usize,
    pub(crate) pad: usize,
    pub(crate) circular: bool,
    pub(crate) ho: usize,
    pub(crate) wo: usize,
}

impl Geometry {
    pub(crate) fn new(
        (b, ci, h, w): (usize, usize, usize, usize),
        (co, ci_w, kh, kw): (usize, usize, usize, usize),
        spec: Conv2dSpec,
    ) -> Result<Self> {
        let Conv2dSpec {
            stride,
            padding: pad,
            mode,
        } = spec;
        if ci != ci_w {
            bail!("conv2d: input has {ci} channels, kernel expects {ci_w}");
        }
        if stride == 0 || kh == 0 || kw == 0 || ci == 0 || co == 0 {
            bail!("conv2d: stride, kernel size and channel counts must be ≥ 1");
        }
        let circular = mode == PaddingMode::Circular;
        if circular && (pad > h || pad > w) {
            bail!("conv2d: circular padding {pad} exceeds the {h}×{w} image");
        }
        if h + 2 * pad < kh || w + 2 * pad < kw {
            bail!("conv2d: kernel {kh}×{kw} is larger than the padded {h}×{w} input");
        }
        let ho = (h + 2 * pad - kh) / stride + 1;
        let wo = (w + 2 * pad - kw) / stride + 1;
        Ok(Self {
            b,
            ci,
            h,
            w,
            co,
            kh,
            kw,
            stride,
            pad,
            circular,
            ho,
            wo,
        })
    }

    pub(crate) fn x_shape(&self) -> Shape {
        (self.b, self.ci, self.h, self.w).into()
    }

    pub(crate) fn w_shape(&self) -> Shape {
        (self.co, self.ci, self.kh, self.kw).into()
    }

    pub(crate) fn y_shape(&self) -> Shape {
        (self.b, self.co, self.ho, self.wo).into()
    }

    /// Rows of the lowered matrix: C_in·kh·kw.
    pub(crate) fn k(&self) -> usize {
        self.ci * self.kh * self.kw
    }

    /// A 1×1 stride-1 unpadded convolution: `col(x)` is `x`.
    pub(crate) fn is_pointwise(&self) -> bool {
        self.kh == 1 && self.kw == 1 && self.stride == 1 && self.pad == 0
    }

    /// Input index for padded position `padded` (input index + `pad`) along an axis of
    /// length `n`: wrapped when circular, `None` when zero-padded.
    pub(crate) fn source_index(&self, padded: usize, pad: usize, n: usize) -> Option<usize> {
        Some(self.source(padded, pad, n)).filter(|&i| i != OUTSIDE)
    }

    /// Input index for padded position `padded` (input index + `pad`) along an axis of
    /// length `n`: wrapped when circular, [`OUTSIDE`] when zero-padded.
    pub(crate) fn source(&self, padded: usize, pad: usize, n: usize) -> usize {
        if padded >= pad && padded - pad < n {
            padded - pad
        } else if self.circular {
            (padded + n - pad) % n
        } else {
            OUTSIDE
        }
    }
}

/// Marks a tap that falls into zero padding.
pub(crate) const OUTSIDE: usize = usize::MAX;
