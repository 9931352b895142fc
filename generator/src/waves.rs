//! Periodic channels of a spatial G: plane waves whose wave vectors follow the material's w,
//! for lattices (tiles, weave, planks) that repeat across many base cells.
//!
//! PSGAN (Bergmann, Jetchev, Vollgraf 2017, "Learning Texture Manifolds with the Periodic
//! Spatial GAN", §3.3) adds periodic latent channels `sin(K·x + φ)` to the local ones, with
//! the wave vectors K a learned function of the global latent: the lattice's period and
//! orientation then belong to the material, and the i.i.d. local latents no longer have to
//! re-draw the lattice cell by cell in step with their neighbours (docs/neural-models.md,
//! "Regular lattices"). Here, with [`SpatialConfig::waves`](crate::SpatialConfig) = n:
//!
//! - **Wave vectors** `k = A·w / cell` (B, n, 2) in cycles per texel of F, from the first
//!   layer's w by one equalised linear layer A (w_dim → 2n): a material's lattice is part of
//!   its style, truncation ψ pulls it towards the average material's.
//! - **Whole periods per sample.** A sample of side N texels uses `m = round(k·N)` whole
//!   cycles per side, so every wave, and so every sample, stays periodic at its own side
//!   (tileable at any size, like the rest of the spatial G). Rounding has no gradient; training
//!   passes the gradient of `k·N` through it (the straight-through estimator, Bengio, Léonard,
//!   Courville 2013). At the 80-texel training samples a wave's period moves by at most half a
//!   cycle per side; at 512² by ten times less.
//! - **At every block.** Each block's input features (the base features at 4², the previous
//!   block's features above) get a learned 1×1 projection (2n → C, no bias) of `sin` and `cos`
//!   of every wave at that grid's texel centres. PSGAN feeds the waves at its input grid only;
//!   here a base cell is 16 texels wide, and a weave's period of about 8 texels is beyond what
//!   a grid of one value per cell can carry (2 cells per period at the least).
//! - **Band-limited per grid.** A wave whose frequency along an axis exceeds ¼ cycle per texel
//!   of a block's grid fades out linearly to 0 at ½ (that grid's Nyquist frequency), so no
//!   block sees it aliased; finer grids still carry it.
//! - **No random phase.** PSGAN draws φ per sample. In training a spatial G's fakes are random
//!   windows of a periodic sample ([`crate::train`]), which already places the lattice anywhere
//!   in D's view, so here the waves start at the sample's corner: a seed's material is the same
//!   at every sampling, and translating the local field by k cells translates everything but
//!   the lattice (the lattice moves only by whole periods).
//!
//! Parameter names under the synthesis `vb`: `waves.affine.{weight,bias}` and
//! `waves.b{r}.weight` (the projection into block r's input, (C, 2n, 1, 1)).

use std::f64::consts::TAU;

use candle_core::{Result, Tensor, bail};
use candle_nn::VarBuilder;

use crate::equalized::{EqualizedConv2d, EqualizedLinear, LinearConfig};
use crate::equalized::{equalized_conv2d, equalized_linear};
use crate::padding::Padding;

/// Below this many cycles per texel of a block's grid a wave enters that block at full
/// amplitude (four texels per period); above it the wave fades out.
const FULL_BAND: f64 = 0.25;
/// A grid's Nyquist frequency, where a wave's amplitude reaches 0.
const NYQUIST: f64 = 0.5;

/// The wave-vector layer and the per-block projections.
#[derive(Debug, Clone)]
pub struct PeriodicWaves {
    affine: EqualizedLinear,
    projections: Vec<EqualizedConv2d>,
    waves: usize,
    cell_size: usize,
}

/// Builds the [`PeriodicWaves`] of `waves` waves for a G whose blocks are `blocks`, each as
/// (its resolution r, the channels of its input), under `vb` (`affine`, `b{r}`).
pub fn periodic_waves(
    waves: usize,
    w_dim: usize,
    cell_size: usize,
    blocks: &[(usize, usize)],
    vb: VarBuilder,
) -> Result<PeriodicWaves> {
    if waves == 0 {
        bail!("periodic waves: at least one wave is needed");
    }
    let affine = equalized_linear(w_dim, 2 * waves, LinearConfig::default(), vb.pp("affine"))?;
    let projections = blocks
        .iter()
        .map(|&(resolution, channels)| {
            equalized_conv2d(
                2 * waves,
                channels,
                1,
                false,
                vb.pp(format!("b{resolution}")),
            )
        })
        .collect::<Result<_>>()?;
    Ok(PeriodicWaves {
        affine,
        projections,
        waves,
        cell_size,
    })
}

