//! Circular (wrap-around) padding of NCHW tensors.
//!
//! The tileable networks of PhotoMat (TileGen's strategy, paper §4 "Implementation"; the
//! reference `CircularConv2d` is `F.pad(x, (p, p, p, p), mode='circular')` followed by an
//! unpadded `F.conv2d`) treat every feature map as one period of an infinite periodic image:
//! the texel left of column 0 is column W − 1. Padding that way before each convolution makes
//! the network commute with `roll` (shift equivariance), which is what makes tileable
//! sampling and the estimator's roll fine-tune (`docs/neural-models.md`, "Training E") possible.
//!
//! Implemented with `narrow` + `cat` only, whose forward and backward passes are exact (and
//! twice differentiable) in candle 0.11 (`docs/candle-notes.md`, "Gradients that were checked and
//! are right"). Padded row `r` of an input of height H holds input row `(r − top) mod H`, and
//! likewise for columns.

use candle_core::{Result, Tensor, bail};

/// Wrap-around padding of one dimension: `before` elements taken from the end of `dim` are
/// put in front, `after` elements from its start are put behind.
///
/// # Shapes
/// Any rank; `dim` of size S becomes `before + S + after`. Both pads must be ≤ S (one
/// period at most: a wider pad would need the input repeated, which no layer here does).
pub fn circular_pad_dim(x: &Tensor, dim: usize, before: usize, after: usize) -> Result<Tensor> {
    let size = x.dim(dim)?;
    if before > size || after > size {
        bail!(
            "circular padding ({before} before, {after} after) exceeds the size {size} of dim \
             {dim} of a tensor of shape {:?}; pads may be at most one period",
            x.dims()
        );
    }
    if before == 0 && after == 0 {
        return Ok(x.clone());
    }
    let mut parts = Vec::with_capacity(3);
    if before > 0 {
        parts.push(x.narrow(dim, size - before, before)?);
    }
    parts.push(x.clone());
    if after > 0 {
        parts.push(x.narrow(dim, 0, after)?);
    }
    Tensor::cat(&parts, dim)
}

/// Circular padding of the two spatial dimensions by `(top, bottom)` rows and
/// `(left, right)` columns.
///
/// # Shapes
/// (B, C, H, W) → (B, C, top + H + bottom, left + W + right); each pad ≤ its side.
pub fn circular_pad2d(
    x: &Tensor,
    (top, bottom): (usize, usize),
    (left, right): (usize, usize),
) -> Result<Tensor> {
    let (_b, _c, _h, _w) = x.dims4()?;
    let x = circular_pad_dim(x, 2, top, bottom)?;
    circular_pad_dim(&x, 3, left, right)
}

