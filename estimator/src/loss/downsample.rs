//! Differentiable area downsampling: the 2×2 average of the Gram loss's image pyramid and of
//! the feature extractors' pooling stages, and the N×N area average of the fine-tune's L1
//! (`docs/neural-models.md`, "Training E": "0.1·L1 on 16×16 downsamples").
//!
//! Both are a reshape that splits each side into (blocks, block size) followed by means over
//! the block axes: exact, and differentiable to any order with candle's own ops (candle's
//! `avg_pool2d` is only correct when kernel = stride, see `docs/candle-notes.md`; this form needs
//! no such caveat).

use candle_core::{Result, Tensor, bail};

/// 2×2 average pooling with stride 2; an odd last row or column is dropped (PyTorch's
/// `avg_pool2d(x, 2)` floor semantics).
///
/// # Shapes
/// (B, C, H, W) with H, W ≥ 2 → (B, C, ⌊H/2⌋, ⌊W/2⌋).
pub fn avg_pool2x2(x: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    if h < 2 || w < 2 {
        bail!("2×2 average pooling needs at least 2×2 texels, got {h}×{w}");
    }
    let (h2, w2) = (h / 2, w / 2);
    let x = if h % 2 == 1 || w % 2 == 1 {
        x.narrow(2, 0, 2 * h2)?.narrow(3, 0, 2 * w2)?
    } else {
        x.clone()
    };
    block_mean(&x, (b, c, h2, 2, w2, 2))
}

/// Area average down to `size`×`size`: each output texel is the mean of an
/// (H/size)×(W/size) block.
///
/// # Shapes
/// (B, C, H, W) with H and W multiples of `size` → (B, C, size, size).
pub fn area_downsample(x: &Tensor, size: usize) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    if size == 0 || h % size != 0 || w % size != 0 {
        bail!(
            "area downsampling of a {h}×{w} image to {size}×{size}: the sides must be positive \
             multiples of {size}"
        );
    }
    block_mean(&x.contiguous()?, (b, c, size, h / size, size, w / size))
}

/// Mean over axes 3 and 5 of `x` viewed as (B, C, H', kh, W', kw).
fn block_mean(x: &Tensor, blocks: (usize, usize, usize, usize, usize, usize)) -> Result<Tensor> {
    x.contiguous()?.reshape(blocks)?.mean(5)?.mean(3)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    #[test]
    fn avg_pool2x2_averages_blocks_and_floors_odd_sides() -> Result<()> {
        let x = Tensor::arange(0f32, 15., &Device::Cpu)?.reshape((1, 1, 3, 5))?;
        // Rows 0–1, columns 0–3: blocks {0,1,5,6} and {2,3,7,8}.
        let y = avg_pool2x2(&x)?.flatten_all()?.to_vec1::<f32>()?;
        assert_eq!(y, [3.0, 5.0]);
        Ok(())
    }

    #[test]
    fn area_downsample_preserves_the_mean_and_rejects_bad_sizes() -> Result<()> {
        let x = photomat_core::rng::pseudo_random((2, 3, 32, 32), 3, DType::F64, &Device::Cpu)?;
        let y = area_downsample(&x, 16)?;
        assert_eq!(y.dims(), [2, 3, 16, 16]);
        let (mx, my) = (
            x.mean_all()?.to_scalar::<f64>()?,
            y.mean_all()?.to_scalar::<f64>()?,
        );
        assert!((mx - my).abs() < 1e-12);
        // The first output texel is the mean of the top-left 2×2 block.
        let block = x
            .narrow(2, 0, 2)?
            .narrow(3, 0, 2)?
            .narrow(1, 0, 1)?
            .narrow(0, 0, 1)?;
        let first = y
            .narrow(2, 0, 1)?
            .narrow(3, 0, 1)?
            .narrow(1, 0, 1)?
            .narrow(0, 0, 1)?;
        assert!(
            (block.mean_all()?.to_scalar::<f64>()? - first.mean_all()?.to_scalar::<f64>()?).abs()
                < 1e-12
        );
        assert!(area_downsample(&x, 12).is_err());
        Ok(())
    }
}