impl PeriodicWaves {
    /// Number of waves.
    pub fn waves(&self) -> usize {
        self.waves
    }

    /// The continuous wave vectors of the materials, in cycles per texel of F.
    ///
    /// # Shapes
    /// w (B, w_dim) → (B, waves, 2), (k_x, k_y).
    pub fn wave_vectors(&self, w: &Tensor) -> Result<Tensor> {
        let (b, _) = w.dims2()?;
        self.affine
            .forward(w)?
            .affine(1.0 / self.cell_size as f64, 0.0)?
            .reshape((b, self.waves, 2))
    }

    /// Whole cycles per side of a sample `side` texels wide: `round(k·side)` forward, the
    /// gradient of `k·side` backward (straight-through).
    ///
    /// # Shapes
    /// k (B, waves, 2) → (B, waves, 2).
    pub fn cycles_per_side(k: &Tensor, side: usize) -> Result<Tensor> {
        let continuous = k.affine(side as f64, 0.0)?;
        let rounding = (continuous.round()? - &continuous)?.detach();
        continuous + rounding
    }

    /// `sin` and `cos` of every wave at the texel centres of an s × s grid covering the
    /// sample, each wave faded out towards the grid's Nyquist frequency (module docs).
    ///
    /// # Shapes
    /// cycles (B, waves, 2) → (B, 2·waves, s, s): channels `sin` of every wave, then `cos`.
    pub fn features(cycles: &Tensor, s: usize) -> Result<Tensor> {
        let (b, n, _) = cycles.dims3()?;
        let (dtype, device) = (cycles.dtype(), cycles.device());
        // Texel centres as fractions of the side: (i + ½)/s.
        let u = Tensor::arange(0u32, s as u32, device)?
            .to_dtype(dtype)?
            .affine(1.0 / s as f64, 0.5 / s as f64)?;
        let m_x = cycles.narrow(2, 0, 1)?.reshape((b, n, 1, 1))?;
        let m_y = cycles.narrow(2, 1, 1)?.reshape((b, n, 1, 1))?;
        let phase = m_x
            .broadcast_mul(&u.reshape((1, 1, 1, s))?)?
            .broadcast_add(&m_y.broadcast_mul(&u.reshape((1, 1, s, 1))?)?)?
            .affine(TAU, 0.0)?;
        // Amplitude per axis: 1 up to FULL_BAND cycles per texel, 0 at NYQUIST.
        let band = |m: &Tensor| -> Result<Tensor> {
            m.abs()?
                .affine(
                    -1.0 / (s as f64 * (NYQUIST - FULL_BAND)),
                    NYQUIST / (NYQUIST - FULL_BAND),
                )?
                .clamp(0.0, 1.0)
        };
        let amplitude = (band(&m_x)? * band(&m_y)?)?;
        Tensor::cat(
            &[
                phase.sin()?.broadcast_mul(&amplitude)?,
                phase.cos()?.broadcast_mul(&amplitude)?,
            ],
            1,
        )
    }

    /// How strongly each wave enters each block: the norm of its two columns (`sin`, `cos`)
    /// in the block's effective projection, per block (in block order) and wave. A wave that
    /// training left unused has small norms everywhere.
    pub fn projection_norms(&self) -> Result<Vec<Vec<f64>>> {
        self.projections
            .iter()
            .map(|p| {
                let w = p.effective_weight()?.to_dtype(candle_core::DType::F64)?;
                let per_input = w.sqr()?.sum_keepdim(0)?.flatten_all()?.to_vec1::<f64>()?;
                Ok((0..self.waves)
                    .map(|j| (per_input[j] + per_input[self.waves + j]).sqrt())
                    .collect())
            })
            .collect()
    }

    /// Block `block`'s input features plus the projection of the waves at their grid, for a
    /// sample `side` texels wide.
    ///
    /// # Shapes
    /// x (B, C, s, s), cycles (B, waves, 2) from [`Self::cycles_per_side`] → (B, C, s, s).
    pub fn add_to_block_input(&self, block: usize, x: &Tensor, cycles: &Tensor) -> Result<Tensor> {
        let Some(projection) = self.projections.get(block) else {
            bail!(
                "periodic waves: no projection for block {block} of {}",
                self.projections.len()
            );
        };
        let s = x.dim(2)?;
        // A 1×1 conv reads no neighbour: the padding mode is irrelevant.
        let y = projection.conv(&Self::features(cycles, s)?, 1, 0, Padding::Zeros)?;
        x + y
    }
}
