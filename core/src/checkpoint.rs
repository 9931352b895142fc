//! Safetensors checkpoints of a candle [`VarMap`] that refuse another architecture and never
//! leave a half-written file: the one loader and saver of every network's weights (G, M, D,
//! E, optimiser state).
//!
//! [`load_vars_checked`] loads only when every variable is present with the same shape and
//! the file holds no other tensor; otherwise nothing is modified and the error names the file
//! and the first mismatching tensors. [`load_vars_allowing_absent`] does the same but lets a
//! group of variables its caller names be absent all together (left as they are), for a
//! training state saved without its optimiser ([`copy_checkpoint_where`]).
//! [`save_vars_atomic`] writes a temporary file in the same folder and renames it over the
//! target, so a Ctrl-C or a crash mid-save keeps the previous checkpoint intact.

use std::collections::HashMap;
use std::path::Path;

use candle_core::Tensor;
use candle_core::safetensors::MmapedSafetensors;
use candle_nn::VarMap;

use crate::image_io::write_atomic;
use crate::{Error, Result};

/// Most mismatches listed in an error (the count of all of them is given too).
const MAX_LISTED_MISMATCHES: usize = 5;

/// Saves every variable of `vars` to the safetensors file `path` atomically. The file is
/// serialised in memory and written by [`write_atomic`], so it gets the umask's permissions
/// like every other output, and a killed save leaves only a `.NAME.PID-N.tmp` file that the
/// next lock of the folder removes ([`crate::folder_lock`]).
pub fn save_vars_atomic(vars: &VarMap, path: &Path) -> Result<()> {
    let bytes = {
        let data = vars.data().lock().expect("VarMap lock poisoned");
        let tensors: Vec<(&String, Tensor)> = data
            .iter()
            .map(|(name, var)| (name, var.as_tensor().clone()))
            .collect();
        safetensors::tensor::serialize(tensors, None)
            .map_err(|e| Error::file(path, format!("cannot serialise checkpoint: {e}")))?
    };
    write_atomic(path, &bytes)
}

/// Copies the tensors of the safetensors file `from` whose name `keep` accepts into a new
/// file `to` (written atomically), unchanged. Returns how many were left out.
pub fn copy_checkpoint_where(from: &Path, to: &Path, keep: impl Fn(&str) -> bool) -> Result<usize> {
    let bytes = std::fs::read(from)
        .map_err(|e| Error::file(from, format!("cannot read checkpoint: {e}")))?;
    let file = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| Error::file(from, format!("not a safetensors checkpoint: {e}")))?;
    let all = file.tensors();
    let total = all.len();
    let kept: Vec<_> = all.into_iter().filter(|(name, _)| keep(name)).collect();
    let left_out = total - kept.len();
    let out = safetensors::tensor::serialize(kept, None)
        .map_err(|e| Error::file(to, format!("cannot serialise checkpoint: {e}")))?;
    write_atomic(to, &out)?;
    Ok(left_out)
}

/// Loads the safetensors file `path` into the variables of `vars`, which must describe the
/// same architecture: same names, same shapes. Stored values are converted to each
/// variable's dtype (an f64 checkpoint loads into an f32 model).
pub fn load_vars_checked(vars: &VarMap, path: &Path) -> Result<()> {
    load_vars_allowing_absent(vars, path, |_| false).map(|_| ())
}

/// [`load_vars_checked`], except that the variables whose name `optional` accepts form a
/// group the file holds entirely or not at all: when none of them is in the file they keep
/// their values; a file with only part of them is refused like any other mismatch, before
/// anything is loaded. Returns whether the group was absent.
pub fn load_vars_allowing_absent(
    vars: &VarMap,
    path: &Path,
    optional: impl Fn(&str) -> bool,
) -> Result<bool> {
    load_vars_allowing_new(vars, path, optional, |_| false)
}

