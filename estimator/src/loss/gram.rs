//! The Gram-matrix (texture) loss of the estimator (PhotoMat §3 "Material map estimator";
//! reference details in `docs/neural-models.md`, "Gram loss"), after Gatys, Ecker & Bethge
//! (2015), "Texture synthesis using convolutional neural networks".
//!
//! For a feature map F with C channels over N = H·W texels, the Gram matrix is
//! `G = F Fᵀ / N` (C×C): the feature correlations averaged over positions, blind to *where*
//! things are. The loss compares two images a, b through a [`FeatureExtractor`] at the scales
//! 1, ½, ¼ of an image pyramid built by 2×2 averaging ([`avg_pool2x2`]):
//!
//! ```text
//! L = mean over (scale s, feature stage k) of  mean_{b,i,j} |G(φ_k(a_s)) − G(φ_k(b_s))|_{ij}
//! ```
//!
//! i.e. the mean absolute difference of all Grams, each (scale, stage) pair weighted equally.
//! The fine-tune stage uses the full resolution only (`scales = 1`).

use candle_core::{Result, Tensor, bail};

use super::downsample::avg_pool2x2;
use super::extractor::FeatureExtractor;

/// Pyramid levels of the reference's Gram loss: scales 1, ½ and ¼.
pub const REFERENCE_GRAM_SCALES: usize = 3;

/// `F Fᵀ / (H·W)` per batch item.
///
/// # Shapes
/// (B, C, H, W) → (B, C, C).
pub fn gram_matrix(features: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = features.dims4()?;
    let f = features.contiguous()?.reshape((b, c, h * w))?;
    let ft = f.transpose(1, 2)?.contiguous()?;
    f.matmul(&ft)? / (h * w) as f64
}

/// The Gram loss between `a` and `b` over `scales` pyramid levels (1 = full resolution only,
/// [`REFERENCE_GRAM_SCALES`] = 1, ½, ¼); images display-encoded in [0, 1]. A level is skipped
/// once the image is smaller than 2×2 (nothing left to pool). Differentiable w.r.t. both.
///
/// # Shapes
/// a, b (B, 3, H, W) → scalar.
pub fn gram_loss(
    extractor: &dyn FeatureExtractor,
    a: &Tensor,
    b: &Tensor,
    scales: usize,
) -> Result<Tensor> {
    if a.dims() != b.dims() {
        bail!(
            "Gram loss between images of shapes {:?} and {:?}",
            a.dims(),
            b.dims()
        );
    }
    if scales == 0 {
        bail!("Gram loss needs at least one scale");
    }
    let (mut a, mut b) = (a.clone(), b.clone());
    let mut terms = Vec::new();
    for level in 0..scales {
        if level > 0 {
            let (_, _, h, w) = a.dims4()?;
            if h < 2 || w < 2 {
                break;
            }
            a = avg_pool2x2(&a)?;
            b = avg_pool2x2(&b)?;
        }
        let (fa, fb) = (extractor.features(&a)?, extractor.features(&b)?);
        for (x, y) in fa.iter().zip(&fb) {
            terms.push((gram_matrix(x)? - gram_matrix(y)?)?.abs()?.mean_all()?);
        }
    }
    if terms.is_empty() {
        bail!(
            "Gram loss: images of shape {:?} are too small for any feature stage (at least 2×2 texels)",
            a.dims()
        );
    }
    let n = terms.len() as f64;
    Tensor::stack(&terms, 0)?.sum_all()? / n
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn gram_of_a_tiny_map_matches_hand_computation() -> Result<()> {
        // Two channels over 2×2 texels: f0 = (1, 2, 3, 4), f1 = (0, 1, 0, −1).
        let f = Tensor::new(&[1f64, 2., 3., 4., 0., 1., 0., -1.], &Device::Cpu)?
            .reshape((1, 2, 2, 2))?;
        let g = gram_matrix(&f)?.flatten_all()?.to_vec1::<f64>()?;
        // f0·f0 = 30, f0·f1 = 2 − 4 = −2, f1·f1 = 2; divided by N = 4.
        assert_eq!(g, [7.5, -0.5, -0.5, 0.5]);
        Ok(())
    }
}
