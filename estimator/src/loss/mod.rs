//! Losses of the map estimator E (PhotoMat §3 "Material map estimator"; `docs/neural-models.md`,
//! "Training E"): the analytic render of E's decoded maps is compared with the frozen relighter M's
//! image by `0.1·L1 + 1.0·Gram`.
//!
//! - [`l1`]: plain L1 and L1 on 16×16 area downsamples (the fine-tune);
//! - [`gram`]: Gram matrices `F Fᵀ/(HW)` of feature maps at scales 1, ½, ¼, mean absolute
//!   difference;
//! - [`extractor`]: the [`FeatureExtractor`] trait and the pooled conv stack both
//!   implementations share: [`vgg19`] (torchvision weights from a safetensors file) and
//!   [`random_features`] (the seeded fallback);
//! - [`downsample`]: differentiable 2×2 and area averaging.

pub mod downsample;
pub mod extractor;
pub mod gram;
pub mod l1;
pub mod random_features;
pub mod vgg19;

pub use downsample::{area_downsample, avg_pool2x2};
pub use extractor::{ConvLayer, FeatureExtractor, PooledConvStack};
pub use gram::{REFERENCE_GRAM_SCALES, gram_loss, gram_matrix};
pub use l1::{FINETUNE_L1_SIZE, l1, l1_downsampled};
pub use random_features::{DEFAULT_RANDOM_FEATURE_SEED, RANDOM_FEATURE_WIDTHS, random_features};
pub use vgg19::{IMAGENET_MEAN, IMAGENET_STD, VGG19_CONV_INDICES, load_vgg19};
