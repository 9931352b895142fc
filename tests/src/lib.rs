//! Shared helpers of photomat's integration tests (the test files live in `tests/tests/`).
//!
//! This crate is a workspace member because a bare top-level `tests/` folder is never built
//! in a virtual workspace. It names the plugin crate so the registry sees the built-ins; each
//! test file writes `use photomat_tests as _;` (or uses an item from here) for the same reason.
//!
//! Layout of random test cases: N = R×R independent (wi, wo, parameters) cases laid out as an
//! R×R "material" — directions (1, 3, R, R), maps (1, C, R, R) — so that every model, adapters
//! included, is exercised through exactly the tensors the renderer uses.

use candle_core::{DType, Device, Tensor, Var};
use photomat_core::{Brdf, Encoding, MaterialMaps, lookup};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

pub use photomat_brdfs as brdfs;

pub mod cli_fixtures;

/// The models linked into plain test binaries, sorted (registry guard).
pub const EXPECTED_BUILTINS: &[&str] = &["coated", "ggx", "height", "lambert"];

/// Every model configuration the property tests run on.
pub const MODELS_UNDER_TEST: &[&str] = &["lambert", "ggx", "coated", "height(ggx)"];

/// A model by specification; panics with the registry's message (tests only).
pub fn model(spec: &str) -> Brdf {
    lookup(spec).unwrap_or_else(|e| panic!("{e}"))
}

/// Seeded generator for reproducible cases.
pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// A unit direction with `z ≥ min_cos`, uniform in solid angle over that cap.
pub fn random_direction(rng: &mut StdRng, min_cos: f64) -> [f64; 3] {
    let z: f64 = rng.random_range(min_cos..1.0);
    let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let s = (1.0 - z * z).max(0.0).sqrt();
    [s * phi.cos(), s * phi.sin(), z]
}

/// (1, 3, R, R) tensor of per-texel directions, row-major over the R×R grid.
pub fn directions(dirs: &[[f64; 3]], size: usize, dtype: DType) -> Tensor {
    assert_eq!(dirs.len(), size * size);
    let mut data = vec![0f64; 3 * size * size];
    for (t, d) in dirs.iter().enumerate() {
        for c in 0..3 {
            data[c * size * size + t] = d[c];
        }
    }
    Tensor::from_vec(data, (1, 3, size, size), &Device::Cpu)
        .and_then(|t| t.to_dtype(dtype))
        .unwrap()
}

/// `size²` random directions with `z ≥ min_cos`, as a (1, 3, R, R) tensor.
pub fn random_directions(rng: &mut StdRng, size: usize, min_cos: f64, dtype: DType) -> Tensor {
    let dirs: Vec<_> = (0..size * size)
        .map(|_| random_direction(rng, min_cos))
        .collect();
    directions(&dirs, size, dtype)
}

/// Random maps for `brdf` of size R×R: every channel uniform over its range, except
/// roughness-like linear scalars drawn from `[rough_min, 1]` and normals tilted by at most
/// ≈ 27° (x, y ∈ [−½, ½], z = 1) so that cases with directions of `z ≥ ½` stay above the
/// shading horizon. Heights use the full [0, 1] range.
pub fn random_maps(
    brdf: &Brdf,
    rng: &mut StdRng,
    size: usize,
    rough_min: f64,
    dtype: DType,
) -> MaterialMaps {
    let mut maps = MaterialMaps::new();
    for spec in brdf.params() {
        let n = spec.channels * size * size;
        let data: Vec<f64> = match spec.encoding {
            Encoding::UnitNormal => (0..n)
                .map(|i| {
                    if i / (size * size) == 2 {
                        1.0
                    } else {
                        rng.random_range(-0.5..0.5)
                    }
                })
                .collect(),
            _ if spec.name.starts_with("roughness") => {
                (0..n).map(|_| rng.random_range(rough_min..=1.0)).collect()
            }
            _ => {
                let (lo, hi) = (spec.range.0 as f64, spec.range.1 as f64);
                (0..n).map(|_| rng.random_range(lo..=hi)).collect()
            }
        };
        let t = Tensor::from_vec(data, (1, spec.channels, size, size), &Device::Cpu)
            .and_then(|t| t.to_dtype(dtype))
            .unwrap();
        maps.insert(spec.name, t);
    }
    maps
}

/// Flattened values of any tensor as f64.
pub fn values(t: &Tensor) -> Vec<f64> {
    t.to_dtype(DType::F64)
        .and_then(|t| t.flatten_all())
        .and_then(|t| t.to_vec1::<f64>())
        .unwrap()
}

/// Wrap every map in a [`Var`] so that gradients can be taken w.r.t. it.
pub fn as_vars(maps: &MaterialMaps) -> (MaterialMaps, Vec<(String, Var)>) {
    let mut out = MaterialMaps::new();
    let mut vars = Vec::new();
    for (name, t) in maps.iter() {
        let var = Var::from_tensor(t).unwrap();
        out.insert(name, var.as_tensor().clone());
        vars.push((name.to_string(), var));
    }
    (out, vars)
}

/// Gradient of scalar `loss` w.r.t. every var, as flattened f64 vectors, by name.
pub fn gradients(loss: &Tensor, vars: &[(String, Var)]) -> Vec<(String, Vec<f64>)> {
    let grads = loss.backward().unwrap();
    vars.iter()
        .map(|(name, var)| {
            let g = grads
                .get(var.as_tensor())
                .map(values)
                .unwrap_or_else(|| vec![0.0; var.as_tensor().elem_count()]);
            (name.clone(), g)
        })
        .collect()
}

/// Copy of `maps` with element `index` (flattened) of map `name` shifted by `delta`.
pub fn perturbed(maps: &MaterialMaps, name: &str, index: usize, delta: f64) -> MaterialMaps {
    let mut out = maps.clone();
    let t = maps.get(name).unwrap();
    let mut v = values(t);
    v[index] += delta;
    let shifted = Tensor::from_vec(v, t.dims(), t.device())
        .and_then(|s| s.to_dtype(t.dtype()))
        .unwrap();
    out.insert(name, shifted);
    out
}
