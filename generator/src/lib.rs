//! # photomat-generator
//!
//! The relightable generator of PhotoMat (Zhou et al., SIGGRAPH 2023), §3 "Relightable
//! generator" and §4 "Implementation", with the architecture facts of the reference code
//! recorded in docs/conventions.md:
//!
//! - **G** ([`Generator`]): a StyleGAN2 generator (Karras et al. 2020, "Analyzing and Improving
//!   the Image Quality of StyleGAN", config F / StyleGAN2-ADA code) whose output is a 32-channel
//!   *neural material* F instead of an RGB image: [`mapping`] (z → w), [`synthesis`] (skip
//!   architecture of [`modulated_conv`] layers with [`noise`], summed "toFeature" layers
//!   upsampled with the [`fir`] filter). Optionally **tileable**: circular padding in every conv
//!   and in the upsampling path, so that F is exactly periodic (TileGen's strategy).
//! - Optionally **spatial** ([`spatial`], [`GeneratorConfig::spatial`]): the learned 4×4
//!   constant is replaced by a field of local latents, one per base cell, so that G is fully
//!   convolutional and translation-equivariant and makes materials of any multiple of its cell
//!   size (Jetchev et al. 2016, Spatial GAN; Bergmann et al. 2017, PSGAN).
//! - **M** ([`Relight`], [`relight`]): the per-texel relighting MLP, F ‖ ω → RGB.
//! - **D** ([`Discriminator`], [`discriminator`]): the StyleGAN2 residual discriminator on
//!   RGB ‖ ω (6 channels).
//!
//! - [`GanModel`] ([`model_files`]): G + M on disk (gan.json + gan.safetensors), the inference
//!   half of a training run, with seeded latents and noise per material seed.
//! - [`train`]: the GAN training of `photomat train-gan` (non-saturating loss, lazy R1, Adam,
//!   EMA, tileable roll, NaN guard, resumable state); [`swd`]: the sliced Wasserstein
//!   distance (ProGAN) logged during training and printed by `photomat eval-gan`.
//!
//! Every weight is an equalised-learning-rate parameter ([`equalized`]). Parameters live in a
//! candle [`VarMap`](candle_nn::VarMap) under the `vb.pp(..)` prefixes documented per module;
//! [`checkpoint`] saves and loads them as safetensors, rejecting checkpoints of another
//! architecture with the mismatching tensor named; [`seeded_var_builder`] ([`init`]) makes
//! initialisation reproducible.
//!
//! G, M and D run on the custom CPU ops of `photomat-kernels` (im2col + gemm convs with
//! padding inside the op, the fused modulated conv, sparse separable FIR passes, fused
//! bias + LeakyReLU and noise epilogues), each with its own backward, itself differentiable
//! where second derivatives are needed: the R1 penalty through D and path-length
//! regularisation through G (whose inner pass is `backward_keeping_graph`). `tests/fast_ops.rs` checks G+M
//! and D against the plain-candle composition (loss and every parameter gradient in f64),
//! `tests/r1_gradient.rs` the R1 gradient against finite differences and its double backward
//! against plain candle, `tests/g_second_order.rs` the path-length double backward. The
//! plain-candle path stays available as the reference: `photomat_kernels::with_reference_ops`.
//! On other devices and dtypes than CPU f32/f64 the candle ops are used.
//!
//! # Sizes and speed
//! Trainable parameters (M: 27 459 at every size):
//!
//! | config | G (+512 w_avg) | D |
//! |---|---|---|
//! | 64², multiplier 1 | 22 310 569 | 23 408 129 |
//! | 256², multiplier 1 (reference) | 23 264 109 | 24 001 281 |
//! | 64², multiplier ¼ | 2 543 401 | 1 465 217 |
//! | 256², multiplier ¼ | 2 678 157 | 1 502 145 |
//!
//! Forward and backward (`examples/gan_timing.rs`, release, f32, batch 4, 64², plain candle vs
//! the kernels in the same process, medians, on the loaded 2-core build machine):
//!
//! | config | G+M fwd | G+M bwd | D fwd+bwd | D R1 fwd+bwd |
//! |---|---|---|---|---|
//! | multiplier ¼ | 966 → 374 ms (2.6×) | 4008 → 1213 ms (3.3×) | 2415 → 540 ms (4.5×) | 6321 → 1497 ms (4.2×) |
//! | multiplier 1 | 11.2 → 1.49 s (7.5×) | 39.4 → 4.14 s (9.5×) | 16.8 → 3.10 s (5.4×) | 41.0 → 7.65 s (5.4×) |
//!
//! ```no_run
//! use candle_core::{DType, Device, Tensor};
//! use candle_nn::{VarBuilder, VarMap};
//! use photomat_generator::{Generator, GeneratorConfig, NoiseInput, Relight};
//!
//! # fn main() -> candle_core::Result<()> {
//! let cfg = GeneratorConfig { resolution: 64, channel_multiplier: 0.25, ..Default::default() };
//! let vars = VarMap::new();
//! let vb = VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu);
//! let g = Generator::new(&cfg, vb.pp("g"))?;
//! let m = Relight::new(&cfg, vb.pp("m"))?;
//! let z = Tensor::randn(0f32, 1., (2, cfg.latent_dim), &Device::Cpu)?;
//! let features = g.forward(&z, 1.0, &NoiseInput::Random)?; // (2, 32, 64, 64)
//! let omega = Tensor::ones((2, 3, 64, 64), DType::F32, &Device::Cpu)?; // per-texel ω in practice
//! let rgb = m.forward(&features, &omega)?; // (2, 3, 64, 64), encoded space [−1, 1]
//! # Ok(()) }
//! ```

