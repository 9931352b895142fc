//! Helpers shared by the integration tests.

use candle_core::{DType, Result};
use candle_nn::VarMap;
use photomat_generator::seeded_uniform;

/// Makes a freshly initialised model deterministic: candle's CPU generator cannot be seeded,
/// so every randomly initialised variable (values not all equal) is replaced by seeded
/// zero-mean, unit-variance values times `std_of(name)` (its initial standard deviation: 1 for
/// equalised weights and the constant input, 1/λ for layers with lr multiplier λ).
/// Constant-initialised variables (biases, noise strengths, w_avg) are kept. Variables are
/// visited in name order, each with its own seed.
pub fn reseed(vars: &VarMap, seed: u64, std_of: impl Fn(&str) -> f64) -> Result<()> {
    let data = vars.data().lock().expect("VarMap lock");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    for (k, name) in names.into_iter().enumerate() {
        let var = &data[name];
        let t = var.as_tensor().to_dtype(DType::F64)?;
        let spread = (t.max_all()? - t.min_all()?)?.to_scalar::<f64>()?;
        if spread > 0.0 {
            let fresh = seeded_uniform(t.shape(), seed * 1000 + k as u64, DType::F64, t.device())?;
            var.set(&fresh.affine(std_of(name), 0.0)?.to_dtype(var.dtype())?)?;
        }
    }
    Ok(())
}
