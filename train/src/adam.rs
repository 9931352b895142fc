//! Adam (Kingma & Ba 2015) over a list of *named* candle [`Var`]s, with its whole state (step
//! count, first and second moments) held in a [`VarMap`] so that a training run can save it
//! with [`photomat_core::checkpoint::save_vars_atomic`] and resume bit-identically after
//! [`photomat_core::checkpoint::load_vars_checked`].
//!
//! The update is PyTorch's `torch.optim.Adam` (the optimiser of the StyleGAN2-ADA reference
//! code that PhotoMat builds on, and of PhotoMat's estimator), in the variable's dtype:
//!
//! ```text
//! t ← t + 1
//! m ← β₁·m + (1 − β₁)·g
//! v ← β₂·v + (1 − β₂)·g²
//! θ ← θ − lr/(1 − β₁ᵗ) · m / (√v / √(1 − β₂ᵗ) + ε)
//! ```
//!
//! Variables without a gradient in the [`GradStore`] are left alone, moments included (as
//! PyTorch does for parameters whose `.grad` is `None`); the step count is shared.
//!
//! On the CPU (f32, f64) each variable is updated by two in-place passes with no allocation,
//! the moments from the gradient and then the variable from the moments, in the order of
//! operations above (PyTorch's `fused` Adam does the same on CUDA). Composed from candle ops
//! the same update is eleven passes that each allocate their result; that path remains for
//! other devices and dtypes and runs inside [`photomat_kernels::with_reference_ops`]
//! (`docs/benchmarks/conv-kernels.md`, "Fused Adam"; bench `train/benches/adam.rs`).
//!
//! [`AdamConfig::lazy`] applies StyleGAN2's lazy-regularisation correction (Karras et al. 2020,
//! Appendix B / `training_loop.py`): a network regularised every k steps uses
//! `lr·c`, `β₁^c`, `β₂^c` with `c = k/(k+1)`.
//!
//! # State layout
//! [`Adam::state`] is a [`VarMap`] with
//! - `step`: shape `[1]`, f64, the number of steps taken (exact up to 2⁵³);
//! - `m.<name>` and `v.<name>`: the moments of variable `<name>`, its shape and dtype.
//!
//! Loading a file saved from an optimiser over other variables (other names or shapes) fails
//! and names the mismatching tensor, leaving the state untouched.
//!
//! ```no_run
//! use candle_core::{DType, Device, Var};
//! use photomat_train::adam::{Adam, AdamConfig};
//!
//! # fn main() -> candle_core::Result<()> {
//! let w = Var::zeros((3,), DType::F32, &Device::Cpu)?;
//! let mut opt = Adam::new(vec![("w".into(), w.clone())], AdamConfig::default())?;
//! let loss = w.as_tensor().affine(2.0, -1.0)?.sqr()?.sum_all()?;
//! opt.step(&loss.backward()?)?;
//! opt.save(std::path::Path::new("opt.safetensors"))?; // resume: opt.load(..)
//! # Ok(()) }
//! ```

use std::ops::SubAssign;
use std::path::Path;

use candle_core::backprop::GradStore;
use candle_core::{
    CpuStorage, DType, InplaceOp2, InplaceOp3, Layout, Result, Tensor, Var, WithDType, bail,
};
use candle_nn::VarMap;
use num_traits::Float;

use crate::varmap::{lock, sorted_vars};

/// Name of the step counter in [`Adam::state`].
pub const STEP_NAME: &str = "step";

/// Hyper-parameters of [`Adam`]. The defaults are StyleGAN2's GAN setting at 256² (Karras et
/// al. 2020; lr 0.0025, β = (0, 0.99), ε = 1e-8), without the lazy-regularisation correction.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdamConfig {
    /// Learning rate.
    pub lr: f64,
    /// Decay of the first moment, in [0, 1).
    pub beta1: f64,
    /// Decay of the second moment, in [0, 1).
    pub beta2: f64,
    /// Added to the bias-corrected √v before dividing (PyTorch's placement).
    pub eps: f64,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            lr: 0.0025,
            beta1: 0.0,
            beta2: 0.99,
            eps: 1e-8,
        }
    }
}