pub mod activation;
pub mod checkpoint;
pub mod discriminator;
pub mod equalized;
pub mod fir;
pub mod init;
pub mod mapping;
pub mod model_files;
pub mod modulated_conv;
pub mod noise;
pub mod padding;
pub mod relief;
pub mod relight;
pub mod spatial;
pub mod swd;
pub mod synthesis;
pub mod train;
pub mod waves;

pub use checkpoint::{
    is_buffer, load_checkpoint, parameter_count, save_checkpoint, trainable_vars,
};
pub use discriminator::Discriminator;
pub use init::seeded_var_builder;
pub use mapping::{Mapping, mix_styles};
pub use model_files::{GanManifest, GanModel};
pub use noise::NoiseInput;
pub use relight::Relight;
pub use spatial::{LocalInput, SpatialConfig};
pub use synthesis::{Generator, Synthesis};

use candle_core::{Result, bail};

/// Smallest output resolution (the paper trains 256² … 1024²; 32² keeps tests and CPU runs
/// small while still having the 4² … 32² block structure).
pub const MIN_RESOLUTION: usize = 32;
/// Largest output resolution (the paper's largest model).
pub const MAX_RESOLUTION: usize = 1024;
/// Resolution of the learned constant input and of D's epilogue (StyleGAN2).
pub const BASE_RESOLUTION: usize = 4;
/// Channel cap of the channel table (StyleGAN2 `channel_max`).
pub const MAX_CHANNELS: usize = 512;
/// Upper limits of the architecture fields, checked by [`GeneratorConfig::validate`] before any
/// weight is allocated, so that a corrupt or hostile `gan.json` (say `latent_dim: 1e9`) is an
/// error naming the field instead of an allocation that aborts the process. Each is several
/// times the reference's value (docs/robustness.md, "Limits"); together they bound a model to
/// a few hundred million parameters.
pub mod limits {
    /// Largest channel multiplier (×4: 2048 channels where the reference has 512).
    pub const MAX_CHANNEL_MULTIPLIER: f64 = 4.0;
    /// Largest dimension of z and w (the reference: 512).
    pub const MAX_LATENT_DIM: usize = 2048;
    /// Most mapping layers (the reference: 2; StyleGAN2: 8).
    pub const MAX_MAPPING_DEPTH: usize = 16;
    /// Most channels of F (the reference: 32).
    pub const MAX_FEATURE_CHANNELS: usize = 256;
    /// Widest hidden layer of M (the reference: 64).
    pub const MAX_RELIGHT_HIDDEN: usize = 1024;
    /// Most layers of M (the reference: 8).
    pub const MAX_RELIGHT_LAYERS: usize = 32;
    /// Most Phong lobes of M's light input (the default: 5).
    pub const MAX_RELIGHT_LOBES: usize = 32;
    /// Largest minibatch-stddev group and channel count (the reference: 4 and 1).
    pub const MAX_MBSTD: usize = 64;
    /// Most channels of a spatial G's local latents (the default: 32).
    pub const MAX_LOCAL_DIM: usize = 1024;
    /// Most 1×1 layers of a spatial G's local input (the default: 2).
    pub const MAX_LOCAL_LAYERS: usize = 16;
    /// Most periodic waves of a spatial G (PSGAN uses a handful).
    pub const MAX_WAVES: usize = 256;
    /// Largest gain of D's input sharpening (9, ×10 detail, is what was measured; beyond
    /// ×100 the detail's rounding noise would be amplified past the signal).
    pub const MAX_D_INPUT_SHARPEN: f64 = 100.0;
}

