//! # photomat-estimator
//!
//! The map estimator E of PhotoMat (Zhou et al., SIGGRAPH 2023): §3 "Material map estimator"
//! trains a network that turns the generator's neural material F (32 feature channels per
//! texel) into the parameter maps of an analytic BRDF, so that rendering those maps matches
//! the neural relighting of F; §4 "Implementation" fixes it as a UNet with five down- and
//! five up-sampling levels, 32→32→64→128→256→256→256→128→64→32→n.
//!
//! Here the BRDF is any registered plugin (`docs/plugins.md`, "Parameter maps";
//! `docs/neural-models.md`, "Map estimator E"): n is the plugin's channel count, E outputs
//! unconstrained raw values and the plugin's `decode` maps them into physical ranges (applying the
//! reference's tanh head exactly once, see [`unet`]).
//!
//! - [`Estimator`] / [`EstimatorConfig`]: the UNet ([`unet`]).
//! - [`EstimatorModel`] ([`model_files`]): a trained E on disk with the BRDF it decodes into.
//! - [`map_distribution`]: the statistics of E's maps of sampled materials, to compare with
//!   real materials' (`photomat eval-gan --library`).
//! - [`model_choice`]: which of a model folder's estimators a material gets (`--brdf SPEC|auto`
//!   of `photomat sample` and `photomat capture`).
//! - [`loss`]: the Gram (VGG19 or seeded random-feature fallback) and L1 losses of §3.
//! - [`train`]: the two-stage training against a frozen `GanModel` (aligned, then rolled
//!   fine-tune), resumable, behind `photomat train-estimator`.
//! - [`trade`]: the speed/accuracy trade of BRDF models (one E per model, same budget),
//!   behind `photomat trade`.
//! - [`circular_conv2d`]: convolution with wrap-around padding ([`conv`]) on
//!   [`photomat_kernels::conv2d`] (im2col + gemm custom ops; E's layers 2–5× faster forward +
//!   backward than with candle's CPU `conv2d`). [`conv2d_fast_backward`] ([`conv_grad`])
//!   remains available for unpadded convs.
//! - [`circular_pad()`]: wrap-around padding by `narrow` + `cat` ([`mod@circular_pad`]).
//! - [`leaky_relu`]: the activation as one fused element-wise pass each way ([`activation`],
//!   from `photomat-kernels`).
//! - [`upsample2x_periodic`]: ×2 bilinear upsampling with a periodic boundary as two sparse
//!   interpolation-matrix passes ([`upsample`]).
//!
//! Every layer wraps around the image borders, so E commutes with rolls by multiples of 32
//! texels and maps periodic (tileable) features to periodic maps.
//!
//! One deliberate deviation from the reference code: its upsampling uses
//! `align_corners=True`, which is not shift equivariant; here it is `align_corners=False`
//! with wrap-around (documented in [`upsample`]).
//!
//! ```no_run
//! use candle_core::{DType, Device, Tensor};
//! use candle_nn::{VarBuilder, VarMap};
//! use photomat_brdfs as _; // link the built-in plugins
//! use photomat_estimator::Estimator;
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let brdf = photomat_core::lookup("height(ggx)")?;
//! let vars = VarMap::new();
//! let e = Estimator::for_brdf(brdf.as_ref(), VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu))?;
//! let features = Tensor::randn(0f32, 1., (1, 32, 256, 256), &Device::Cpu)?;
//! let maps = e.estimate(&features, brdf.as_ref())?; // diffuse, specular, roughness, height
//! # Ok(()) }
//! ```

pub mod conv;
pub mod loss;
pub mod map_distribution;
pub mod model_choice;
pub mod model_files;
pub mod sample;
pub mod trade;
pub mod train;
pub mod unet;
pub mod upsample;

/// The fused LeakyReLU, re-exported from `photomat-kernels` (its single home).
pub use photomat_kernels::activation;
/// The polyphase conv backward, re-exported from `photomat-kernels` (its single home).
pub use photomat_kernels::conv_grad;

pub use activation::leaky_relu;
pub use conv::{CircularConv2d, circular_conv2d};
pub use conv_grad::conv2d_fast_backward;
pub use model_files::{EstimatorManifest, EstimatorModel};
pub use photomat_kernels::{circular_pad, circular_pad_dim, circular_pad2d};
pub use unet::{Estimator, EstimatorConfig};
pub use upsample::{periodic_upsample_axis, periodic_upsample_matrix, upsample2x_periodic};

/// Deterministic test inputs (`photomat-core`'s seeded generator) and comparisons
/// (`photomat-kernels`) shared by the unit tests.
#[cfg(test)]
pub(crate) mod test_util {
    pub use photomat_core::rng::pseudo_random;
    pub use photomat_kernels::testing::max_abs_diff;
}
