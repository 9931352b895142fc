//! The mapping network z → w (StyleGAN, Karras et al. 2019 §2; StyleGAN2-ADA
//! `MappingNetwork`), with the tracked average of w and the truncation trick.
//!
//! - z is normalised by its root mean square over the latent dimension
//!   (`z · rsqrt(mean(z²) + ε)`, StyleGAN's `normalize_2nd_moment`), then passes through
//!   `mapping_depth` fully connected layers (default 2: the PhotoMat reference; StyleGAN2 uses
//!   8) with learning-rate multiplier 0.01 and `lrelu` (0.2, gain √2).
//! - ε = 1e-8 (StyleGAN): mean(z²) ≈ 1 for z ~ N(0, I), so ε only keeps a zero latent finite.
//! - `w_avg` tracks the mean w during training: `w_avg ← β·w_avg + (1 − β)·mean_batch(w)` with
//!   β = 0.995. It is a buffer, not a trainable parameter: it lives in the VarMap (so
//!   checkpoints carry it) under the name `w_avg`, and optimisers must skip it
//!   ([`crate::trainable_vars`]).
//! - Truncation: `w_avg + ψ·(w − w_avg)`; ψ = 1 is the identity, ψ = 0 gives `w_avg`.
//! - Style mixing ([`mix_styles`]): per-layer w taken from a second latent from a cut-off
//!   layer on (StyleGAN §3.1; the reference trains with probability 0.9).
//!
//! Parameter names under `vb`: `fc{i}.weight`, `fc{i}.bias` for i < depth, and `w_avg`.

use candle_core::{D, Result, Tensor, Var, bail};
use candle_nn::{Init, VarBuilder};

use crate::GeneratorConfig;
use crate::equalized::{EqualizedLinear, LinearConfig, equalized_linear};

/// ε of the RMS normalisation of z (justified in the module docs).
pub const Z_NORM_EPS: f64 = 1e-8;

/// The mapping network.
#[derive(Debug, Clone)]
pub struct Mapping {
    layers: Vec<EqualizedLinear>,
    w_avg: Tensor,
    w_avg_beta: f64,
    latent_dim: usize,
}

impl Mapping {
    /// Builds the mapping network of `cfg` under `vb`.
    pub fn new(cfg: &GeneratorConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let layer_cfg = LinearConfig {
            lr_multiplier: cfg.mapping_lr_multiplier,
            ..Default::default()
        };
        let layers = (0..cfg.mapping_depth)
            .map(|i| {
                equalized_linear(
                    cfg.latent_dim,
                    cfg.latent_dim,
                    layer_cfg,
                    vb.pp(format!("fc{i}")),
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let w_avg = vb.get_with_hints(cfg.latent_dim, "w_avg", Init::Const(0.0))?;
        Ok(Self {
            layers,
            w_avg,
            w_avg_beta: cfg.w_avg_beta,
            latent_dim: cfg.latent_dim,
        })
    }

    /// z → w, without truncation.
    ///
    /// # Shapes
    /// (B, latent_dim) → (B, latent_dim).
    pub fn forward(&self, z: &Tensor) -> Result<Tensor> {
        let (_b, dim) = z.dims2()?;
        if dim != self.latent_dim {
            bail!(
                "mapping: latent of dimension {dim}, expected {}",
                self.latent_dim
            );
        }
        let rms = (z.sqr()?.mean_keepdim(D::Minus1)? + Z_NORM_EPS)?.sqrt()?;
        let mut x = z.broadcast_div(&rms)?;
        for layer in &self.layers {
            x = layer.forward_lrelu(&x)?;
        }
        Ok(x)
    }

    /// The tracked average w, shape (latent_dim).
    pub fn w_avg(&self) -> &Tensor {
        &self.w_avg
    }

    /// Moves `w_avg` towards the batch mean of `w` (a training step's update, no gradient):
    /// `w_avg ← β·w_avg + (1 − β)·mean(w)`.
    ///
    /// # Shapes
    /// w (B, latent_dim).
    pub fn update_w_avg(&self, w: &Tensor) -> Result<()> {
        let (_b, dim) = w.dims2()?;
        if dim != self.latent_dim {
            bail!(
                "w_avg update: w of dimension {dim}, expected {}",
                self.latent_dim
            );
        }
        if !self.w_avg.is_variable() {
            bail!("w_avg is not a variable (the mapping was built from a read-only VarBuilder)");
        }
        let mean = w.detach().mean(0)?;
        let next = ((self.w_avg.affine(self.w_avg_beta, 0.0))?
            + mean.affine(1.0 - self.w_avg_beta, 0.0)?)?;
        Var::from_tensor(&self.w_avg)?.set(&next)
    }

    /// Truncation trick: `w_avg + ψ·(w − w_avg)`.
    ///
    /// # Shapes
    /// (..., latent_dim) → same.
    pub fn truncate(&self, w: &Tensor, psi: f64) -> Result<Tensor> {
        if psi == 1.0 {
            return Ok(w.clone());
        }
        let avg = self.w_avg.broadcast_as(w.shape())?;
        (avg.affine(1.0 - psi, 0.0)? + w.affine(psi, 0.0)?)?.contiguous()
    }

    /// z → per-layer w: mapping, truncation with ψ, and broadcast to `num_ws` layers.
    ///
    /// # Shapes
    /// (B, latent_dim) → (B, num_ws, latent_dim).
    pub fn ws(&self, z: &Tensor, psi: f64, num_ws: usize) -> Result<Tensor> {
        let w = self.truncate(&self.forward(z)?, psi)?;
        let (b, d) = w.dims2()?;
        w.unsqueeze(1)?.broadcast_as((b, num_ws, d))?.contiguous()
    }
}

/// Style mixing: layers `0 … cutoff − 1` take their w from `a`, layers `cutoff …` from `b`.
///
/// # Shapes
/// a, b (B, num_ws, latent_dim), cutoff ≤ num_ws → (B, num_ws, latent_dim).
pub fn mix_styles(a: &Tensor, b: &Tensor, cutoff: usize) -> Result<Tensor> {
    let (_b, n, _d) = a.dims3()?;
    if a.dims() != b.dims() {
        bail!(
            "style mixing: shapes {:?} and {:?} differ",
            a.dims(),
            b.dims()
        );
    }
    if cutoff > n {
        bail!("style mixing: cut-off {cutoff} beyond {n} layers");
    }
    if cutoff == n {
        return Ok(a.clone());
    }
    if cutoff == 0 {
        return Ok(b.clone());
    }
    Tensor::cat(
        &[a.narrow(1, 0, cutoff)?, b.narrow(1, cutoff, n - cutoff)?],
        1,
    )
}