/// Default side of a spatial G's sampled materials, in texels: 512², the smallest texture size
/// renderers commonly take for a surface filling a view (any multiple of the cell works).
pub const DEFAULT_SPATIAL_SAMPLE_SIDE: usize = 512;

/// Architecture of G, M and D. The defaults are the reference configuration (docs/conventions.md) at
/// 256² (channel multiplier 1); CPU users shrink `channel_multiplier` and `resolution`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeneratorConfig {
    /// Side of F, of M's images and of D's input: a power of two in 32 … 1024. Default 256.
    pub resolution: usize,
    /// Scales every entry of the channel table (see [`GeneratorConfig::channels_at`]).
    /// Default 1 (the reference); e.g. ¼ for CPU training.
    pub channel_multiplier: f64,
    /// Fully connected layers of the mapping network. Default 2 (the reference; StyleGAN2 uses 8).
    pub mapping_depth: usize,
    /// Circular padding in every conv and in the upsampling path of G, so that F is exactly
    /// periodic. D is never tileable (it sees real crops). Default false.
    pub tileable: bool,
    /// Dimension of z and w. Default 512.
    pub latent_dim: usize,
    /// Channels of the neural material F (the toFeature outputs). Default 32.
    pub feature_channels: usize,
    /// Learning-rate multiplier of the mapping layers. Default 0.01.
    pub mapping_lr_multiplier: f64,
    /// Decay of the tracked w average per training step. Default 0.995.
    pub w_avg_beta: f64,
    /// Width of M's hidden layers. Default 64.
    pub relight_hidden: usize,
    /// Fully connected layers of M (the last one linear). Default 8.
    pub relight_layers: usize,
    /// Learning-rate multiplier of every layer of M. Default 0.01.
    pub relight_lr_multiplier: f64,
    /// Exponents s of the Phong lobes `ω_z^s` M reads next to ω ([`relight`], "Light
    /// input"): empty (the default, and older `gan.json` files) gives the paper's M on F ‖ ω.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub relight_lobes: Vec<f64>,
    /// Largest group of D's minibatch-stddev layer. Default 4.
    pub mbstd_group_size: usize,
    /// Feature channels of D's minibatch-stddev statistic. Default 1.
    pub mbstd_channels: usize,
    /// `None` (the default): StyleGAN2's learned 4×4 constant, G is a fixed-size R×R image
    /// model. `Some`: G starts from a field of local latents instead ([`spatial`]), is fully
    /// convolutional and makes materials of any side that is a multiple of
    /// [`GeneratorConfig::cell_size`]; it needs `tileable` (circular padding everywhere).
    /// Absent from older `gan.json` files, and not written when `None`, so they load and save
    /// unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spatial: Option<SpatialConfig>,
    /// StyleGAN2's per-pixel noise inputs ([`noise`]). Default true (the reference). False
    /// leaves every layer's noise out, so that all texel-scale variation must come from the
    /// latents (as in the spatial texture GANs, Jetchev et al. 2016 and Bergmann et al. 2017,
    /// which have no noise inputs): the noise strength of the last 64² layer of the first
    /// spatial CPU run grew to 0.29, a per-texel speckle that M turned into coloured dots
    /// (docs/benchmarks/bundled-model.md, "Size generalisation, map spread and noise inputs").
    /// Absent from older `gan.json` files, and not written when true.
    #[serde(
        default = "noise_inputs_default",
        skip_serializing_if = "is_noise_default"
    )]
    pub noise_inputs: bool,
    /// Gain k of D's input sharpening ([`discriminator`], "Input sharpening"): D reads
    /// `x + k·(x − box₃ₓ₃ x)` instead of the image x, its detail amplified k + 1 times, so that
    /// texture whose amplitude is small next to the colour and the highlight weighs in its
    /// first layer. 0 (the default, and older files, where it is absent) is StyleGAN2's D.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub d_input_sharpen: f64,
    /// M shades each texel in the frame of a normal from a learned height channel of F
    /// ([`relief`]). False (the default, and older files, where it is absent) is the paper's M.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub relief: bool,
}