impl AdamConfig {
    /// Kingma & Ba 2015's defaults (β = (0.9, 0.999), ε = 1e-8) at learning rate `lr`: the
    /// setting of the fits that optimise maps or latents directly (photo capture and its prior).
    pub fn kingma(lr: f64) -> Self {
        Self {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }

    /// The lazy-regularisation correction for a network whose regulariser runs every
    /// `interval` steps: with `c = interval/(interval+1)`, `lr·c`, `β₁^c`, `β₂^c`
    /// (StyleGAN2). An interval of 0 means "no lazy regulariser" and returns `self`.
    pub fn lazy(self, interval: usize) -> Self {
        if interval == 0 {
            return self;
        }
        let c = interval as f64 / (interval as f64 + 1.0);
        Self {
            lr: self.lr * c,
            beta1: self.beta1.powf(c),
            beta2: self.beta2.powf(c),
            eps: self.eps,
        }
    }

    /// Checks the ranges; the error names the field and its value.
    pub fn validate(&self) -> Result<()> {
        if !(self.lr.is_finite() && self.lr > 0.0) {
            bail!("Adam learning rate {} must be positive and finite", self.lr);
        }
        for (name, b) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(0.0..1.0).contains(&b) {
                bail!("Adam {name} {b} must be in [0, 1)");
            }
        }
        if !(self.eps.is_finite() && self.eps > 0.0) {
            bail!("Adam eps {} must be positive and finite", self.eps);
        }
        Ok(())
    }
}

/// One optimised variable and its moments (the moment `Var`s are shared with the state map).
struct Slot {
    var: Var,
    m: Var,
    v: Var,
}

/// The constants of one Adam step `t` (module docs): `step_size = lr/(1 − β₁ᵗ)`,
/// `inv_sqrt_bias2 = 1/√(1 − β₂ᵗ)`.
#[derive(Debug, Clone, Copy)]
struct Update {
    beta1: f64,
    beta2: f64,
    step_size: f64,
    inv_sqrt_bias2: f64,
    eps: f64,
}

/// Whether a slot can take the fused in-place update: CPU, f32 or f64, every tensor
/// contiguous (a `Var` always is; the gradient is made so by the caller), and not inside
/// [`photomat_kernels::with_reference_ops`] (which times and checks the composed update).
fn fused_path(slot: &Slot, g: &Tensor) -> bool {
    let t = slot.var.as_tensor();
    !photomat_kernels::reference_ops()
        && t.device().is_cpu()
        && matches!(t.dtype(), DType::F32 | DType::F64)
        && [t, slot.m.as_tensor(), slot.v.as_tensor()]
            .iter()
            .all(|x| x.is_contiguous())
        && g.shape() == t.shape()
}

impl Update {
    /// The update from candle ops: eleven passes over the variable, each allocating its
    /// result. The path for devices and dtypes the fused update does not handle.
    fn apply_composed(&self, slot: &Slot, g: &Tensor) -> Result<()> {
        let m = ((slot.m.as_tensor() * self.beta1)? + (g * (1.0 - self.beta1))?)?;
        let v = ((slot.v.as_tensor() * self.beta2)? + (g.sqr()? * (1.0 - self.beta2))?)?;
        let denom = v.sqrt()?.affine(self.inv_sqrt_bias2, self.eps)?;
        let update = (m.div(&denom)? * self.step_size)?;
        slot.var.set(&slot.var.as_tensor().sub(&update)?)?;
        slot.m.set(&m)?;
        slot.v.set(&v)?;
        Ok(())
    }