/// Symmetric circular padding by `pad` texels on every side, what a `k × k` convolution with
/// PyTorch `padding=pad, padding_mode='circular'` applies.
///
/// # Shapes
/// (B, C, H, W) → (B, C, H + 2·pad, W + 2·pad); `pad` ≤ min(H, W).
pub fn circular_pad(x: &Tensor, pad: usize) -> Result<Tensor> {
    circular_pad2d(x, (pad, pad), (pad, pad))
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use photomat_core::rng::pseudo_random;

    /// Reference built element by element: padded (r, c) holds input ((r − top) mod H,
    /// (c − left) mod W).
    fn reference_pad(
        x: &[f64],
        (h, w): (usize, usize),
        (top, bottom): (usize, usize),
        (left, right): (usize, usize),
    ) -> Vec<f64> {
        let (hp, wp) = (top + h + bottom, left + w + right);
        let mut out = vec![0.0; hp * wp];
        for r in 0..hp {
            for c in 0..wp {
                let i = (r + h - top) % h;
                let j = (c + w - left) % w;
                out[r * wp + c] = x[i * w + j];
            }
        }
        out
    }

    #[test]
    fn circular_pad_matches_elementwise_reference() -> Result<()> {
        let (b, ch, h, w) = (2, 3, 3, 5);
        let x = pseudo_random((b, ch, h, w), 11, DType::F64, &Device::Cpu)?;
        // Asymmetric pads, one of them a full period, catch swapped axes and off-by-ones.
        let (rows, cols) = ((2, 3), (1, 5));
        let padded = circular_pad2d(&x, rows, cols)?;
        assert_eq!(padded.dims4()?, (b, ch, h + 5, w + 6));
        for bi in 0..b {
            for ci in 0..ch {
                let plane = x.get(bi)?.get(ci)?.flatten_all()?.to_vec1::<f64>()?;
                let got = padded.get(bi)?.get(ci)?.flatten_all()?.to_vec1::<f64>()?;
                // Copies only: equality is exact.
                assert_eq!(got, reference_pad(&plane, (h, w), rows, cols));
            }
        }
        Ok(())
    }

    #[test]
    fn circular_pad_symmetric_equals_roll_windows() -> Result<()> {
        // The centre of a padded tensor is the input; its 1-texel border is the input's
        // opposite edge (independent check through `roll`).
        let x = pseudo_random((1, 2, 4, 6), 3, DType::F32, &Device::Cpu)?;
        let p = circular_pad(&x, 1)?;
        let diff = |a: &Tensor, b: &Tensor| -> Result<f32> {
            (a - b)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()
        };
        assert_eq!(diff(&p.narrow(2, 1, 4)?.narrow(3, 1, 6)?, &x)?, 0.0);
        let rolled = x.roll(1, 2)?.roll(1, 3)?; // rolled[0, 0] = x[H−1, W−1]
        assert_eq!(diff(&p.narrow(2, 0, 4)?.narrow(3, 0, 6)?, &rolled)?, 0.0);
        Ok(())
    }

    #[test]
    fn circular_pad_gradient_folds_back_onto_the_period() -> Result<()> {
        // L = Σ g ⊙ pad(x)  ⇒  ∂L/∂x[i, j] = Σ of g over every padded texel that copies
        // (i, j): the adjoint of padding wraps the border gradients back.
        let (h, w) = (3, 4);
        let (rows, cols) = ((1, 2), (3, 1));
        let x = Var::from_tensor(&pseudo_random((1, 1, h, w), 5, DType::F64, &Device::Cpu)?)?;
        let g = pseudo_random((1, 1, h + 3, w + 4), 6, DType::F64, &Device::Cpu)?;
        let loss = (circular_pad2d(x.as_tensor(), rows, cols)? * &g)?.sum_all()?;
        let grad = loss.backward()?;
        let got = grad
            .get(x.as_tensor())
            .expect("x is a variable")
            .flatten_all()?
            .to_vec1::<f64>()?;
        let g = g.flatten_all()?.to_vec1::<f64>()?;
        let (hp, wp) = (h + 3, w + 4);
        let mut expected = vec![0.0; h * w];
        for r in 0..hp {
            for c in 0..wp {
                let i = (r + h - rows.0) % h;
                let j = (c + w - cols.0) % w;
                expected[i * w + j] += g[r * wp + c];
            }
        }
        for (a, b) in got.iter().zip(&expected) {
            // Sums of at most 4 f64 terms in possibly different order.
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        Ok(())
    }

    #[test]
    fn circular_pad_rejects_more_than_one_period() -> Result<()> {
        let x = Tensor::zeros((1, 1, 2, 8), DType::F32, &Device::Cpu)?;
        let err = circular_pad(&x, 3)
            .expect_err("pad 3 > height 2")
            .to_string();
        assert!(err.contains("exceeds the size 2"), "{err}");
        assert_eq!(circular_pad(&x, 0)?.dims4()?, (1, 1, 2, 8));
        assert_eq!(circular_pad_dim(&x, 3, 0, 8)?.dims4()?, (1, 1, 2, 16));
        Ok(())
    }
}