/// Whether a gain is 0 (then `gan.json` omits it).
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// Serde default of [`GeneratorConfig::noise_inputs`]: on, as before the option existed.
fn noise_inputs_default() -> bool {
    true
}

/// Whether `noise_inputs` has its default value (then `gan.json` omits it).
fn is_noise_default(on: &bool) -> bool {
    *on
}

impl Default for GeneratorConfig {
    fn default() -> Self {
        Self {
            resolution: 256,
            channel_multiplier: 1.0,
            mapping_depth: 2,
            tileable: false,
            latent_dim: 512,
            feature_channels: 32,
            mapping_lr_multiplier: 0.01,
            w_avg_beta: 0.995,
            relight_hidden: 64,
            relight_layers: 8,
            relight_lr_multiplier: 0.01,
            relight_lobes: Vec::new(),
            mbstd_group_size: 4,
            mbstd_channels: 1,
            spatial: None,
            noise_inputs: true,
            d_input_sharpen: 0.0,
            relief: false,
        }
    }
}

impl GeneratorConfig {
    /// Checks every field; the error names the field, its value and what is accepted.
    pub fn validate(&self) -> Result<()> {
        let r = self.resolution;
        if !r.is_power_of_two() || !(MIN_RESOLUTION..=MAX_RESOLUTION).contains(&r) {
            bail!(
                "resolution {r} is not supported: use a power of two in {MIN_RESOLUTION} … {MAX_RESOLUTION}"
            );
        }
        if !(self.channel_multiplier.is_finite() && self.channel_multiplier > 0.0) {
            bail!(
                "channel multiplier {} must be positive and finite",
                self.channel_multiplier
            );
        }
        if self.channel_multiplier > limits::MAX_CHANNEL_MULTIPLIER {
            bail!(
                "channel multiplier {} exceeds the limit of {}",
                self.channel_multiplier,
                limits::MAX_CHANNEL_MULTIPLIER
            );
        }
        if self.relight_layers < 2 {
            bail!(
                "relight MLP needs at least 2 layers, got {}",
                self.relight_layers
            );
        }
        for (name, v, max) in [
            (
                "mapping_depth",
                self.mapping_depth,
                limits::MAX_MAPPING_DEPTH,
            ),
            ("latent_dim", self.latent_dim, limits::MAX_LATENT_DIM),
            (
                "feature_channels",
                self.feature_channels,
                limits::MAX_FEATURE_CHANNELS,
            ),
            (
                "relight_hidden",
                self.relight_hidden,
                limits::MAX_RELIGHT_HIDDEN,
            ),
            (
                "relight_layers",
                self.relight_layers,
                limits::MAX_RELIGHT_LAYERS,
            ),
            (
                "relight_lobes (count)",
                self.relight_lobes.len().max(1),
                limits::MAX_RELIGHT_LOBES,
            ),
            ("mbstd_group_size", self.mbstd_group_size, limits::MAX_MBSTD),
            ("mbstd_channels", self.mbstd_channels, limits::MAX_MBSTD),
        ] {
            if v == 0 {
                bail!("{name} must be at least 1");
            }
            if v > max {
                bail!("{name} {v} exceeds the limit of {max}");
            }
        }
        if !(0.0..=limits::MAX_D_INPUT_SHARPEN).contains(&self.d_input_sharpen) {
            bail!(
                "d_input_sharpen {} must be in 0 … {}",
                self.d_input_sharpen,
                limits::MAX_D_INPUT_SHARPEN
            );
        }
        for (name, v) in [
            ("mapping_lr_multiplier", self.mapping_lr_multiplier),
            ("relight_lr_multiplier", self.relight_lr_multiplier),
        ] {
            if !(v.is_finite() && v > 0.0) {
                bail!("{name} {v} must be positive and finite");
            }
        }
        if let Some(s) = self
            .relight_lobes
            .iter()
            .find(|s| !(s.is_finite() && **s >= 1.0))
        {
            bail!("relight lobe exponent {s} must be a finite number ≥ 1");
        }
        if !(0.0..1.0).contains(&self.w_avg_beta) {
            bail!("w_avg_beta {} must be in [0, 1)", self.w_avg_beta);
        }
        if let Some(spatial) = &self.spatial {
            // Required rather than implied, so that `tileable` keeps one meaning (F is
            // periodic) for every reader of the configuration.
            if !self.tileable {
                bail!(
                    "a spatial generator needs tileable = true: its translation equivariance \
                     rests on circular padding in every conv and wrap-around upsampling"
                );
            }
            spatial.validate()?;
        }
        Ok(())
    }