/// [`load_vars_allowing_absent`], and besides the variables whose name `new` accepts may each be
/// absent from the file, keeping their values: parts added to a model after the file was
/// written (they are not counted in the `optional` group).
pub fn load_vars_allowing_new(
    vars: &VarMap,
    path: &Path,
    optional: impl Fn(&str) -> bool,
    new: impl Fn(&str) -> bool,
) -> Result<bool> {
    let optional = |name: &str| optional(name) && !new(name);
    // SAFETY: the file is mapped read-only for the duration of this call; a checkpoint
    // modified concurrently by another process is outside this API's contract (as for
    // candle's own VarMap::load).
    let file = unsafe { MmapedSafetensors::new(path) }
        .map_err(|e| Error::file(path, format!("cannot read checkpoint: {e}")))?;
    let stored: HashMap<String, Vec<usize>> = file
        .tensors()
        .into_iter()
        .map(|(name, view)| (name, view.shape().to_vec()))
        .collect();
    let data = vars.data().lock().expect("VarMap lock poisoned");
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    let optional_names: Vec<&&String> = names.iter().filter(|n| optional(n)).collect();
    let optional_stored = optional_names
        .iter()
        .filter(|n| stored.contains_key(***n))
        .count();
    let group_absent = !optional_names.is_empty() && optional_stored == 0;
    let mut problems = Vec::new();
    if optional_stored != 0 && optional_stored != optional_names.len() {
        problems.push(format!(
            "holds {optional_stored} of the {} optional tensors; a state holds all of them or \
             none",
            optional_names.len()
        ));
    }
    for name in &names {
        let expected = data[*name].dims();
        match stored.get(*name) {
            // The whole group absent is allowed; a part of it is the problem above.
            None if optional(name) || new(name) => {}
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
        problems.truncate(MAX_LISTED_MISMATCHES);
        return Err(Error::file(
            path,
            format!(
                "checkpoint does not match the model's architecture ({n} mismatches): {}{}",
                problems.join("; "),
                if n > MAX_LISTED_MISMATCHES {
                    "; …"
                } else {
                    ""
                }
            ),
        ));
    }
    for name in names.into_iter().filter(|n| stored.contains_key(*n)) {
        let var = &data[name];
        var.set(&file.load(name, var.device())?.to_dtype(var.dtype())?)?;
    }
    Ok(group_absent)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
    use candle_nn::{Init, VarBuilder};

    fn vars_with(shape: (usize, usize), value: f64) -> VarMap {
        let vars = VarMap::new();
        let vb = VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu);
        vb.get_with_hints(shape, "layer.weight", Init::Const(value))
            .unwrap();
        vars
    }

    #[test]
    fn round_trip_and_mismatch() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.safetensors");
        save_vars_atomic(&vars_with((2, 3), 1.5), &path).unwrap();
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "temporary left"
        );

        let target = vars_with((2, 3), 0.0);
        load_vars_checked(&target, &path).unwrap();
        let v = target.data().lock().unwrap()["layer.weight"]
            .as_tensor()
            .clone();
        assert_eq!(v.sum_all().unwrap().to_scalar::<f32>().unwrap(), 9.0);

        let other = vars_with((3, 3), 0.0);
        let err = load_vars_checked(&other, &path).unwrap_err().to_string();
        assert!(
            err.contains("w.safetensors") && err.contains("layer.weight"),
            "{err}"
        );
        let untouched = other.data().lock().unwrap()["layer.weight"]
            .as_tensor()
            .clone();
        assert_eq!(
            untouched.sum_all().unwrap().to_scalar::<f32>().unwrap(),
            0.0
        );
    }

    #[test]
    fn variables_saved_apart_may_be_absent_only_where_allowed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.safetensors");
        let saved = vars_with((2, 3), 1.5);
        VarBuilder::from_varmap(&saved, DType::F32, &Device::Cpu)
            .get_with_hints(4, "opt.moment", Init::Const(7.0))
            .unwrap();
        let full = dir.path().join("full.safetensors");
        save_vars_atomic(&saved, &full).unwrap();
        let left_out =
            copy_checkpoint_where(&full, &path, |name| !name.starts_with("opt.")).unwrap();
        assert_eq!(left_out, 1);

        let target = vars_with((2, 3), 0.0);
        VarBuilder::from_varmap(&target, DType::F32, &Device::Cpu)
            .get_with_hints(4, "opt.moment", Init::Const(0.0))
            .unwrap();
        // Without permission the absent tensor is an error, and nothing is loaded.
        let err = load_vars_checked(&target, &path).unwrap_err().to_string();
        assert!(err.contains("`opt.moment` [4] is missing"), "{err}");
        let sum = |name: &str| {
            target.data().lock().unwrap()[name]
                .as_tensor()
                .sum_all()
                .unwrap()
                .to_scalar::<f32>()
                .unwrap()
        };
        assert_eq!(sum("layer.weight"), 0.0);
        // With it, the rest loads and the absent one keeps its value.
        let absent =
            load_vars_allowing_absent(&target, &path, |name| name.starts_with("opt.")).unwrap();
        assert!(absent);
        assert_eq!(sum("layer.weight"), 9.0);
        assert_eq!(sum("opt.moment"), 0.0);
    }

    /// Checkpoints get the permissions of any file the user creates (the umask's), not the
    /// 0600 of a `tempfile` temporary.
    #[cfg(unix)]
    #[test]
    fn checkpoint_permissions_follow_the_umask() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.safetensors");
        save_vars_atomic(&vars_with((2, 3), 1.5), &path).unwrap();
        let plain = dir.path().join("plain");
        std::fs::write(&plain, b"x").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&path), mode(&plain));
    }
}
