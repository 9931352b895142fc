//! [`VarMap`] plumbing shared by the trainers: a run's training-state file is one map whose
//! entries are the *live* variables of several others (the networks, the optimisers' moments,
//! counters) under distinct prefixes, so that saving it with
//! [`photomat_core::checkpoint::save_vars_atomic`] writes the whole run and loading into it
//! with [`photomat_core::checkpoint::load_vars_checked`] restores every part at once.
//!
//! The `Var`s are shared, never copied: an entry inserted here is the same tensor storage as
//! the source's.

use std::collections::HashMap;
use std::sync::MutexGuard;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};

/// The map's entries, locked. A lock poisoned by a panic elsewhere is taken over: the map is a
/// plain name → `Var` table that no half-finished operation can leave inconsistent, so there is
/// nothing to refuse (and no reason for a library path to panic).
pub fn lock(map: &VarMap) -> MutexGuard<'_, HashMap<String, Var>> {
    map.data()
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// A builder over detached copies of `map`'s variables (same storage, no gradient tracking),
/// for networks that only run forward: with the weights as variables candle keeps every
/// intermediate of a forward pass alive through the output's graph (a 2048² sample held all
/// of G's full-size activations at once, 22.5 GB); over detached weights each is freed as soon
/// as the next layer has read it.
pub fn frozen_var_builder(map: &VarMap, dtype: DType, device: &Device) -> VarBuilder<'static> {
    let frozen: HashMap<String, Tensor> = lock(map)
        .iter()
        .map(|(name, var)| (name.clone(), var.as_tensor().detach()))
        .collect();
    VarBuilder::from_tensors(frozen, dtype, device)
}

/// The variables of `map` whose names `keep` accepts, with their names, sorted by name (a
/// deterministic order: `VarMap`'s own iteration order is a hash map's).
pub fn sorted_vars(map: &VarMap, keep: impl Fn(&str) -> bool) -> Vec<(String, Var)> {
    let mut named: Vec<(String, Var)> = lock(map)
        .iter()
        .filter(|(name, _)| keep(name))
        .map(|(name, var)| (name.clone(), var.clone()))
        .collect();
    named.sort_by(|a, b| a.0.cmp(&b.0));
    named
}

/// Inserts the variables of `source` whose names start with `from` into `target`, renamed
/// with `to` in place of `from` (`from = ""` prefixes every name with `to`); the `Var`s are
/// shared, not copied. An existing entry of the same name is replaced.
pub fn insert_renamed(target: &VarMap, source: &VarMap, from: &str, to: &str) {
    let src = lock(source);
    let mut dst = lock(target);
    for (name, var) in src.iter().filter(|(n, _)| n.starts_with(from)) {
        dst.insert(format!("{to}{}", &name[from.len()..]), var.clone());
    }
}

/// Inserts one variable under `name` (shared, not copied), replacing an existing entry.
pub fn insert_var(target: &VarMap, name: &str, var: &Var) {
    lock(target).insert(name.to_string(), var.clone());
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor};

    fn var(x: f32) -> Var {
        Var::new(&[x], &Device::Cpu).unwrap()
    }

    #[test]
    fn renamed_entries_share_the_source_variables() {
        let source = VarMap::new();
        insert_var(&source, "g.w", &var(1.0));
        insert_var(&source, "g.b", &var(2.0));
        insert_var(&source, "m.w", &var(3.0));
        let target = VarMap::new();
        insert_renamed(&target, &source, "g.", "g_ema.");
        insert_renamed(&target, &source, "", "all.");
        let names: Vec<String> = sorted_vars(&target, |_| true)
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        assert_eq!(
            names,
            ["all.g.b", "all.g.w", "all.m.w", "g_ema.b", "g_ema.w"]
        );
        // Setting the source's variable is seen through the renamed entry: same storage.
        lock(&source)["g.w"]
            .set(&Tensor::new(&[7f32], &Device::Cpu).unwrap())
            .unwrap();
        let seen = lock(&target)["g_ema.w"]
            .as_tensor()
            .to_vec1::<f32>()
            .unwrap();
        assert_eq!(seen, [7.0]);
    }

    #[test]
    fn sorted_vars_filters_and_sorts() {
        let map = VarMap::new();
        for name in ["c", "a.w_avg", "b", "a"] {
            insert_var(&map, name, &var(0.0));
        }
        let kept: Vec<String> = sorted_vars(&map, |n| !n.ends_with("w_avg"))
            .into_iter()
            .map(|(n, _)| n)
            .collect();
        assert_eq!(kept, ["a", "b", "c"]);
    }
}