    /// The same update as two in-place passes and no allocation: the moments from the
    /// gradient, then the variable from the moments ([`MomentsOp`], [`ParameterOp`]).
    fn apply_fused(&self, slot: &Slot, g: &Tensor) -> Result<()> {
        slot.m.as_tensor().inplace_op2(
            g,
            &MomentsOp {
                beta: self.beta1,
                squared: false,
            },
        )?;
        slot.v.as_tensor().inplace_op2(
            g,
            &MomentsOp {
                beta: self.beta2,
                squared: true,
            },
        )?;
        slot.var.as_tensor().inplace_op3(
            slot.m.as_tensor(),
            slot.v.as_tensor(),
            &ParameterOp(*self),
        )
    }
}

/// The contiguous elements of a CPU tensor's storage (the fused path's tensors all are).
fn elements<'a, T: WithDType>(data: &'a [T], layout: &Layout) -> Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&data[start..end]),
        None => bail!("Adam: fused update on a non-contiguous tensor"),
    }
}

/// Mutable [`elements`].
fn elements_mut<'a, T: WithDType>(data: &'a mut [T], layout: &Layout) -> Result<&'a mut [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&mut data[start..end]),
        None => bail!("Adam: fused update on a non-contiguous tensor"),
    }
}

/// A moment in place: `m ← β·m + (1 − β)·g`, or `v ← β·v + (1 − β)·g²` when `squared`.
struct MomentsOp {
    beta: f64,
    squared: bool,
}

impl MomentsOp {
    fn run<T: WithDType + Float>(&self, moment: &mut [T], g: &[T]) {
        let (beta, rest) = (T::from_f64(self.beta), T::from_f64(1.0 - self.beta));
        if self.squared {
            for (m, &g) in moment.iter_mut().zip(g) {
                *m = *m * beta + g * g * rest;
            }
        } else {
            for (m, &g) in moment.iter_mut().zip(g) {
                *m = *m * beta + g * rest;
            }
        }
    }
}

impl InplaceOp2 for MomentsOp {
    fn name(&self) -> &'static str {
        "adam-moment"
    }

    fn cpu_fwd(
        &self,
        s1: &mut CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> Result<()> {
        match (s1, s2) {
            (CpuStorage::F32(m), CpuStorage::F32(g)) => {
                self.run(elements_mut(m, l1)?, elements(g, l2)?)
            }
            (CpuStorage::F64(m), CpuStorage::F64(g)) => {
                self.run(elements_mut(m, l1)?, elements(g, l2)?)
            }
            _ => bail!("Adam: fused moments need f32 or f64 tensors of one dtype"),
        }
        Ok(())
    }
}

/// The variable in place from its updated moments:
/// `θ ← θ − step_size · m / (√v · inv_sqrt_bias2 + ε)`.
struct ParameterOp(Update);

impl ParameterOp {
    fn run<T: WithDType + Float + SubAssign>(&self, theta: &mut [T], m: &[T], v: &[T]) {
        let Update {
            step_size,
            inv_sqrt_bias2,
            eps,
            ..
        } = self.0;
        let (step, scale, eps) = (
            T::from_f64(step_size),
            T::from_f64(inv_sqrt_bias2),
            T::from_f64(eps),
        );
        for ((p, &m), &v) in theta.iter_mut().zip(m).zip(v) {
            *p -= m / (v.sqrt() * scale + eps) * step;
        }
    }
}

impl InplaceOp3 for ParameterOp {
    fn name(&self) -> &'static str {
        "adam-parameter"
    }

    fn cpu_fwd(
        &self,
        s1: &mut CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<()> {
        match (s1, s2, s3) {
            (CpuStorage::F32(p), CpuStorage::F32(m), CpuStorage::F32(v)) => {
                self.run(elements_mut(p, l1)?, elements(m, l2)?, elements(v, l3)?)
            }
            (CpuStorage::F64(p), CpuStorage::F64(m), CpuStorage::F64(v)) => {
                self.run(elements_mut(p, l1)?, elements(m, l2)?, elements(v, l3)?)
            }
            _ => bail!("Adam: fused update needs f32 or f64 tensors of one dtype"),
        }
        Ok(())
    }
}

