//! The L1 term of the estimator loss (PhotoMat §3 "Material map estimator";
//! `docs/neural-models.md`, "Training E"): mean absolute difference between the analytic render and
//! the neural relighting, in the networks' encoded [−1, 1] image space. Stage 1 compares the images
//! texel by texel; the fine-tune compares 16×16 area downsamples ([`FINETUNE_L1_SIZE`]), which
//! keeps the colour and overall brightness tied to M while leaving the texel layout to the Gram
//! term (the rolled maps no longer sit where M's image has them).

use candle_core::{Result, Tensor, bail};

use super::downsample::area_downsample;

/// Side of the area downsamples the fine-tune's L1 compares.
pub const FINETUNE_L1_SIZE: usize = 16;

/// `mean |a − b|`.
///
/// # Shapes
/// a, b of one shape → scalar.
pub fn l1(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    if a.dims() != b.dims() {
        bail!(
            "L1 between tensors of shapes {:?} and {:?}",
            a.dims(),
            b.dims()
        );
    }
    (a - b)?.abs()?.mean_all()
}

/// `mean |down(a) − down(b)|` with `down` the area average to `size`×`size`.
///
/// # Shapes
/// a, b (B, C, H, W), H and W multiples of `size` → scalar.
pub fn l1_downsampled(a: &Tensor, b: &Tensor, size: usize) -> Result<Tensor> {
    l1(&area_downsample(a, size)?, &area_downsample(b, size)?)
}
