//! Parameter store helpers: safetensors checkpoints of a [`VarMap`] with architecture checks,
//! parameter counts and the trainable subset.
//!
//! A checkpoint is candle's VarMap safetensors file (one tensor per parameter name, names the
//! `vb.pp(..)` paths of the modules). [`load_checkpoint`] refuses a file of another
//! architecture instead of silently loading part of it: every variable must be present with
//! the same shape and the file must hold no other tensor; the error names the first
//! mismatching tensors and their shapes.

use std::path::Path;

use candle_core::safetensors::MmapedSafetensors;
use candle_core::{Result, Var, bail};
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

/// Saves every variable of `vars` to a safetensors file.
pub fn save_checkpoint(vars: &VarMap, path: impl AsRef<Path>) -> Result<()> {
    vars.save(path)
}

/// Loads a checkpoint into the variables of `vars`, which must describe the same
/// architecture: same names, same shapes. Nothing is modified when the check fails. Stored
/// values are converted to each variable's dtype (an f64 checkpoint loads into an f32 model).
pub fn load_checkpoint(vars: &VarMap, path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    // SAFETY: the file is mapped read-only for the duration of this call; a checkpoint
    // modified concurrently by another process is outside this API's contract (as for
    // candle's own VarMap::load).
    let file = unsafe { MmapedSafetensors::new(path)? };
    let stored: std::collections::HashMap<String, Vec<usize>> = file
        .tensors()
        .into_iter()
        .map(|(name, view)| (name, view.shape().to_vec()))
        .collect();
    let data = vars.data().lock().expect("VarMap lock poisoned");
    let mut problems = Vec::new();
    let mut names: Vec<_> = data.keys().collect();
    names.sort();
    for name in &names {
        let expected = data[*name].dims();
        match stored.get(*name) {
            None => problems.push(format!("tensor `{name}` {expected:?} is missing")),
            Some(shape) if shape.as_slice() != expected => problems.push(format!(
                "tensor `{name}` has shape {shape:?} in the checkpoint, the model expects {expected:?}"
            )),
            Some(_) => {}
        }
    }
    let mut extra: Vec<_> = stored.keys().filter(|n| !data.contains_key(*n)).collect();
    extra.sort();
    for name in extra {
        problems.push(format!("unexpected tensor `{name}` {:?}", stored[name]));
    }
    if !problems.is_empty() {
        let n = problems.len();
        problems.truncate(5);
        bail!(
            "checkpoint {} does not match the model's architecture ({n} mismatches): {}{}",
            path.display(),
            problems.join("; "),
            if n > 5 { "; …" } else { "" }
        );
    }
    for name in names {
        let var = &data[name];
        var.set(&file.load(name, var.device())?.to_dtype(var.dtype())?)?;
    }
    Ok(())
}