/// Adam over named variables; see the module documentation for the update and the state.
pub struct Adam {
    config: AdamConfig,
    names: Vec<String>,
    slots: Vec<Slot>,
    step: Var,
    state: VarMap,
}

impl Adam {
    /// An optimiser over `vars` (name, variable), moments at zero, step 0. Names must be
    /// unique; the same `Var` must not be listed twice.
    pub fn new(vars: Vec<(String, Var)>, config: AdamConfig) -> Result<Self> {
        config.validate()?;
        let state = VarMap::new();
        let step = Var::zeros(1, DType::F64, &candle_core::Device::Cpu)?;
        let mut names = Vec::with_capacity(vars.len());
        let mut slots = Vec::with_capacity(vars.len());
        {
            let mut data = lock(&state);
            data.insert(STEP_NAME.to_string(), step.clone());
            for (name, var) in vars {
                let m = Var::zeros(var.shape(), var.dtype(), var.device())?;
                let v = Var::zeros(var.shape(), var.dtype(), var.device())?;
                let m_key = format!("m.{name}");
                if data.contains_key(&m_key) {
                    bail!("Adam: variable `{name}` is listed twice");
                }
                data.insert(m_key, m.clone());
                data.insert(format!("v.{name}"), v.clone());
                names.push(name);
                slots.push(Slot { var, m, v });
            }
        }
        Ok(Self {
            config,
            names,
            slots,
            step,
            state,
        })
    }

    /// An optimiser over the variables of `vars` whose names `trainable` accepts, sorted by
    /// name. Buffers updated outside the optimiser (the generator's tracked `w_avg`) are the
    /// caller's to leave out: `|_| true` optimises the whole map.
    pub fn for_varmap(
        vars: &VarMap,
        trainable: impl Fn(&str) -> bool,
        config: AdamConfig,
    ) -> Result<Self> {
        Self::new(sorted_vars(vars, trainable), config)
    }

