//! StyleGAN2's path-length regularisation of G (Karras et al. 2020 §3.2; StyleGAN2-ADA
//! `loss.py`, phase `Greg`), optional in PhotoMat's reference configuration
//! (`docs/neural-models.md`, "GAN training": weight 2 every 4 steps).
//!
//! For a half batch (`pl_batch_shrink` = 2) of generated images x = M(G(ws), ω) and an image
//! of noise y ~ N(0, I)/√(H·W), the Jacobian-vector product `g = ∂(x·y)/∂ws` gives per sample
//! the path length `a = √(mean over layers of ‖g_layer‖²)`. A running mean ā of a
//! (decay 0.01) is the target: the penalty `mean (a − ā)² · weight · interval` (lazy, as
//! R1) asks a fixed-size step in w to change the image by a fixed amount in every direction,
//! which smooths the mapping from w to images.
//!
//! `g` keeps its graph (a double backward): it comes from candle's `backward_keeping_graph`
//! (`docs/candle-notes.md`, "Second-order gradients").

use candle_core::{DType, Device, Result, Tensor, Var, bail};
use photomat_core::rng::SplitMix64;

/// Decay of the running mean path length (StyleGAN2 `pl_decay`).
pub const PL_DECAY: f64 = 0.01;
/// The regularisation batch is the training batch divided by this (StyleGAN2
/// `pl_batch_shrink`), at least 1.
pub const PL_BATCH_SHRINK: usize = 2;

/// The image-space noise y ~ N(0, I)/√(H·W), seeded.
///
/// # Shapes
/// → (B, C, H, W), f32.
pub fn pl_noise(shape: (usize, usize, usize, usize), seed: u64, device: &Device) -> Result<Tensor> {
    let (b, c, h, w) = shape;
    let scale = 1.0 / ((h * w) as f64).sqrt();
    let values: Vec<f32> = SplitMix64(seed)
        .normals(b * c * h * w)
        .into_iter()
        .map(|v| (v * scale) as f32)
        .collect();
    Tensor::from_vec(values, shape, device)
}

/// Per-sample path lengths `√(mean_layers ‖∂(x·y)/∂ws_layer‖²)`, keeping the graph so that
/// their gradient reaches G's parameters. `ws` must be a variable (candle keeps gradients of
/// variables only): the trainer adds a zero [`Var`] to the mapping's output and passes it.
///
/// # Shapes
/// images (B, C, H, W) computed from ws (B, L, D), noise like images → (B).
pub fn path_lengths(images: &Tensor, ws: &Tensor, noise: &Tensor) -> Result<Tensor> {
    let grads = (images * noise)?.sum_all()?.backward_keeping_graph()?;
    let Some(g) = grads.get(ws) else {
        bail!("path length: the images do not depend on ws");
    };
    // √ of a sum of squares: its derivative is unbounded only where every component of g
    // vanishes, which a generator whose images depend on w does not reach (as in StyleGAN2).
    g.sqr()?.sum(2)?.mean(1)?.sqrt()
}

/// The running mean ā of the path lengths, a training-state variable.
#[derive(Debug, Clone)]
pub struct PathLengthMean {
    var: Var,
}

impl PathLengthMean {
    /// ā = 0 (StyleGAN2 starts from 0, so the first penalties are the lengths themselves).
    pub fn new(device: &Device) -> Result<Self> {
        Ok(Self {
            var: Var::zeros(1, DType::F64, device)?,
        })
    }

    /// The variable (for the training state file).
    pub fn var(&self) -> &Var {
        &self.var
    }

    /// ā.
    pub fn value(&self) -> Result<f64> {
        Ok(self.var.as_tensor().to_vec1::<f64>()?[0])
    }

    /// Moves ā towards `batch_mean` by [`PL_DECAY`] and returns the new ā (StyleGAN2 updates
    /// it before computing the penalty).
    pub fn update(&self, batch_mean: f64) -> Result<f64> {
        let old = self.value()?;
        let new = old + (batch_mean - old) * PL_DECAY;
        self.var.set(&Tensor::new(&[new], self.var.device())?)?;
        Ok(new)
    }
}

/// The lazy path-length loss `mean (a − ā)² · weight · interval`.
///
/// # Shapes
/// lengths (B) → scalar.
pub fn pl_loss(lengths: &Tensor, mean: f64, weight: f64, interval: usize) -> Result<Tensor> {
    (lengths - mean)?.sqr()?.mean_all()? * (weight * interval as f64)
}
