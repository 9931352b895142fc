//! What a BRDF model costs, measured: its flash render (evaluation) and render + gradient time
//! per megatexel, and the bytes of its exported maps. The trade study's cost axis.
//!
//! Times are the minimum over [`REPEATS`] rounds after one warm-up round (the run least
//! disturbed by other processes on a shared machine), on random valid maps
//! ([`photomat_core::testing::random_maps`]) of [`BENCH_SIDE`]² texels under the centred flash,
//! in f32 on the CPU. [`render_costs`] times several models in interleaved rounds (each round
//! renders every model once), so that a load that comes and goes slows them all alike and
//! their order holds. They are measurements of this machine at this moment: compare models
//! measured in the same call, not numbers from different runs.

use std::path::Path;
use std::time::Instant;

use candle_core::{DType, Device, Var};
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::{Brdf, Highlight, LightSet, MaterialMaps, render_with};
use serde::{Deserialize, Serialize};

/// Side of the maps the render is timed on: 256² = 65 536 texels, large enough that fixed
/// per-call costs are a small share, small enough for a second per model.
pub const BENCH_SIDE: usize = 256;
/// Timed rounds per measurement (the fastest is kept).
pub const REPEATS: usize = 7;

/// Render cost of one model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderCost {
    /// Milliseconds per megatexel of a flash render (BRDF evaluation, geometry included).
    pub eval_ms_per_megatexel: f64,
    /// Milliseconds per megatexel of the render plus the gradient w.r.t. every map.
    pub eval_grad_ms_per_megatexel: f64,
}

/// Times the flash render and render + backward ([`RenderCost`]) of every model in
/// `brdfs`, in interleaved rounds; one cost per model, in order.
pub fn render_costs(brdfs: &[Brdf], seed: u64) -> anyhow::Result<Vec<RenderCost>> {
    let device = Device::Cpu;
    let geometry =
        LightSet::single(Highlight { x: 0.0, y: 0.0 }).geometry(BENCH_SIDE, DType::F32, &device)?;
    let mut inputs = Vec::new();
    for brdf in brdfs {
        let mut rng = photomat_core::testing::rng(seed);
        // Roughness ≥ 0.05: the timed values stay in the models' well-conditioned range.
        let maps =
            photomat_core::testing::random_maps(brdf, &mut rng, BENCH_SIDE, 0.05, DType::F32)?;
        let (vars, var_maps) = as_vars(&maps)?;
        inputs.push((maps, vars, var_maps));
    }
    let eval = |k: usize| -> anyhow::Result<f64> {
        let start = Instant::now();
        render_with(brdfs[k].as_ref(), &inputs[k].0, &geometry)?;
        Ok(start.elapsed().as_secs_f64())
    };
    let eval_grad = |k: usize| -> anyhow::Result<f64> {
        let (_, vars, var_maps) = &inputs[k];
        let start = Instant::now();
        let image = render_with(brdfs[k].as_ref(), var_maps, &geometry)?;
        let grads = image.sum_all()?.backward()?;
        // Touch every gradient so that none is optimised away.
        for var in vars {
            grads.get(var.as_tensor());
        }
        Ok(start.elapsed().as_secs_f64())
    };
    let mut fastest = vec![(f64::INFINITY, f64::INFINITY); brdfs.len()];
    // Round 0 is the untimed warm-up.
    for round in 0..=REPEATS {
        for (k, best) in fastest.iter_mut().enumerate() {
            let (e, g) = (eval(k)?, eval_grad(k)?);
            if round > 0 {
                *best = (best.0.min(e), best.1.min(g));
            }
        }
    }
    let megatexels = (BENCH_SIDE * BENCH_SIDE) as f64 / 1e6;
    Ok(fastest
        .into_iter()
        .map(|(e, g)| RenderCost {
            eval_ms_per_megatexel: e * 1e3 / megatexels,
            eval_grad_ms_per_megatexel: g * 1e3 / megatexels,
        })
        .collect())
}

/// Every map as a [`Var`], and the maps that read them.
fn as_vars(maps: &MaterialMaps) -> anyhow::Result<(Vec<Var>, MaterialMaps)> {
    let mut vars = Vec::new();
    let mut out = MaterialMaps::new();
    for (name, tensor) in maps.iter() {
        let var = Var::from_tensor(tensor)?;
        out.insert(name, var.as_tensor().clone());
        vars.push(var);
    }
    Ok((vars, out))
}

/// Bytes of one material's exported maps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapBytes {
    /// The PNG files (what most renderers load).
    pub png: u64,
    /// The float EXR files.
    pub exr: u64,
}

/// Writes `maps` as a material folder at `dir` ([`save_maps`]) and measures its files.
pub fn write_and_measure(dir: &Path, brdf: &Brdf, maps: &MaterialMaps) -> anyhow::Result<MapBytes> {
    save_maps(dir, brdf.as_ref(), maps, &SaveOptions::default())?;
    let mut bytes = MapBytes { png: 0, exr: 0 };
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        let len = std::fs::metadata(&path)?.len();
        match path.extension().and_then(|e| e.to_str()) {
            Some("png") => bytes.png += len,
            Some("exr") => bytes.exr += len,
            _ => {}
        }
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photomat_brdfs as _;

    #[test]
    fn map_bytes_are_the_files_written() {
        let brdf = photomat_core::lookup("height(ggx)").unwrap();
        let mut rng = photomat_core::testing::rng(3);
        let maps =
            photomat_core::testing::random_maps(&brdf, &mut rng, 16, 0.1, DType::F32).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let bytes = write_and_measure(&dir.path().join("m"), &brdf, &maps).unwrap();
        let mut png = 0;
        let mut exr = 0;
        for entry in std::fs::read_dir(dir.path().join("m")).unwrap() {
            let path = entry.unwrap().path();
            let len = std::fs::metadata(&path).unwrap().len();
            if path.extension().unwrap() == "png" {
                png += len;
            } else if path.extension().unwrap() == "exr" {
                exr += len;
            }
        }
        assert_eq!(bytes, MapBytes { png, exr });
        assert!(png > 0 && exr > 0);
    }

    #[test]
    fn render_cost_is_measured_for_every_builtin() {
        let specs = photomat_brdfs::builtin_configurations().unwrap();
        let brdfs: Vec<Brdf> = specs
            .iter()
            .map(|s| photomat_core::lookup(s).unwrap())
            .collect();
        let costs = render_costs(&brdfs, 1).unwrap();
        assert_eq!(costs.len(), specs.len());
        for (spec, cost) in specs.iter().zip(&costs) {
            assert!(
                cost.eval_ms_per_megatexel.is_finite() && cost.eval_ms_per_megatexel > 0.0,
                "{spec}: {cost:?}"
            );
            assert!(
                cost.eval_grad_ms_per_megatexel.is_finite(),
                "{spec}: {cost:?}"
            );
        }
    }
}
