//! The conformance kit: the properties every BRDF plugin must have, checked by name.
//!
//! `check_model("my_model")` runs every check below on a registered model or adapter
//! configuration; the built-ins' tests and the custom-BRDF example call it, and so can any
//! user crate's tests (the plugin crate must be linked: `use my_plugins as _;`). The checks
//! follow Mitsuba 3's plugin tests and pbrt-v4's BxDF tests, and the conventions of
//! `docs/conventions.md` (`eval` returns `f·cos θ_o`, exactly 0 below the horizon):
//!
//! | check                           | inputs                                   | property                          |
//! |---------------------------------|------------------------------------------|-----------------------------------|
//! | [`check_finite_at_extremes`]    | f32, 10 000 cases of 16 texels: range ends, grazing, below-horizon and opposite directions, zero and near-tangent normals, far flashes | values finite and ≥ 0, gradients finite, through `eval` and the renderer |
//! | [`check_non_negative`]          | f64, directions over the whole sphere    | `eval ≥ 0`, finite                |
//! | [`check_zero_below_horizon`]    | f64, either or both directions below the shading normal's horizon | value and gradient exactly 0 |
//! | [`check_reciprocity`]           | f64, directions with cos θ ≥ ½           | `f(wi, wo) = f(wo, wi)`           |
//! | [`check_eval_gradients`], [`check_render_gradients`] | f64, 4×4 random maps | autodiff = central differences, non-zero for every map |
//! | [`check_map_files_round_trip`]  | f32 16×16 random maps                    | EXR exact, PNG within quantisation |
//!
//! Random maps ([`random_maps`]) draw every channel uniformly over its spec range, except
//! maps named `roughness*` (drawn from `[rough_min, 1]`) and unit normals (tilted by at most
//! ≈ 27° so that directions with cos θ ≥ ½ stay above the shading horizon). Every case is
//! seeded, so a failure reproduces.
//!
//! Every check returns [`Error::Invalid`] naming the model, the property, the map and the
//! case on the first violation, so a test is `check_model("ggx")` with `-> Result<()>` or
//! `.unwrap()`.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use candle_core::{DType, Device, Tensor, Var};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::map_files::{MANIFEST_FILE, PngBits, SaveOptions, load_maps, save_maps};
use crate::vecops::{constant3, dot3, normalize3};
use crate::{
    Brdf, ColorSpace, Encoding, Error, Highlight, MaterialMaps, Result, encode_display, lookup,
    render_radiance,
};

/// Cases of [`check_finite_at_extremes`], each covering [`EXTREME_SIZE`]² texels.
pub const EXTREME_CASES: u32 = 10_000;
/// Side of one extreme case's texel grid.
pub const EXTREME_SIZE: usize = 4;
/// Side of the random grids of the non-negativity, horizon and reciprocity checks
/// (256 cases per property).
pub const PROPERTY_SIZE: usize = 16;
/// Side of the gradient checks' grids (16 texels: each map element is differentiated twice).
pub const GRADIENT_SIZE: usize = 4;
/// Central-difference step: truncation error ~h² ≈ 1e-12, rounding ~ε/h ≈ 1e-10 in f64.
pub const FD_STEP: f64 = 1e-6;
/// Agreement required between analytic and numerical gradients (relative to max(1, |g|)).
pub const FD_TOLERANCE: f64 = 1e-6;
/// Side of the maps of [`check_map_files_round_trip`].
pub const ROUND_TRIP_SIZE: usize = 16;

/// Fail with `Error::Invalid(format!(…))` unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $($msg:tt)+) => {
        // A NaN comparison is false, so it fails the check as it should.
        let holds: bool = $cond;
        if !holds {
            return Err(Error::Invalid(format!($($msg)+)));
        }
    };
}

