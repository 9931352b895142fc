//! The relighting MLP M (PhotoMat paper §3 "Relightable generator" and §4 "Implementation";
//! reference facts in `docs/neural-models.md`, "Relighting MLP M").
//!
//! Per texel, M maps the neural material's features and the light direction to an RGB value:
//! input `F ‖ ω` (32 + 3 = 35 channels), 8 fully connected layers 35 → 64 → … → 64 → 3,
//! `lrelu` (LeakyReLU 0.2 × √2) after the first seven, the last linear. The output lives in
//! the networks' encoded image space (`2·encoded − 1`, nominally [−1, 1]; `docs/conventions.md`,
//! "Image values") and is not clamped, so the discriminator's gradient never vanishes at the range
//! ends; clamp only for display. Every layer is an equalised-lr [`EqualizedLinear`] with lr
//! multiplier 0.01.
//!
//! On the CPU, M runs as photomat-kernels' fused per-texel MLP
//! ([`photomat_kernels::per_texel_mlp`]: texel rows in cache-sized blocks, one `gemm` per layer,
//! NCHW inputs and output without a concatenated copy; its backward is differentiable once
//! more for path-length regularisation). Inside [`photomat_kernels::with_reference_ops`] (and
//! on other devices) it is the candle composition: matrix products on (B·H·W, C) rows with the
//! activation of [`crate::activation`] (`docs/benchmarks/fused-ops.md`, "The relighting MLP M as
//! one fused per-texel op", compares the two).
//!
//! # Light input
//! With `relight_lobes` = [s₁ … s_L] M reads F ‖ ω ‖ ω_z^{s₁} … ω_z^{s_L}. Under the
//! collocated flash the half vector is ω itself, so a flat texel's specular peak is a bump of
//! width about 1/√s radians in ω around the normal: a plain MLP on ω must learn that sharp a
//! function from inputs that vary by a few hundredths across a patch, which its spectral bias
//! makes slow (the reason NeRF encodes positions, Mildenhall et al. 2020, §5.1). The lobes give
//! M Blinn–Phong's basis of peaks of every width at once (exponents 4 … 1024: 0.5 to 0.03 rad),
//! so that following the light is a linear readout from the first layer on. ω_z ∈ (0, 1]
//! (the flash is above the plane), so every power is finite and in (0, 1].
//!
//! # Relief
//! With `relief` on, M reads ω in the frame of a normal derived from a learned height channel
//! of F instead of ω itself ([`crate::relief`]).
//!
//! Parameter names under `vb`: `fc{i}.weight`, `fc{i}.bias`, i = 0 … 7, and `relief.weight`
//! with relief on.

use candle_core::{Result, Tensor, bail};
use candle_nn::VarBuilder;

use crate::GeneratorConfig;
use crate::activation::{LRELU_GAIN, LRELU_SLOPE};
use crate::equalized::{EqualizedLinear, LinearConfig, equalized_linear};
use crate::relief::{Edges, Relief};

/// Channels of the per-texel light direction ω.
pub const OMEGA_CHANNELS: usize = 3;
/// Channels of M's output (RGB).
pub const RGB_CHANNELS: usize = 3;

/// M's activation after every layer but the last: StyleGAN2's `lrelu` (LeakyReLU 0.2 × √2),
/// as [`crate::activation`].
const ACTIVATION: photomat_kernels::MlpActivation = photomat_kernels::MlpActivation {
    slope: LRELU_SLOPE,
    gain: LRELU_GAIN,
};

/// M's encoded output (`2·display − 1`, unbounded) as display values in [0, 1], clamped: how
/// every picture and image metric reads a relighting.
///
/// # Shapes
/// any → the same.
pub fn to_display(encoded: &Tensor) -> Result<Tensor> {
    encoded.affine(0.5, 0.5)?.clamp(0f32, 1f32)
}

/// The relighting MLP M.
#[derive(Debug, Clone)]
pub struct Relight {
    layers: Vec<EqualizedLinear>,
    feature_channels: usize,
    lobes: Vec<f64>,
    relief: Option<Relief>,
}

/// Default lobe exponents of new runs ([`crate::GeneratorConfig::relight_lobes`]; module
/// docs, "Light input"): peaks of width 0.5, 0.25, 0.125, 0.06 and 0.03 rad.
pub const DEFAULT_RELIGHT_LOBES: [f64; 5] = [4.0, 16.0, 64.0, 256.0, 1024.0];

impl Relight {
    /// Builds M of `cfg` (`feature_channels` + 3 → `relight_hidden` × (`relight_layers` − 1)
    /// → 3) under `vb`.
    pub fn new(cfg: &GeneratorConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let layer_cfg = LinearConfig {
            lr_multiplier: cfg.relight_lr_multiplier,
            ..Default::default()
        };
        let n = cfg.relight_layers;
        let layers = (0..n)
            .map(|i| {
                let fan_in = if i == 0 {
                    cfg.feature_channels + OMEGA_CHANNELS + cfg.relight_lobes.len()
                } else {
                    cfg.relight_hidden
                };
                let fan_out = if i + 1 == n {
                    RGB_CHANNELS
                } else {
                    cfg.relight_hidden
                };
                equalized_linear(fan_in, fan_out, layer_cfg, vb.pp(format!("fc{i}")))
            })
            .collect::<Result<Vec<_>>>()?;
        let relief = if cfg.relief {
            Some(Relief::new(
                cfg.feature_channels,
                cfg.relight_lr_multiplier,
                vb.pp("relief"),
            )?)
        } else {
            None
        };
        Ok(Self {
            layers,
            feature_channels: cfg.feature_channels,
            lobes: cfg.relight_lobes.clone(),
            relief,
        })
    }

