//! What the GAN trainer's tests (`train.rs`, `train_spatial.rs`) share: a tiny simulated data
//! set, and snapshots of a run's state for bit-identity checks.

use std::path::{Path, PathBuf};

use anyhow::Result;
use candle_nn::VarMap;
// Link the built-in BRDF plugins: the simulator renders with them.
use photomat_brdfs as _;
use photomat_data::dataset::{PrepareOptions, prepare};
use photomat_data::procedural::families;
use photomat_data::simulator::{
    CameraSource, HighlightJitter, PhoneCamera, PhotoFormat, SimulationConfig, simulate,
};
/// `count` simulated photos of 64² of every family (PNG, seeded), prepared at 64² in
/// `dir/data`; returns the data set folder.
pub fn simulated_dataset(dir: &Path, count: usize, seed: u64) -> Result<PathBuf> {
    let (sim, data) = (dir.join("sim"), dir.join("data"));
    let all = families();
    let config = SimulationConfig {
        count,
        size: 64,
        seed,
        format: PhotoFormat::Png,
        families: all.iter().map(|f| f.as_ref()).collect(),
        camera: CameraSource::Phone(PhoneCamera::default()),
        jitter: HighlightJitter::default(),
        pose: Default::default(),
    };
    simulate(&sim, &config, false, &|| {})?;
    let options = PrepareOptions {
        size: 64,
        progress: false,
        ..PrepareOptions::default()
    };
    prepare(&sim.join("photos"), &data, &options)?;
    Ok(data)
}

/// Every state variable as raw values, by name.
pub fn snapshot(vars: &VarMap) -> Vec<(String, Vec<f64>)> {
    let data = vars.data().lock().unwrap();
    let mut out: Vec<_> = data
        .iter()
        .map(|(n, v)| {
            let values = v
                .as_tensor()
                .flatten_all()
                .and_then(|t| t.to_dtype(candle_core::DType::F64))
                .and_then(|t| t.to_vec1::<f64>())
                .unwrap();
            (n.clone(), values)
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}