/// Every check of this module on the model built from `spec` (`ggx`, `height(ggx)`).
pub fn check_model(spec: &str) -> Result<()> {
    check_finite_at_extremes(spec)?;
    check_non_negative(spec)?;
    check_zero_below_horizon(spec)?;
    check_reciprocity(spec)?;
    check_eval_gradients(spec)?;
    check_render_gradients(spec)?;
    check_map_files_round_trip(spec)
}

/// Every model registered by the crates named (as `module_path!()` spells them), each of its
/// variants (every non-default word of every choice argument, one argument at a time), and
/// every adapter among them wrapped around the first of those models it accepts: the
/// configurations a plugin crate's tests run (`["coated", "ggx",
/// "ggx(shadowing=correlated)", …, "lambert", "height(ggx)"]` for the built-ins).
pub fn configurations(crates: &[&str]) -> Result<Vec<String>> {
    let regs: Vec<_> = crate::registrations()?
        .into_iter()
        .filter(|r| crates.contains(&r.crate_name()))
        .collect();
    let models: Vec<String> = regs
        .iter()
        .filter(|r| !r.takes_nested)
        .map(|r| r.name.to_string())
        .collect();
    let mut out = Vec::new();
    for reg in regs.iter().filter(|r| !r.takes_nested) {
        out.push(reg.name.to_string());
        for arg in reg.args {
            if let crate::registry::ArgKind::Choice { words } = arg.kind {
                out.extend(
                    words[1..]
                        .iter()
                        .map(|w| format!("{}({}={w})", reg.name, arg.name)),
                );
            }
        }
    }
    for adapter in regs.iter().filter(|r| r.takes_nested) {
        let wrapped = models
            .iter()
            .map(|m| format!("{}({m})", adapter.name))
            .find(|spec| lookup(spec).is_ok())
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "adapter '{}' accepts none of the models {models:?}",
                    adapter.name
                ))
            })?;
        out.push(wrapped);
    }
    Ok(out)
}

/// Stems of the plugin files in the source folder `dir`: every `*.rs` file but the crate root
/// `lib.rs`, sorted. One file per model and file stem = registered name make this the list a
/// plugin crate's registrations must equal.
pub fn plugin_file_stems(dir: &Path) -> Result<Vec<String>> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| Error::Invalid(format!("cannot list '{}': {e}", dir.display())))?;
    let mut stems = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|e| Error::Invalid(format!("cannot list '{}': {e}", dir.display())))?
            .path();
        let stem = path.file_stem().and_then(|s| s.to_str());
        if let Some(stem) = stem.filter(|_| path.extension().is_some_and(|x| x == "rs"))
            && stem != "lib"
        {
            stems.push(stem.to_string());
        }
    }
    stems.sort();
    Ok(stems)
}

