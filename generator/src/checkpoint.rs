//! Parameter store helpers: safetensors checkpoints of a [`VarMap`] with architecture checks,
//! parameter counts and the trainable subset.
//!
//! A checkpoint is candle's VarMap safetensors file (one tensor per parameter name, names the
//! `vb.pp(..)` paths of the modules), saved and loaded by `photomat_core::checkpoint`:
//! atomic writes, and loads that refuse a file of another architecture naming the first
//! mismatching tensors and their shapes.

use std::path::Path;

use candle_core::{Result, Var};
use candle_nn::VarMap;

/// Suffix of the names of non-trainable buffers (the mapping's tracked w average).
const BUFFER_SUFFIXES: [&str; 1] = ["w_avg"];

/// Whether the variable `name` is a buffer updated outside the optimiser.
pub fn is_buffer(name: &str) -> bool {
    BUFFER_SUFFIXES
        .iter()
        .any(|s| name == *s || name.ends_with(&format!(".{s}")))
}

/// The variables an optimiser should update (all but buffers), sorted by name.
pub fn trainable_vars(vars: &VarMap) -> Vec<Var> {
    let data = vars.data().lock().expect("VarMap lock poisoned");
    let mut named: Vec<_> = data.iter().filter(|(n, _)| !is_buffer(n)).collect();
    named.sort_by(|a, b| a.0.cmp(b.0));
    named.into_iter().map(|(_, v)| v.clone()).collect()
}

/// Number of scalars in the map, with or without buffers.
pub fn parameter_count(vars: &VarMap, include_buffers: bool) -> usize {
    let data = vars.data().lock().expect("VarMap lock poisoned");
    data.iter()
        .filter(|(n, _)| include_buffers || !is_buffer(n))
        .map(|(_, v)| v.elem_count())
        .sum()
}

/// Saves every variable of `vars` to a safetensors file, atomically
/// ([`photomat_core::checkpoint::save_vars_atomic`]).
pub fn save_checkpoint(vars: &VarMap, path: impl AsRef<Path>) -> Result<()> {
    photomat_core::checkpoint::save_vars_atomic(vars, path.as_ref())
        .map_err(candle_core::Error::wrap)
}

/// Loads a checkpoint into the variables of `vars`, which must describe the same
/// architecture: same names, same shapes; nothing is modified when the check fails and the
/// error names the mismatching tensors ([`photomat_core::checkpoint::load_vars_checked`]).
pub fn load_checkpoint(vars: &VarMap, path: impl AsRef<Path>) -> Result<()> {
    photomat_core::checkpoint::load_vars_checked(vars, path.as_ref())
        .map_err(candle_core::Error::wrap)
}