    /// Channels of M's light input: ω and the lobes (module docs).
    pub fn light_channels(&self) -> usize {
        OMEGA_CHANNELS + self.lobes.len()
    }

    /// M's light input from ω: ω itself, or ω ‖ ω_z^{s₁} … ω_z^{s_L} (module docs).
    ///
    /// # Shapes
    /// (B, 3, H, W) → (B, 3 + L, H, W).
    pub fn light_input(&self, omega: &Tensor) -> Result<Tensor> {
        if self.lobes.is_empty() {
            return Ok(omega.clone());
        }
        // ω_z > 0 for a flash above the plane; the floor only guards powf against rounding.
        let z = omega.narrow(1, 2, 1)?.clamp(0f32, 1f32)?;
        let mut parts = vec![omega.clone()];
        for &s in &self.lobes {
            parts.push(z.powf(s)?);
        }
        Tensor::cat(&parts, 1)
    }

    /// The layers for the fused op, unless the reference composition is asked for.
    fn fused_layers(&self) -> Option<Vec<photomat_kernels::MlpLayer<'_>>> {
        if photomat_kernels::reference_ops() {
            return None;
        }
        self.layers.iter().map(EqualizedLinear::mlp_layer).collect()
    }

    /// M on rows: one texel per row.
    ///
    /// # Shapes
    /// (N, feature_channels + light channels) → (N, 3): rows of F ‖ [`Self::light_input`].
    pub fn forward_rows(&self, rows: &Tensor) -> Result<Tensor> {
        let (_n, c) = rows.dims2()?;
        if c != self.feature_channels + self.light_channels() {
            bail!(
                "relight: rows of {c} channels, expected {} features + {} for the light",
                self.feature_channels,
                self.light_channels()
            );
        }
        if let Some(layers) = self.fused_layers() {
            return photomat_kernels::per_texel_mlp_rows(rows, &layers, ACTIVATION);
        }
        let last = self.layers.len() - 1;
        let mut x = rows.clone();
        for (i, layer) in self.layers.iter().enumerate() {
            x = if i < last {
                layer.forward_lrelu(&x)?
            } else {
                layer.forward(&x)?
            };
        }
        Ok(x)
    }

    /// The relief's height projection, when M has one ([`crate::relief`]).
    pub fn relief(&self) -> Option<&Relief> {
        self.relief.as_ref()
    }

    /// Relights the neural material `features` — a whole, periodic material — under the
    /// per-texel light directions `omega` (e.g. `photomat_core::FlashGeometry::omega`).
    ///
    /// # Shapes
    /// features (B, feature_channels, H, W), omega (B, 3, H, W) → (B, 3, H, W).
    pub fn forward(&self, features: &Tensor, omega: &Tensor) -> Result<Tensor> {
        self.forward_with_edges(features, omega, Edges::Wrap)
    }

    /// [`Self::forward`] on a window cut from a larger feature field (the spatial trainer's
    /// patches): the relief's differences do not wrap across the window's border.
    ///
    /// # Shapes
    /// features (B, feature_channels, H, W), omega (B, 3, H, W) → (B, 3, H, W).
    pub fn forward_window(&self, features: &Tensor, omega: &Tensor) -> Result<Tensor> {
        self.forward_with_edges(features, omega, Edges::Clamp)
    }

    fn forward_with_edges(
        &self,
        features: &Tensor,
        omega: &Tensor,
        edges: Edges,
    ) -> Result<Tensor> {
        let (b, c, h, w) = features.dims4()?;
        if c != self.feature_channels {
            bail!(
                "relight: features of {c} channels, expected {}",
                self.feature_channels
            );
        }
        if omega.dims4()? != (b, OMEGA_CHANNELS, h, w) {
            bail!(
                "relight: ω of shape {:?} does not match features {:?}",
                omega.dims(),
                features.dims()
            );
        }
        let light = match &self.relief {
            Some(relief) => self.light_input(&relief.local_omega(features, omega, edges)?)?,
            None => self.light_input(omega)?,
        };
        if let Some(layers) = self.fused_layers() {
            return photomat_kernels::per_texel_mlp(features, &light, &layers, ACTIVATION);
        }
        let rows = Tensor::cat(&[features, &light], 1)?
            .permute((0, 2, 3, 1))?
            .contiguous()?
            .reshape((b * h * w, c + self.light_channels()))?;
        self.forward_rows(&rows)?
            .reshape((b, h, w, RGB_CHANNELS))?
            .permute((0, 3, 1, 2))?
            .contiguous()
    }
}
