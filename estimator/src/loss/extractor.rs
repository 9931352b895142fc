//! The feature extractor behind the Gram loss (`docs/neural-models.md`, "Gram loss"): an
//! image → a list of feature maps, one per pooling stage, and the one network shape both
//! implementations share.
//!
//! The reference uses VGG19 (Simonyan & Zisserman 2015) with its max-pools replaced by
//! average pools and takes the features after pool1 … pool5 (Gatys, Ecker & Bethge 2015,
//! "Texture synthesis using convolutional neural networks"). [`PooledConvStack`] is that
//! shape with any weights: stages of (3×3 conv + bias + ReLU)ᵏ followed by a 2×2 average
//! pool, the output of every pool being one feature map. [`crate::loss::vgg19`] fills it
//! with torchvision's VGG19 weights, [`crate::loss::random_features`] with a seeded random
//! bank.
//!
//! Small inputs: a stage needs at least 2×2 texels to pool, so an input of side s yields
//! min(stages, ⌊log₂ s⌋) feature maps (a 32² image at the Gram loss's ¼ scale, 8², gives
//! three). Every implementation follows this rule.

use candle_core::{DType, Device, Result, Tensor, bail};
use photomat_kernels::{Conv2dSpec, conv2d};

use super::downsample::avg_pool2x2;

/// Images → feature maps for the Gram loss.
pub trait FeatureExtractor: Send + Sync {
    /// A short description for logs and manifests (e.g. `vgg19 (weights.safetensors)`).
    fn describe(&self) -> String;

    /// The feature maps of `images` (display-encoded, values in [0, 1]), coarsening stage by
    /// stage; gradients flow to `images`, never to the extractor's weights.
    ///
    /// # Shapes
    /// (B, 3, H, W) → one (B, C_k, H / 2^(k+1), W / 2^(k+1)) tensor per stage k.
    fn features(&self, images: &Tensor) -> Result<Vec<Tensor>>;
}

/// One 3×3 convolution of a stage: weight (C_out, C_in, 3, 3), bias (C_out).
#[derive(Debug, Clone)]
pub struct ConvLayer {
    pub weight: Tensor,
    pub bias: Tensor,
}

/// Stages of (3×3 conv, bias, ReLU)ᵏ + 2×2 average pool over a per-channel normalised input
/// `(x − mean) / std`. Weights are plain tensors (not variables): the extractor is frozen.
#[derive(Debug, Clone)]
pub struct PooledConvStack {
    stages: Vec<Vec<ConvLayer>>,
    mean: Tensor,
    inv_std: Tensor,
    padding: Conv2dSpec,
    description: String,
}

impl PooledConvStack {
    /// A stack from its stages; `mean` and `std` per input channel normalise the [0, 1] input.
    /// Checks that every layer is a 3×3 conv whose input width is the previous output width
    /// (3 for the first) and names the offending layer otherwise.
    pub fn new(
        stages: Vec<Vec<ConvLayer>>,
        mean: [f64; 3],
        std: [f64; 3],
        padding: Conv2dSpec,
        description: String,
    ) -> Result<Self> {
        let first = stages
            .iter()
            .flatten()
            .next()
            .ok_or_else(|| candle_core::Error::msg("feature extractor without layers"))?;
        let (dtype, device) = (first.weight.dtype(), first.weight.device().clone());
        let mut c = 3;
        for (s, stage) in stages.iter().enumerate() {
            if stage.is_empty() {
                bail!("feature extractor: stage {s} has no conv layer");
            }
            for (l, layer) in stage.iter().enumerate() {
                let (co, ci, kh, kw) = layer.weight.dims4()?;
                if (ci, kh, kw) != (c, 3, 3) || layer.bias.dims() != [co] {
                    bail!(
                        "feature extractor: stage {s} layer {l} has weight {:?} and bias {:?}, \
                         expected ({co}, {c}, 3, 3) and ({co})",
                        layer.weight.dims(),
                        layer.bias.dims()
                    );
                }
                c = co;
            }
        }
        let per_channel = |v: [f64; 3]| -> Result<Tensor> {
            Tensor::from_vec(v.to_vec(), (1, 3, 1, 1), &device)?.to_dtype(dtype)
        };
        Ok(Self {
            stages,
            mean: per_channel(mean)?,
            inv_std: per_channel(std.map(|s| 1.0 / s))?,
            padding,
            description,
        })
    }