    /// Applies one update from the gradients in `grads`; variables without a gradient are
    /// skipped. Gradients are not checked for finiteness here (see [`crate::nan_guard`]).
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        let t = self.step_count() + 1;
        let AdamConfig {
            lr,
            beta1,
            beta2,
            eps,
        } = self.config;
        let bias1 = 1.0 - beta1.powi(t as i32);
        let update = Update {
            beta1,
            beta2,
            step_size: lr / bias1,
            inv_sqrt_bias2: 1.0 / (1.0 - beta2.powi(t as i32)).sqrt(),
            eps,
        };
        for slot in &self.slots {
            let Some(g) = grads.get(slot.var.as_tensor()) else {
                continue;
            };
            let g = g.to_dtype(slot.var.dtype())?;
            if fused_path(slot, &g) {
                update.apply_fused(slot, &g.contiguous()?)?;
            } else {
                update.apply_composed(slot, &g)?;
            }
        }
        self.step
            .set(&Tensor::new(&[t as f64], self.step.device())?)?;
        Ok(())
    }

    /// Number of steps taken (restored by [`Adam::load`]).
    pub fn step_count(&self) -> u64 {
        self.step
            .as_tensor()
            .to_vec1::<f64>()
            .map(|v| v[0] as u64)
            .unwrap_or(0)
    }

    /// Current learning rate.
    pub fn lr(&self) -> f64 {
        self.config.lr
    }

    /// Sets the learning rate (schedules); the moments are kept.
    pub fn set_lr(&mut self, lr: f64) {
        self.config.lr = lr;
    }

    /// The hyper-parameters in use.
    pub fn config(&self) -> &AdamConfig {
        &self.config
    }

    /// The optimised variables with their names, in construction order.
    pub fn vars(&self) -> impl Iterator<Item = (&str, &Var)> {
        self.names
            .iter()
            .map(String::as_str)
            .zip(self.slots.iter().map(|s| &s.var))
    }

    /// The optimiser state (`step`, `m.<name>`, `v.<name>`; module docs). Its `Var`s are the
    /// live state: loading into them with
    /// [`photomat_core::checkpoint::load_vars_checked`] restores the optimiser, and they can
    /// be inserted under a prefix into a larger map to save one training-state file.
    pub fn state(&self) -> &VarMap {
        &self.state
    }

    /// Saves [`Adam::state`] atomically to the safetensors file `path`.
    pub fn save(&self, path: &Path) -> Result<()> {
        photomat_core::checkpoint::save_vars_atomic(&self.state, path)
            .map_err(candle_core::Error::wrap)
    }

    /// Restores the state saved by [`Adam::save`] for the same variables; the error names
    /// the file and the mismatching tensors, and nothing changes when it fails.
    pub fn load(&mut self, path: &Path) -> Result<()> {
        photomat_core::checkpoint::load_vars_checked(&self.state, path)
            .map_err(candle_core::Error::wrap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    fn scalar(v: &Var) -> f64 {
        v.as_tensor().to_vec1::<f64>().unwrap()[0]
    }

    /// Two steps on loss = (θ − 3)² from θ = 1 against the closed form computed by hand.
    #[test]
    fn two_steps_match_closed_form() {
        let dev = Device::Cpu;
        let theta = Var::new(&[1.0f64], &dev).unwrap();
        let cfg = AdamConfig {
            lr: 0.1,
            beta1: 0.9,
            beta2: 0.99,
            eps: 1e-8,
        };
        let mut opt = Adam::new(vec![("theta".into(), theta.clone())], cfg).unwrap();
        let loss = |t: &Var| {
            (t.as_tensor() - 3.0)
                .unwrap()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap()
        };

        // Step 1: g = 2(1 − 3) = −4; m = 0.1·(−4) = −0.4; v = 0.01·16 = 0.16;
        // θ = 1 − 0.1/(1−0.9) · (−0.4) / (√0.16/√(1−0.99) + ε) = 1 + 0.4/4 ≈ 1.1.
        opt.step(&loss(&theta).backward().unwrap()).unwrap();
        let m1: f64 = -0.4;
        let v1: f64 = 0.16;
        let t1 = 1.0 - 0.1 / 0.1 * m1 / (v1.sqrt() / (0.01f64).sqrt() + 1e-8);
        assert!((scalar(&theta) - t1).abs() < 1e-12, "{}", scalar(&theta));

        // Step 2: g = 2(t1 − 3).
        opt.step(&loss(&theta).backward().unwrap()).unwrap();
        let g2 = 2.0 * (t1 - 3.0);
        let m2 = 0.9 * m1 + 0.1 * g2;
        let v2 = 0.99 * v1 + 0.01 * g2 * g2;
        let b1 = 1.0 - 0.9f64.powi(2);
        let b2 = 1.0 - 0.99f64.powi(2);
        let t2 = t1 - 0.1 / b1 * m2 / (v2.sqrt() / b2.sqrt() + 1e-8);
        assert!(
            (scalar(&theta) - t2).abs() < 1e-12,
            "{} vs {t2}",
            scalar(&theta)
        );
        assert_eq!(opt.step_count(), 2);
    }

    /// The fused in-place update equals the composed candle-op update over several steps on
    /// f32 tensors with mixed-sign, mixed-magnitude gradients (same operation order, so equal to
    /// within an ulp or two of the values).
    #[test]
    fn fused_update_equals_the_composed_one() -> Result<()> {
        let dev = Device::Cpu;
        let init: Vec<f32> = (0..257)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) / 7.0)
            .collect();
        let slot = |data: &[f32]| -> Result<Slot> {
            let var = Var::from_vec(data.to_vec(), (257,), &dev)?;
            Ok(Slot {
                m: Var::zeros(var.shape(), DType::F32, &dev)?,
                v: Var::zeros(var.shape(), DType::F32, &dev)?,
                var,
            })
        };
        let (fused, composed) = (slot(&init)?, slot(&init)?);
        for t in 1..=4i32 {
            let g: Vec<f32> = (0..257)
                .map(|i| (((i * 13 + t * 7) % 29) as f32 - 14.0) * 10f32.powi(i % 7 - 3))
                .collect();
            let g = Tensor::from_vec(g, (257,), &dev)?;
            let update = Update {
                beta1: 0.9,
                beta2: 0.99,
                step_size: 0.01 / (1.0 - 0.9f64.powi(t)),
                inv_sqrt_bias2: 1.0 / (1.0 - 0.99f64.powi(t)).sqrt(),
                eps: 1e-8,
            };
            assert!(fused_path(&fused, &g));
            update.apply_fused(&fused, &g)?;
            update.apply_composed(&composed, &g)?;
        }
        for (a, b) in [
            (&fused.var, &composed.var),
            (&fused.m, &composed.m),
            (&fused.v, &composed.v),
        ] {
            let (a, b) = (
                a.as_tensor().to_vec1::<f32>()?,
                b.as_tensor().to_vec1::<f32>()?,
            );
            for (x, y) in a.iter().zip(&b) {
                assert!(
                    (x - y).abs() <= 2.0 * f32::EPSILON * y.abs().max(1e-30),
                    "{x} vs {y}"
                );
            }
        }
        Ok(())
    }

    #[test]
    fn lazy_correction_and_validation() {
        let c = AdamConfig::default().lazy(16);
        let k = 16.0 / 17.0;
        assert!((c.lr - 0.0025 * k).abs() < 1e-15);
        assert_eq!(c.beta1, 0.0);
        assert!((c.beta2 - 0.99f64.powf(k)).abs() < 1e-15);
        assert_eq!(AdamConfig::default().lazy(0), AdamConfig::default());
        let bad = AdamConfig {
            beta2: 1.0,
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("beta2"));
    }

    /// Saving after one step and loading into a fresh optimiser gives the same second step
    /// as continuing; another variable set is refused by name.
    #[test]
    fn state_round_trips_for_resume() {
        let dev = Device::Cpu;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("adam.safetensors");
        let make = |x: f32| Var::new(&[x, -2.0 * x], &dev).unwrap();
        let loss = |t: &Var| t.as_tensor().sqr().unwrap().sum_all().unwrap();

        let a = make(1.0);
        let mut opt_a = Adam::new(vec![("w".into(), a.clone())], AdamConfig::default()).unwrap();
        opt_a.step(&loss(&a).backward().unwrap()).unwrap();
        opt_a.save(&path).unwrap();
        opt_a.step(&loss(&a).backward().unwrap()).unwrap();

        let b = make(1.0);
        let mut opt_b = Adam::new(vec![("w".into(), b.clone())], AdamConfig::default()).unwrap();
        opt_b.step(&loss(&b).backward().unwrap()).unwrap(); // same θ after one step
        let fresh = make(0.0);
        fresh.set(b.as_tensor()).unwrap();
        let mut opt_c =
            Adam::new(vec![("w".into(), fresh.clone())], AdamConfig::default()).unwrap();
        opt_c.load(&path).unwrap();
        assert_eq!(opt_c.step_count(), 1);
        opt_c.step(&loss(&fresh).backward().unwrap()).unwrap();
        assert_eq!(
            fresh.as_tensor().to_vec1::<f32>().unwrap(),
            a.as_tensor().to_vec1::<f32>().unwrap()
        );

        let other = Var::new(&[0f32, 0.0], &dev).unwrap();
        let mut opt_d = Adam::new(vec![("u".into(), other)], AdamConfig::default()).unwrap();
        let err = opt_d.load(&path).unwrap_err().to_string();
        assert!(err.contains("m.u") || err.contains("m.w"), "{err}");
        assert_eq!(opt_d.step_count(), 0);
    }
}