    /// Texels of F per cell of the base (4² at R = `resolution`) grid: the total stride of
    /// the synthesis network, `resolution / 4`. A spatial G makes F of any side that is a
    /// multiple of it (one local latent per cell).
    pub fn cell_size(&self) -> usize {
        self.resolution / BASE_RESOLUTION
    }

    /// World units per texel of F (flash at height 1): 1/R for the fixed-size G (its R×R
    /// output is the unit square), the training photos' texel for a spatial G; `None` for a
    /// spatial G saved before the texel size was recorded.
    pub fn texel_size(&self) -> Option<f64> {
        match &self.spatial {
            None => Some(photomat_core::flash::PLANE_SIDE / self.resolution as f64),
            Some(spatial) => spatial.texel_size,
        }
    }

    /// The side in texels of a sampled material: `size` when given (checked by
    /// [`Self::cells_for`]), else the model's native side: R for the fixed-size G,
    /// [`DEFAULT_SPATIAL_SAMPLE_SIDE`] rounded up to a whole number of cells for a spatial G.
    pub fn sample_side(&self, size: Option<usize>) -> Result<usize> {
        let side = match (size, &self.spatial) {
            (Some(size), _) => size,
            (None, None) => self.resolution,
            (None, Some(_)) => {
                DEFAULT_SPATIAL_SAMPLE_SIDE.div_ceil(self.cell_size()) * self.cell_size()
            }
        };
        self.cells_for(side)?;
        Ok(side)
    }

    /// World side of a material `size` texels wide: the unit square
    /// ([`photomat_core::flash::PLANE_SIDE`]) for the fixed-size G, `size` × texel size for a
    /// spatial G, whose texel keeps its world size at every side (an error for a spatial G
    /// saved before the texel size was recorded).
    pub fn world_side(&self, size: usize) -> Result<f64> {
        self.cells_for(size)?;
        match (&self.spatial, self.texel_size()) {
            (None, _) => Ok(photomat_core::flash::PLANE_SIDE),
            (Some(_), Some(texel)) => Ok(size as f64 * texel),
            (Some(_), None) => bail!(
                "this spatial model does not record its texel size (gan.json: \
                 architecture.spatial.texel_size); resume its training once with the current \
                 photomat to record it"
            ),
        }
    }

    /// The texel size a material's maps record ([`photomat_core::MaterialMaps::texel_size`]):
    /// a spatial G's, so that derived maps (normals from heights) keep their meaning at every
    /// side; `None` for the fixed-size G, whose maps cover the unit square.
    pub fn map_texel_size(&self) -> Option<f64> {
        self.spatial.as_ref().and_then(|s| s.texel_size)
    }

    /// The number of base cells per side of an F of side `size`: `size / cell_size` for a
    /// spatial G and a positive multiple of the cell size, 4 for the fixed-size G at
    /// `size = resolution`; otherwise an error saying which sizes are possible.
    pub fn cells_for(&self, size: usize) -> Result<usize> {
        let cell = self.cell_size();
        match &self.spatial {
            Some(_) if size > 0 && size.is_multiple_of(cell) => Ok(size / cell),
            Some(_) => bail!(
                "a material side of {size} texels is not possible: this spatial generator makes \
                 sides that are positive multiples of its cell of {cell} texels \
                 (resolution {} / 4)",
                self.resolution
            ),
            None if size == self.resolution => Ok(BASE_RESOLUTION),
            None => bail!(
                "this generator makes {r}×{r} materials only (a fixed-size StyleGAN2 model); \
                 {size}×{size} needs a spatial generator",
                r = self.resolution
            ),
        }
    }

