//! # photomat-kernels
//!
//! Fast CPU kernels for photomat's networks, as candle 0.11 custom ops, each with
//! its backward pass. candle's own CPU path runs this project's layers 5–8× slower than
//! PyTorch CPU (`docs/candle-notes.md`, "Speed"); the generator and the estimator call these ops
//! instead where they measure faster (today's numbers in `docs/results.md`, their history in
//! `docs/benchmarks/`).
//!
//! - [`conv2d`]: convolution with zero or circular padding, forward, input gradient and
//!   weight gradient each a custom op, differentiable to any order ([`conv`], which picks
//!   the kernel; sizes in [`conv_geometry`]). On im2col + `gemm` ([`im2col`], through
//!   [`matmul`]) for f64 and pointwise layers; f32 forwards whose output rows hold at least
//!   one vector, their input gradients and weight gradients over ≥ 1024 texels run on
//!   direct register-blocked kernels instead ([`direct_conv`], [`strided_input_grad`] phase
//!   by phase, [`direct_weight_grad`]; tiles in [`conv_tiles`], the padded input in
//!   [`padded_input`]), compiled for AVX-512 and for AVX2 + FMA ([`simd`]).
//! - [`conv2d_fast_backward`]: unpadded strided `conv2d` whose input gradient is a polyphase
//!   `conv2d` instead of candle's slow direct-loop `conv_transpose2d` ([`conv_grad`]).
//! - [`leaky_relu`], [`leaky_relu_gain`], [`bias_leaky_relu_gain`]: (bias +) LeakyReLU (× gain)
//!   as one fused element-wise pass each way, differentiable to any order ([`activation`]).
//! - [`add_channel_bias`], [`channel_sums`]: a per-channel bias with no activation after it,
//!   whose backward sums each plane contiguously instead of candle's strided reduction
//!   ([`bias`]).
//! - [`fir`]: separable FIR filtering/resampling, one sparse constant matrix per axis
//!   (StyleGAN2's `upfirdn2d` with the `[1, 3, 3, 1]` filter), differentiable to any order;
//!   the repeating rows of its f32 width pass a vector of outputs at a time ([`fir_simd`]).
//! - [`modulated_conv2d`]: StyleGAN2's modulated convolution (input styles, shared-weight
//!   conv, output demodulation) as one op with a seven-pass backward ([`modulated_conv`]).
//! - [`per_texel_mlp`], [`per_texel_mlp_rows`]: PhotoMat's relighting MLP on every texel as
//!   one fused op per pass (forward, backward, second order; [`mlp`]).
//! - [`periodic_window()`]: a window of each sample's periodic extension (a tileable output
//!   rolled and cut), one gather forward and one scatter-add backward
//!   ([`mod@periodic_window`]).
//! - [`scale_planes`], [`plane_dot`]: per-plane scaling and per-plane dot products, each the
//!   other's adjoint, one pass each; [`sum_over_channels`]: each sample's planes added
//!   ([`plane_ops`]).
//! - [`noise_bias_leaky_relu_gain`]: a synthesis layer's epilogue (noise, bias, LeakyReLU ×
//!   gain) as one element-wise pass each way ([`noise_act`]).
//! - [`mod@reference`]: a per-thread switch sending every op to its candle reference composition
//!   (equivalence tests, same-process baselines).
//! - [`simd`]: the vector families the hand-written kernels are compiled for (AVX-512,
//!   AVX2 + FMA), the one that runs (the CPU's widest; `PHOTOMAT_SIMD=avx2|avx512|scalar`
//!   and [`simd::with_simd_family`] force a narrower one), and the lane operations the
//!   kernels are written over.
//! - [`alloc`]: the global allocator (mimalloc, opt-in feature) and thread count binaries use.
//! - [`threads`]: binaries run candle's element-wise ops on the calling thread (candle's own
//!   pool spins, which slows every step on a busy machine).
//! - [`testing`]: tensor comparisons for tests and benchmarks (their seeded inputs come from
//!   `photomat_core::rng`, a dev-dependency).
//!
//! Conventions follow `docs/conventions.md`, "Image values": NCHW tensors, f32 for training (f64
//! accepted by every op so that gradient tests can be tight).

pub mod activation;
pub mod alloc;
pub mod bias;
pub mod circular_pad;
pub mod conv;
pub mod conv_geometry;
pub mod conv_grad;
pub mod conv_tiles;
pub mod direct_conv;
#[cfg(test)]
mod direct_kernel_tests;
pub mod direct_weight_grad;
pub mod fir;
pub mod fir_simd;
pub mod im2col;
pub mod matmul;
pub mod mlp;
pub mod modulated_conv;
pub mod noise_act;
pub mod padded_input;
pub mod periodic_window;
pub mod plane_ops;
pub mod reference;
pub mod simd;
mod storage;
pub mod strided_input_grad;
pub mod testing;
pub mod threads;

pub use activation::{bias_leaky_relu_gain, leaky_relu, leaky_relu_gain};
pub use bias::{add_channel_bias, channel_sums};
pub use circular_pad::{circular_pad, circular_pad_dim, circular_pad2d};
pub use conv::{conv2d, conv2d_reference};
pub use conv_geometry::{Conv2dSpec, PaddingMode};
pub use conv_grad::conv2d_fast_backward;
pub use fir::{AxisMatrix, separable, separable_reference};
pub use mlp::{
    MlpActivation, MlpLayer, per_texel_mlp, per_texel_mlp_reference, per_texel_mlp_rows,
    per_texel_mlp_rows_reference,
};
pub use modulated_conv::{modulated_conv2d, modulated_conv2d_reference};
pub use noise_act::noise_bias_leaky_relu_gain;
pub use periodic_window::{periodic_window, periodic_window_reference};
pub use plane_ops::{plane_dot, scale_planes, sum_over_channels};
pub use reference::{reference_ops, with_reference_ops};
