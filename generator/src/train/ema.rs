//! The exponential moving average of G's weights, G_ema (Karras et al. 2018 §4 / StyleGAN2-ADA
//! `training_loop.py`), which is what a trained GAN samples with.
//!
//! After each step, with B images per step, half-life `ema_nimg = 1000·ema_kimg` images
//! (optionally limited to `rampup · images_seen` early in training),
//! `β = 0.5^(B / ema_nimg)` and every parameter moves as `p_ema ← β·p_ema + (1 − β)·p`.
//! Buffers (the tracked `w_avg`) are *copied*, not averaged, exactly as the reference copies
//! `G.buffers()` into `G_ema`.

use candle_core::{Result, Var};
use candle_nn::VarMap;

use crate::checkpoint::is_buffer;

/// Smallest half-life in images: at the very first step the ramp-up gives 0 and β = 0 (a
/// copy); the floor only keeps the division defined, as the reference's `max(ema_nimg, 1e-8)`.
const MIN_EMA_NIMG: f64 = 1e-8;

/// The EMA decay β of one step (module docs).
pub fn ema_beta(batch: usize, ema_kimg: f64, rampup: Option<f64>, images_seen: u64) -> f64 {
    let mut nimg = ema_kimg * 1000.0;
    if let Some(r) = rampup {
        nimg = nimg.min(images_seen as f64 * r);
    }
    0.5f64.powf(batch as f64 / nimg.max(MIN_EMA_NIMG))
}

/// Pairs of (EMA variable, source variable) matched by name.
pub struct Ema {
    pairs: Vec<(String, Var, Var)>,
}

impl Ema {
    /// Pairs every variable of `source` whose name starts with `prefix` with the variable of
    /// the same name in `ema`; errors name a missing or mis-shaped one.
    pub fn new(ema: &VarMap, source: &VarMap, prefix: &str) -> Result<Self> {
        let src = source.data().lock().expect("VarMap lock poisoned");
        let dst = ema.data().lock().expect("VarMap lock poisoned");
        let mut pairs = Vec::new();
        for (name, var) in src.iter().filter(|(n, _)| n.starts_with(prefix)) {
            let Some(e) = dst.get(name) else {
                candle_core::bail!("EMA: `{name}` has no EMA copy");
            };
            if e.dims() != var.dims() {
                candle_core::bail!(
                    "EMA: `{name}` has shape {:?}, its EMA copy {:?}",
                    var.dims(),
                    e.dims()
                );
            }
            pairs.push((name.clone(), e.clone(), var.clone()));
        }
        pairs.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(Self { pairs })
    }

    /// One EMA update with decay `beta` (buffers copied).
    pub fn update(&self, beta: f64) -> Result<()> {
        for (name, ema, src) in &self.pairs {
            if is_buffer(name) || beta == 0.0 {
                ema.set(src.as_tensor())?;
            } else {
                let next = ((ema.as_tensor() * beta)? + (src.as_tensor() * (1.0 - beta))?)?;
                ema.set(&next)?;
            }
        }
        Ok(())
    }

    /// Number of paired variables.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    /// Whether no variable is paired.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
    use candle_nn::{Init, VarBuilder};

    fn map(w: f64, avg: f64) -> VarMap {
        let vars = VarMap::new();
        let vb = VarBuilder::from_varmap(&vars, DType::F64, &Device::Cpu);
        vb.get_with_hints(2, "g.fc.weight", Init::Const(w)).unwrap();
        vb.get_with_hints(2, "g.mapping.w_avg", Init::Const(avg))
            .unwrap();
        vars
    }

    fn get(vars: &VarMap, name: &str) -> f64 {
        vars.data().lock().unwrap()[name]
            .as_tensor()
            .to_vec1::<f64>()
            .unwrap()[0]
    }

    #[test]
    fn beta_has_the_requested_half_life_and_ramp() {
        // After ema_nimg / batch steps the old weights keep half their weight.
        let beta = ema_beta(4, 1.25, None, 0);
        assert!((beta.powf(1250.0 / 4.0) - 0.5).abs() < 1e-12);
        // Ramp-up: early on the half-life is 5 % of the images seen; at 0, a plain copy.
        assert_eq!(ema_beta(4, 1.25, Some(0.05), 0), 0.0);
        let early = ema_beta(4, 1.25, Some(0.05), 800);
        assert!((early - 0.5f64.powf(4.0 / 40.0)).abs() < 1e-12);
        assert_eq!(ema_beta(4, 1.25, Some(0.05), 1_000_000), beta);
    }

    #[test]
    fn parameters_are_averaged_and_buffers_copied() {
        let ema = map(1.0, 0.0);
        let src = map(3.0, 7.0);
        let e = Ema::new(&ema, &src, "g.").unwrap();
        assert_eq!(e.len(), 2);
        e.update(0.75).unwrap();
        assert!((get(&ema, "g.fc.weight") - (0.75 + 0.25 * 3.0)).abs() < 1e-12);
        assert_eq!(get(&ema, "g.mapping.w_avg"), 7.0);
        e.update(0.0).unwrap();
        assert_eq!(get(&ema, "g.fc.weight"), 3.0);
        // A missing copy is named.
        let other = VarMap::new();
        let vb = VarBuilder::from_varmap(&other, DType::F64, &Device::Cpu);
        vb.get_with_hints(2, "g.fc.weight", Init::Const(0.0))
            .unwrap();
        let err = Ema::new(&other, &src, "g.").err().unwrap().to_string();
        assert!(err.contains("g.mapping.w_avg"), "{err}");
    }
}