/// Checks that every plugin the crate `crate_name` registers (as `module_path!()` spells it)
/// was declared in a file whose stem is its registered name.
pub fn check_file_stems(crate_name: &str) -> Result<()> {
    for r in crate::registrations_from(crate_name)? {
        ensure!(
            r.file_stem() == Some(r.name),
            "'{}' is registered in {}: the file stem must be the registered name",
            r.name,
            r.file
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Random cases
// ---------------------------------------------------------------------------------------

/// Seeded generator for reproducible cases.
pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// A unit direction with `z ≥ min_cos`, uniform in solid angle over that cap.
pub fn random_direction(rng: &mut StdRng, min_cos: f64) -> [f64; 3] {
    let z: f64 = rng.random_range(min_cos..1.0);
    let phi: f64 = rng.random_range(0.0..TAU);
    let s = (1.0 - z * z).max(0.0).sqrt();
    [s * phi.cos(), s * phi.sin(), z]
}

/// Per-texel vectors as a (1, 3, R, R) tensor, row-major over the R×R grid.
pub fn directions(dirs: &[[f64; 3]], size: usize, dtype: DType) -> Result<Tensor> {
    if dirs.len() != size * size {
        return Err(Error::Invalid(format!(
            "{} directions do not fill a {size}×{size} grid",
            dirs.len()
        )));
    }
    let mut data = vec![0f64; 3 * size * size];
    for (t, d) in dirs.iter().enumerate() {
        for c in 0..3 {
            data[c * size * size + t] = d[c];
        }
    }
    Ok(Tensor::from_vec(data, (1, 3, size, size), &Device::Cpu)?.to_dtype(dtype)?)
}

/// `size²` random directions with `z ≥ min_cos`, as a (1, 3, R, R) tensor.
pub fn random_directions(
    rng: &mut StdRng,
    size: usize,
    min_cos: f64,
    dtype: DType,
) -> Result<Tensor> {
    let dirs: Vec<_> = (0..size * size)
        .map(|_| random_direction(rng, min_cos))
        .collect();
    directions(&dirs, size, dtype)
}

/// Random (1, C, R, R) maps for `brdf`: every channel uniform over its range, except
/// roughness-like linear scalars (`roughness*`) drawn from `[rough_min, 1]` and unit normals
/// tilted by at most ≈ 27° (x, y ∈ [−½, ½], z = 1, unnormalised) so that cases with
/// directions of `z ≥ ½` stay above the shading horizon. Heights use the full [0, 1] range.
pub fn random_maps(
    brdf: &Brdf,
    rng: &mut StdRng,
    size: usize,
    rough_min: f64,
    dtype: DType,
) -> Result<MaterialMaps> {
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
        let t = Tensor::from_vec(data, (1, spec.channels, size, size), &Device::Cpu)?
            .to_dtype(dtype)?;
        maps.insert(spec.name, t);
    }
    Ok(maps)
}

/// Flattened values of any tensor as f64.
pub fn values(t: &Tensor) -> Result<Vec<f64>> {
    Ok(t.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()?)
}

/// Every map wrapped in a [`Var`] so that gradients can be taken w.r.t. it.
pub fn as_vars(maps: &MaterialMaps) -> Result<(MaterialMaps, Vec<(String, Var)>)> {
    let mut out = MaterialMaps::new();
    let mut vars = Vec::new();
    for (name, t) in maps.iter() {
        let var = Var::from_tensor(t)?;
        out.insert(name, var.as_tensor().clone());
        vars.push((name.to_string(), var));
    }
    Ok((out, vars))
}

/// Gradient of scalar `loss` w.r.t. every var, as flattened f64 vectors, by name (zeros for a
/// var no gradient reaches).
pub fn gradients(loss: &Tensor, vars: &[(String, Var)]) -> Result<Vec<(String, Vec<f64>)>> {
    let grads = loss.backward()?;
    vars.iter()
        .map(|(name, var)| {
            let g = match grads.get(var.as_tensor()) {
                Some(g) => values(g)?,
                None => vec![0.0; var.as_tensor().elem_count()],
            };
            Ok((name.clone(), g))
        })
        .collect()
}

/// Copy of `maps` with element `index` (flattened) of map `name` shifted by `delta`.
pub fn perturbed(
    maps: &MaterialMaps,
    name: &str,
    index: usize,
    delta: f64,
) -> Result<MaterialMaps> {
    let t = maps.get(name)?;
    let mut v = values(t)?;
    let slot = v
        .get_mut(index)
        .ok_or_else(|| Error::Invalid(format!("map '{name}' has no element {index}")))?;
    *slot += delta;
    let shifted = Tensor::from_vec(v, t.dims(), t.device())?.to_dtype(t.dtype())?;
    Ok(maps.clone().with(name, shifted))
}

/// A model by specification.
fn model(spec: &str) -> Result<Brdf> {
    lookup(spec)
}

// ---------------------------------------------------------------------------------------
// Extreme inputs
// ---------------------------------------------------------------------------------------

/// A value in [0, 1] biased towards the ends and the α-floor region of roughness.
fn extreme_unit(r: &mut StdRng) -> f64 {
    match r.random_range(0..6) {
        0 => 0.0,
        1 => 1.0,
        2 => 1e-4,
        3 => 1e-2,
        4 => 1.0 - 1e-7,
        _ => r.random_range(0.0..=1.0),
    }
}

/// A cosine biased towards grazing: exactly tangent, 1e-6, 1e-7, just below the horizon.
fn extreme_cosine(r: &mut StdRng) -> f64 {
    match r.random_range(0..7) {
        0 => 0.0,
        1 => 1e-6,
        2 => 1e-7,
        3 => -1e-6,
        4 => 1.0,
        5 => r.random_range(-1.0..=1.0),
        _ => r.random_range(1e-6..1e-3),
    }
}

fn extreme_direction(r: &mut StdRng) -> [f64; 3] {
    let z = extreme_cosine(r);
    let phi: f64 = r.random_range(0.0..TAU);
    let s = (1.0 - z * z).max(0.0).sqrt();
    [s * phi.cos(), s * phi.sin(), z]
}

/// Normals including near-tangent ones and the zero vector (degenerate input).
fn extreme_normal(r: &mut StdRng) -> [f64; 3] {
    match r.random_range(0..4) {
        0 => [0.0, 0.0, 0.0],
        1 => [0.0, 0.0, 1.0],
        2 => extreme_direction(r),
        _ => {
            let phi: f64 = r.random_range(0.0..TAU);
            let z = if r.random_bool(0.5) { 1e-6 } else { 1e-3 };
            [phi.cos(), phi.sin(), z]
        }
    }
}

/// f32 maps for `brdf` on an R×R grid: unit normals from [`extreme_normal`], every other
/// channel the spec's range scaled by [`extreme_unit`].
fn extreme_maps(brdf: &Brdf, r: &mut StdRng, size: usize) -> Result<MaterialMaps> {
    let mut maps = MaterialMaps::new();
    for spec in brdf.params() {
        let t = if spec.encoding == Encoding::UnitNormal && spec.channels == 3 {
            let normals: Vec<_> = (0..size * size).map(|_| extreme_normal(r)).collect();
            directions(&normals, size, DType::F32)?
        } else {
            let (lo, hi) = (spec.range.0 as f64, spec.range.1 as f64);
            let data: Vec<f64> = (0..spec.channels * size * size)
                .map(|_| lo + (hi - lo) * extreme_unit(r))
                .collect();
            Tensor::from_vec(data, (1, spec.channels, size, size), &Device::Cpu)?
                .to_dtype(DType::F32)?
        };
        maps.insert(spec.name, t);
    }
    Ok(maps)
}

/// `eval(maps)` is finite and non-negative, and its sum has finite gradients w.r.t. every map.
pub fn check_finite_with_gradients(
    label: &str,
    maps: &MaterialMaps,
    eval: impl Fn(&MaterialMaps) -> Result<Tensor>,
) -> Result<()> {
    let (var_maps, vars) = as_vars(maps)?;
    let out = eval(&var_maps)?;
    let v = values(&out)?;
    ensure!(
        v.iter().all(|x| x.is_finite() && *x >= 0.0),
        "{label}: value not finite or negative: {v:?}"
    );
    for (name, g) in gradients(&out.sum_all()?, &vars)? {
        ensure!(
            g.iter().all(|x| x.is_finite()),
            "{label}: gradient w.r.t. {name} not finite: {g:?}"
        );
    }
    Ok(())
}

/// [`EXTREME_CASES`] seeded cases in f32, the production dtype: range ends and the α-floor
/// region for every map, grazing directions (cos θ = 1e-6, 1e-7, 0, just below 0), one
/// exactly opposite pair, zero and near-tangent normals, flashes up to two plane widths away. Through `eval` and through the
/// display-encoded render, values must be finite and non-negative and gradients finite.
pub fn check_finite_at_extremes(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let mut r = rng(0x0e47_7e3e);
    for case in 0..EXTREME_CASES {
        let maps = extreme_maps(&brdf, &mut r, EXTREME_SIZE)?;
        let dirs = |r: &mut StdRng| -> Vec<[f64; 3]> {
            (0..EXTREME_SIZE * EXTREME_SIZE)
                .map(|_| extreme_direction(r))
                .collect()
        };
        let wi_dirs = dirs(&mut r);
        let mut wo_dirs = dirs(&mut r);
        // One exactly opposite pair per case: the half vector wi + wo is zero there.
        wo_dirs[0] = wi_dirs[0].map(|x| -x);
        let wi = directions(&wi_dirs, EXTREME_SIZE, DType::F32)?;
        let wo = directions(&wo_dirs, EXTREME_SIZE, DType::F32)?;
        let light = [Highlight::new(
            r.random_range(-2.0..2.0),
            r.random_range(-2.0..2.0),
        )];
        check_finite_with_gradients(&format!("{spec} eval, extreme case {case}"), &maps, |m| {
            brdf.eval(&wi, &wo, m)
        })?;
        check_finite_with_gradients(
            &format!("{spec} render, extreme case {case} (flash {light:?})"),
            &maps,
            |m| encode_display(&render_radiance(brdf.as_ref(), m, &light)?),
        )?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Physical properties
// ---------------------------------------------------------------------------------------

/// Values are ≥ 0 and finite for directions over the whole sphere (below-horizon pairs give 0,
/// never a negative value).
pub fn check_non_negative(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let mut r = rng(2);
    let maps = random_maps(&brdf, &mut r, PROPERTY_SIZE, 0.0, DType::F64)?;
    let wi = random_directions(&mut r, PROPERTY_SIZE, -1.0, DType::F64)?;
    let wo = random_directions(&mut r, PROPERTY_SIZE, -1.0, DType::F64)?;
    for (k, v) in values(&brdf.eval(&wi, &wo, &maps)?)?
        .into_iter()
        .enumerate()
    {
        ensure!(
            v >= 0.0 && v.is_finite(),
            "{spec}: case {k} evaluates to {v}"
        );
    }
    Ok(())
}

/// With either or both directions below the shading horizon, values *and* gradients are
/// exactly 0 (no 0·∞ NaN from a masked branch). The horizon is the model's own shading normal
/// ([`crate::DifferentiableBrdf::shading_maps`]; +z without one): an adapter's derived
/// normals may tilt a direction below the plane above it, and such texels are skipped.
pub fn check_zero_below_horizon(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let mut r = rng(3);
    let maps = random_maps(&brdf, &mut r, PROPERTY_SIZE, 0.0, DType::F64)?;
    let above = random_directions(&mut r, PROPERTY_SIZE, 0.5, DType::F64)?;
    let below = (random_directions(&mut r, PROPERTY_SIZE, 0.5, DType::F64)? * -1.0)?;
    let n = shading_normal(&brdf, &maps, &above)?;
    let plane = PROPERTY_SIZE * PROPERTY_SIZE;
    for (what, wi, wo) in [
        ("wo below", &above, &below),
        ("wi below", &below, &above),
        ("both below", &below, &below),
    ] {
        let (ci, co) = (values(&dot3(&n, wi)?)?, values(&dot3(&n, wo)?)?);
        let masked: Vec<f64> = (0..plane)
            .map(|t| f64::from(u8::from(ci[t] <= 0.0 || co[t] <= 0.0)))
            .collect();
        let count = masked.iter().filter(|m| **m > 0.0).count();
        ensure!(
            2 * count > plane,
            "{spec}: only {count} of {plane} cases are below the shading horizon ({what})"
        );
        let mask = Tensor::from_vec(
            masked.clone(),
            (1, 1, PROPERTY_SIZE, PROPERTY_SIZE),
            &Device::Cpu,
        )?;
        let (var_maps, vars) = as_vars(&maps)?;
        let out = brdf.eval(wi, wo, &var_maps)?;
        for (k, v) in values(&out)?.iter().enumerate() {
            ensure!(
                masked[k % plane] == 0.0 || *v == 0.0,
                "{spec}: case {} is below the horizon ({what}) but evaluates to {v}",
                k % plane
            );
        }
        let loss = out.broadcast_mul(&mask)?.sum_all()?;
        for (name, g) in gradients(&loss, &vars)? {
            ensure!(
                g.iter().all(|v| *v == 0.0),
                "{spec}: gradient w.r.t. {name} not zero below the horizon ({what})"
            );
        }
    }
    Ok(())
}

/// The unit shading normal of `maps` under `brdf` (+z, shaped like `like`, for a model
/// without a normal map).
fn shading_normal(brdf: &Brdf, maps: &MaterialMaps, like: &Tensor) -> Result<Tensor> {
    let shading = brdf.shading_maps(maps)?;
    match shading.get("normal") {
        Ok(n) => normalize3(n),
        Err(_) => constant3([0.0, 0.0, 1.0], like),
    }
}

/// `f(wi, wo) = f(wo, wi)` to 1e-9 relative, with `f = eval / cos θ_o` about the model's own
/// shading normal ([`crate::DifferentiableBrdf::shading_maps`]; +z for a model without one).
pub fn check_reciprocity(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let mut r = rng(1);
    let maps = random_maps(&brdf, &mut r, PROPERTY_SIZE, 0.05, DType::F64)?;
    let wi = random_directions(&mut r, PROPERTY_SIZE, 0.5, DType::F64)?;
    let wo = random_directions(&mut r, PROPERTY_SIZE, 0.5, DType::F64)?;
    let n = shading_normal(&brdf, &maps, &wi)?;
    let ci = values(&dot3(&n, &wi)?)?;
    let co = values(&dot3(&n, &wo)?)?;
    let f_io = values(&brdf.eval(&wi, &wo, &maps)?)?;
    let f_oi = values(&brdf.eval(&wo, &wi, &maps)?)?;
    let plane = PROPERTY_SIZE * PROPERTY_SIZE;
    for (k, (a, b)) in f_io.iter().zip(&f_oi).enumerate() {
        let t = k % plane;
        let (fa, fb) = (a / co[t], b / ci[t]);
        ensure!(
            (fa - fb).abs() <= 1e-9 * fa.abs().max(1.0),
            "{spec} case {t}: f(wi,wo) = {fa}, f(wo,wi) = {fb}"
        );
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Gradients
// ---------------------------------------------------------------------------------------

/// Autodiff gradients of the scalar `loss(maps)` w.r.t. every map equal central finite
/// differences ([`FD_STEP`], [`FD_TOLERANCE`]) element by element, and no map's gradient is
/// identically zero. Use f64 maps.
pub fn check_against_finite_differences(
    label: &str,
    maps: &MaterialMaps,
    loss: impl Fn(&MaterialMaps) -> Result<Tensor>,
) -> Result<()> {
    let (var_maps, vars) = as_vars(maps)?;
    let analytic = gradients(&loss(&var_maps)?, &vars)?;
    let scalar =
        |m: &MaterialMaps| -> Result<f64> { Ok(loss(m)?.to_dtype(DType::F64)?.to_scalar()?) };
    for (name, grad) in analytic {
        let mut nonzero = 0;
        for (i, g) in grad.iter().enumerate() {
            let up = scalar(&perturbed(maps, &name, i, FD_STEP)?)?;
            let down = scalar(&perturbed(maps, &name, i, -FD_STEP)?)?;
            let numeric = (up - down) / (2.0 * FD_STEP);
            ensure!(
                (g - numeric).abs() <= FD_TOLERANCE * g.abs().max(1.0),
                "{label}: d/d{name}[{i}] analytic {g} vs finite difference {numeric}"
            );
            nonzero += usize::from(g.abs() > 1e-9);
        }
        ensure!(
            nonzero > 0,
            "{label}: gradient w.r.t. {name} is identically zero"
        );
    }
    Ok(())
}

/// (1, 3, R, R) f64 weights in [0.5, 1.5] with R = [`GRADIENT_SIZE`]: a loss `Σ W·x` that
/// weighs every output differently.
pub fn weights(seed: u64) -> Result<Tensor> {
    let mut r = rng(seed);
    let w: Vec<f64> = (0..3 * GRADIENT_SIZE * GRADIENT_SIZE)
        .map(|_| r.random_range(0.5..1.5))
        .collect();
    Ok(Tensor::from_vec(
        w,
        (1, 3, GRADIENT_SIZE, GRADIENT_SIZE),
        &Device::Cpu,
    )?)
}

/// Gradients of `Σ W·eval(wi, wo, maps)` (f64, random maps with roughness ≥ 0.1 and
/// directions with cos θ ≥ ½) against finite differences.
pub fn check_eval_gradients(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let mut r = rng(10);
    let maps = random_maps(&brdf, &mut r, GRADIENT_SIZE, 0.1, DType::F64)?;
    let wi = random_directions(&mut r, GRADIENT_SIZE, 0.5, DType::F64)?;
    let wo = random_directions(&mut r, GRADIENT_SIZE, 0.5, DType::F64)?;
    let w = weights(11)?;
    check_against_finite_differences(&format!("{spec} eval"), &maps, |m| {
        Ok(brdf.eval(&wi, &wo, m)?.mul(&w)?.sum_all()?)
    })
}

/// Gradients of `Σ W·render_radiance(maps)` under an off-centre flash (so an adapter's
/// wrap-around differences and the 1/d² falloff are covered) against finite differences.
pub fn check_render_gradients(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let mut r = rng(12);
    let maps = random_maps(&brdf, &mut r, GRADIENT_SIZE, 0.1, DType::F64)?;
    let w = weights(13)?;
    let light = [Highlight::new(0.15, -0.1)];
    check_against_finite_differences(&format!("{spec} render"), &maps, |m| {
        Ok(render_radiance(brdf.as_ref(), m, &light)?
            .mul(&w)?
            .sum_all()?)
    })
}

// ---------------------------------------------------------------------------------------
// Map files
// ---------------------------------------------------------------------------------------

/// A fresh folder under the system's temporary directory, removed on drop.
struct ScratchDir(PathBuf);

impl ScratchDir {
    fn new() -> Result<Self> {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let path = std::env::temp_dir().join(format!(
            "photomat-conformance-{}-{}-{nanos}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&path).map_err(|e| Error::file(&path, e))?;
        Ok(Self(path))
    }

    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        // Best effort: a leftover folder in the temporary directory harms nothing.
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Random in-range f32 maps for `brdf` with unit normals (a PNG stores directions only).
fn unit_maps(brdf: &Brdf, seed: u64) -> Result<MaterialMaps> {
    let mut maps = random_maps(brdf, &mut rng(seed), ROUND_TRIP_SIZE, 0.05, DType::F32)?;
    for spec in brdf.params() {
        if spec.encoding == Encoding::UnitNormal {
            let unit = normalize3(maps.get(spec.name)?)?;
            maps.insert(spec.name, unit);
        }
    }
    Ok(maps)
}

fn max_abs_diff(a: &Tensor, b: &Tensor) -> Result<f64> {
    Ok(values(a)?
        .iter()
        .zip(values(b)?)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max))
}

/// Remove the `exr` entry of every map that has a PNG, so that loading reads the PNGs.
fn drop_exr_entries(dir: &Path) -> Result<()> {
    let path = dir.join(MANIFEST_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, e))?;
    let mut manifest: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::file(&path, e))?;
    let maps = manifest["maps"]
        .as_array_mut()
        .ok_or_else(|| Error::file(&path, "the manifest lists no maps"))?;
    for entry in maps.iter_mut().filter_map(|e| e.as_object_mut()) {
        if entry.contains_key("png") {
            entry.remove("exr");
        }
    }
    let text = serde_json::to_string_pretty(&manifest).map_err(|e| Error::file(&path, e))?;
    std::fs::write(&path, text).map_err(|e| Error::file(&path, e))
}

/// Save → load through [`crate::map_files`] restores the model and its EXR maps exactly
/// (f32, (1, C, R, R), on the CPU).
pub fn check_exr_round_trip(spec: &str) -> Result<()> {
    let brdf = model(spec)?;
    let maps = unit_maps(&brdf, 7)?;
    let dir = ScratchDir::new()?;
    save_maps(dir.path(), brdf.as_ref(), &maps, &SaveOptions::default())?;
    let loaded = load_maps(dir.path(), None)?;
    ensure!(
        loaded.brdf.name() == brdf.name(),
        "{spec}: saved as '{}', loaded as '{}'",
        brdf.name(),
        loaded.brdf.name()
    );
    ensure!(
        loaded.maps.names() == maps.names(),
        "{spec}: saved maps {:?}, loaded {:?}",
        maps.names(),
        loaded.maps.names()
    );
    for (name, original) in maps.iter() {
        let back = loaded.maps.get(name)?;
        let expected = [1, original.dim(1)?, ROUND_TRIP_SIZE, ROUND_TRIP_SIZE];
        ensure!(
            back.dims() == expected && back.dtype() == DType::F32 && back.device().is_cpu(),
            "{spec}: map '{name}' loads as {:?} {:?}, expected {expected:?} f32 on the CPU",
            back.dims(),
            back.dtype()
        );
        ensure!(
            values(back)? == values(original)?,
            "{spec}: map '{name}' changed through its EXR"
        );
    }
    Ok(())
}

/// Save → load from the PNGs alone (at `bits` per channel) is within half a quantisation step,
/// converted to physical units by the colour space's largest slope.
pub fn check_png_round_trip(spec: &str, bits: PngBits) -> Result<()> {
    let brdf = model(spec)?;
    let maps = unit_maps(&brdf, 7)?;
    let dir = ScratchDir::new()?;
    save_maps(
        dir.path(),
        brdf.as_ref(),
        &maps,
        &SaveOptions {
            png_bits: bits,
            ..SaveOptions::default()
        },
    )?;
    drop_exr_entries(dir.path())?;
    let loaded = load_maps(dir.path(), None)?;
    // Half a quantisation step in stored units, plus f32 arithmetic.
    let half_step = 0.5 / bits.max_value() as f64;
    for p in brdf.params() {
        // Physical error per stored error: 1 (linear); ≤ 2.2 (d s^2.2/ds on [0, 1]);
        // normals: 2 per component, ×√3 over the vector, ×2 after renormalising.
        let gain = match p.color_space {
            ColorSpace::Linear => 1.0,
            ColorSpace::Gamma22 => 2.2,
            ColorSpace::UnitVector => 4.0 * 3f64.sqrt(),
        };
        let err = max_abs_diff(loaded.maps.get(p.name)?, maps.get(p.name)?)?;
        ensure!(
            err <= gain * half_step + 1e-6,
            "{spec}, {bits:?} PNG, map '{}': error {err}",
            p.name
        );
    }
    Ok(())
}

/// [`check_exr_round_trip`] and [`check_png_round_trip`] at 16 and 8 bits.
pub fn check_map_files_round_trip(spec: &str) -> Result<()> {
    check_exr_round_trip(spec)?;
    for bits in [PngBits::Sixteen, PngBits::Eight] {
        check_png_round_trip(spec, bits)?;
    }
    Ok(())
}