    /// Channel count of G's block and D's block at resolution `res` (the reference's table):
    /// `max(1, round(min(C / res, 512) · channel_multiplier))` with C = 16384 for models below
    /// 512² and 32768 at 512² and above (so 512 up to 32², 256 at 64², 128 at 128², 64 at 256²
    /// for a 256² model). Rounding to nearest keeps e.g. multiplier ¼ exact on the table's
    /// powers of two; the floor of 1 keeps tiny test configurations valid.
    pub fn channels_at(&self, res: usize) -> usize {
        let base = if self.resolution >= 512 { 32768 } else { 16384 };
        let full = (base / res).min(MAX_CHANNELS) as f64;
        ((full * self.channel_multiplier).round() as usize).max(1)
    }

    /// Number of block resolutions 4², 8², …, R² (log₂ R − 1).
    pub fn num_blocks(&self) -> usize {
        (self.resolution.trailing_zeros() - BASE_RESOLUTION.trailing_zeros() + 1) as usize
    }

    /// Number of per-layer w vectors the synthesis network consumes: one per modulated conv
    /// plus the last toFeature layer (StyleGAN2: 2·log₂ R − 2; 8 at 32², 14 at 256²).
    pub fn num_ws(&self) -> usize {
        2 * self.num_blocks()
    }
}

/// Deterministic pseudo-random tensors for tests and examples (candle's CPU generator cannot be
/// seeded): values uniform in [−1, 1) from a SplitMix64 stream, scaled by √3 so that their
/// variance is 1 like a standard normal's.
pub fn seeded_uniform(
    shape: impl Into<candle_core::Shape>,
    seed: u64,
    dtype: candle_core::DType,
    device: &candle_core::Device,
) -> Result<candle_core::Tensor> {
    photomat_core::rng::pseudo_random(shape, seed, candle_core::DType::F64, device)?
        .affine(3f64.sqrt(), 0.0)?
        .to_dtype(dtype)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channel_table_matches_design() {
        let cfg = GeneratorConfig::default();
        let table: Vec<usize> = [4, 8, 16, 32, 64, 128, 256]
            .iter()
            .map(|&r| cfg.channels_at(r))
            .collect();
        assert_eq!(table, [512, 512, 512, 512, 256, 128, 64]);
        let big = GeneratorConfig {
            resolution: 1024,
            ..Default::default()
        };
        assert_eq!(big.channels_at(64), 512);
        assert_eq!(big.channels_at(512), 64);
        assert_eq!(big.channels_at(1024), 32);
        let quarter = GeneratorConfig {
            channel_multiplier: 0.25,
            ..Default::default()
        };
        assert_eq!(quarter.channels_at(64), 64);
        let tiny = GeneratorConfig {
            channel_multiplier: 1e-4,
            ..Default::default()
        };
        assert_eq!(tiny.channels_at(4), 1);
        assert_eq!(cfg.num_ws(), 14);
    }

    #[test]
    fn config_rejects_bad_values() {
        let bad = [
            GeneratorConfig {
                resolution: 48,
                ..Default::default()
            },
            GeneratorConfig {
                resolution: 16,
                ..Default::default()
            },
            GeneratorConfig {
                channel_multiplier: 0.0,
                ..Default::default()
            },
            GeneratorConfig {
                mapping_depth: 0,
                ..Default::default()
            },
            GeneratorConfig {
                w_avg_beta: 1.0,
                ..Default::default()
            },
            GeneratorConfig {
                tileable: true,
                spatial: Some(SpatialConfig {
                    waves: limits::MAX_WAVES + 1,
                    ..SpatialConfig::default()
                }),
                ..Default::default()
            },
        ];
        for cfg in bad {
            assert!(cfg.validate().is_err(), "{cfg:?}");
        }
        assert!(GeneratorConfig::default().validate().is_ok());
    }
}