    /// Output channels of each stage.
    pub fn stage_channels(&self) -> Vec<usize> {
        self.stages
            .iter()
            .map(|s| s.last().map_or(0, |l| l.bias.dims()[0]))
            .collect()
    }

    /// dtype and device of the weights.
    pub fn dtype_device(&self) -> (DType, Device) {
        let w = &self.stages[0][0].weight;
        (w.dtype(), w.device().clone())
    }
}

impl FeatureExtractor for PooledConvStack {
    fn describe(&self) -> String {
        self.description.clone()
    }

    fn features(&self, images: &Tensor) -> Result<Vec<Tensor>> {
        let (_b, c, _h, _w) = images.dims4()?;
        let (dtype, _) = self.dtype_device();
        if c != 3 || images.dtype() != dtype {
            bail!(
                "feature extractor: expected RGB images of dtype {dtype:?}, got {:?} of {:?}",
                images.dims(),
                images.dtype()
            );
        }
        let mut x = images
            .broadcast_sub(&self.mean)?
            .broadcast_mul(&self.inv_std)?;
        let mut out = Vec::with_capacity(self.stages.len());
        for stage in &self.stages {
            let (_, _, h, w) = x.dims4()?;
            if h < 2 || w < 2 {
                break;
            }
            for layer in stage {
                // Bias + ReLU (LeakyReLU of slope 0) as one fused pass each way.
                x = photomat_kernels::bias_leaky_relu_gain(
                    &conv2d(&x, &layer.weight, self.padding)?,
                    &layer.bias,
                    0.0,
                    1.0,
                )?;
            }
            x = avg_pool2x2(&x)?;
            out.push(x.clone());
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::Var;

    use super::*;
    use crate::test_util::{max_abs_diff, pseudo_random};

    #[test]
    fn features_and_their_input_gradient_equal_conv_bias_then_relu() -> Result<()> {
        let dev = Device::Cpu;
        let layer = |co: usize, ci: usize, seed: u64| -> Result<ConvLayer> {
            Ok(ConvLayer {
                weight: pseudo_random((co, ci, 3, 3), seed, DType::F64, &dev)?,
                bias: pseudo_random(co, seed + 1, DType::F64, &dev)?,
            })
        };
        let stages = vec![
            vec![layer(4, 3, 1)?, layer(5, 4, 3)?],
            vec![layer(6, 5, 5)?],
        ];
        let padding = Conv2dSpec::circular(1, 1);
        let (mean, std) = ([0.4, 0.5, 0.6], [0.2, 0.25, 0.3]);
        let stack = PooledConvStack::new(stages.clone(), mean, std, padding, "test".into())?;
        let images = Var::from_tensor(&pseudo_random((2, 3, 8, 8), 7, DType::F64, &dev)?)?;

        // The same network from candle ops: broadcast bias, then `relu`.
        let reference = |x: &Tensor| -> Result<Vec<Tensor>> {
            let m = Tensor::new(&mean, &dev)?.reshape((1, 3, 1, 1))?;
            let s = Tensor::new(&std, &dev)?.reshape((1, 3, 1, 1))?;
            let mut x = x.broadcast_sub(&m)?.broadcast_div(&s)?;
            let mut out = Vec::new();
            for stage in &stages {
                for l in stage {
                    let co = l.bias.dims()[0];
                    x = conv2d(&x, &l.weight, padding)?
                        .broadcast_add(&l.bias.reshape((1, co, 1, 1))?)?
                        .relu()?;
                }
                x = avg_pool2x2(&x)?;
                out.push(x.clone());
            }
            Ok(out)
        };
        let ours = stack.features(images.as_tensor())?;
        let theirs = reference(images.as_tensor())?;
        let loss = |f: &[Tensor]| -> Result<Tensor> {
            f.iter()
                .map(|t| t.sqr()?.sum_all())
                .try_fold(Tensor::new(0f64, &dev)?, |a, b| a + b?)
        };
        let (ga, gb) = (loss(&ours)?.backward()?, loss(&theirs)?.backward()?);
        for (a, b) in ours.iter().zip(&theirs) {
            // f64, ≤ 45-term sums in the same order, the normalisation as a product instead of
            // a quotient: rounding-level differences.
            assert!(max_abs_diff(a, b)? < 1e-12);
        }
        let (da, db) = (
            ga.get(images.as_tensor()).expect("gradient"),
            gb.get(images.as_tensor()).expect("gradient"),
        );
        assert!(max_abs_diff(da, db)? < 1e-10);
        Ok(())
    }
}
