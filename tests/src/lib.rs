//! Shared helpers of photomat's integration tests (the test files live in `tests/tests/`).
//!
//! This crate is a workspace member because a bare top-level `tests/` folder is never built
//! in a virtual workspace. It names the plugin crate so the registry sees the built-ins; each
//! test file writes `use photomat_tests as _;` (or uses an item from here) for the same reason.
//!
//! Layout of random test cases: N = R×R independent (wi, wo, parameters) cases laid out as an
//! R×R "material" — directions (1, 3, R, R), maps (1, C, R, R) — so that every model, adapters
//! included, is exercised through exactly the tensors the renderer uses.

use candle_core::{DType, Tensor, Var};
use photomat_core::testing;
use photomat_core::{Brdf, MaterialMaps, lookup};
use rand::rngs::StdRng;

pub use photomat_brdfs as brdfs;

pub mod cli_fixtures;

/// The models linked into plain test binaries, sorted (registry guard): the stems of the
/// plugin files `brdf-plugins/src/*.rs` other than the crate root, read from the sources so
/// that the list does not depend on what the linker kept.
pub fn expected_builtins() -> Vec<String> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../brdf-plugins/src");
    photomat_core::testing::plugin_file_stems(&dir).unwrap_or_else(|e| panic!("{e}"))
}

/// Every model configuration the property tests run on: each built-in model and each
/// built-in adapter around the first model it accepts (`photomat_brdfs::builtin_configurations`).
pub fn models_under_test() -> Vec<String> {
    brdfs::builtin_configurations().unwrap_or_else(|e| panic!("{e}"))
}

/// A model by specification; panics with the registry's message (tests only).
pub fn model(spec: &str) -> Brdf {
    lookup(spec).unwrap_or_else(|e| panic!("{e}"))
}

/// Mean |a − b| over every element, in f64 (the two tensors of one shape, any float dtype);
/// panics on a tensor error (tests only).
pub fn mean_abs_difference(a: &Tensor, b: &Tensor) -> f64 {
    let gap = || -> candle_core::Result<f64> {
        (a.to_dtype(DType::F64)? - b.to_dtype(DType::F64)?)?
            .abs()?
            .mean_all()?
            .to_scalar::<f64>()
    };
    gap().unwrap_or_else(|e| panic!("{e}"))
}

/// Panic with the library's message (tests only).
fn ok<T>(r: photomat_core::Result<T>) -> T {
    r.unwrap_or_else(|e| panic!("{e}"))
}

/// Seeded generator for reproducible cases ([`testing::rng`]).
pub fn rng(seed: u64) -> StdRng {
    testing::rng(seed)
}

/// [`testing::random_direction`].
pub fn random_direction(rng: &mut StdRng, min_cos: f64) -> [f64; 3] {
    testing::random_direction(rng, min_cos)
}

/// [`testing::directions`], panicking.
pub fn directions(dirs: &[[f64; 3]], size: usize, dtype: DType) -> Tensor {
    ok(testing::directions(dirs, size, dtype))
}

/// [`testing::random_directions`], panicking.
pub fn random_directions(rng: &mut StdRng, size: usize, min_cos: f64, dtype: DType) -> Tensor {
    ok(testing::random_directions(rng, size, min_cos, dtype))
}

/// [`testing::random_maps`], panicking.
pub fn random_maps(
    brdf: &Brdf,
    rng: &mut StdRng,
    size: usize,
    rough_min: f64,
    dtype: DType,
) -> MaterialMaps {
    ok(testing::random_maps(brdf, rng, size, rough_min, dtype))
}

/// [`testing::values`], panicking.
pub fn values(t: &Tensor) -> Vec<f64> {
    ok(testing::values(t))
}

/// [`testing::as_vars`], panicking.
pub fn as_vars(maps: &MaterialMaps) -> (MaterialMaps, Vec<(String, Var)>) {
    ok(testing::as_vars(maps))
}

/// [`testing::gradients`], panicking.
pub fn gradients(loss: &Tensor, vars: &[(String, Var)]) -> Vec<(String, Vec<f64>)> {
    ok(testing::gradients(loss, vars))
}

/// [`testing::perturbed`], panicking.
pub fn perturbed(maps: &MaterialMaps, name: &str, index: usize, delta: f64) -> MaterialMaps {
    ok(testing::perturbed(maps, name, index, delta))
}
