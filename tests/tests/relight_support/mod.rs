//! Fixtures of the `relight` and `eval-gan` command tests: the `photomat` command line run in
//! process, an untrained tiny GAN model folder and a tiny simulated, prepared data set.

#![allow(dead_code)] // each test file uses its own subset

use std::path::{Path, PathBuf};

use candle_core::Device;
use photomat_generator::{GanModel, GeneratorConfig};

/// Run `photomat ARGS…`, returning stdout.
pub fn photomat(args: &[&str]) -> anyhow::Result<String> {
    let mut out = Vec::new();
    photomat_cli::run_with_output(
        std::iter::once("photomat").chain(args.iter().copied()),
        &mut out,
    )?;
    Ok(String::from_utf8(out).expect("UTF-8 output"))
}

/// The error of `photomat ARGS…` formatted as the binary prints it.
pub fn photomat_error(args: &[&str]) -> String {
    match photomat(args) {
        Ok(out) => panic!("photomat {args:?} should fail, printed:\n{out}"),
        Err(e) => photomat_cli::format_error(&e),
    }
}

/// The tiny architecture of the GAN tests, at side `resolution`.
pub fn tiny_config(resolution: usize) -> GeneratorConfig {
    GeneratorConfig {
        resolution,
        channel_multiplier: 1.0 / 64.0,
        latent_dim: 16,
        feature_channels: 8,
        relight_hidden: 8,
        ..Default::default()
    }
}

/// An untrained tiny GAN (weights from `seed`) saved in `dir/name`; returns the folder.
pub fn tiny_gan(dir: &Path, name: &str, resolution: usize, seed: u64) -> PathBuf {
    let path = dir.join(name);
    GanModel::new(&tiny_config(resolution), seed, &Device::Cpu)
        .unwrap()
        .save(&path, serde_json::json!({ "test": true }))
        .unwrap();
    path
}

/// A data set of 6 simulated flash photos prepared at 64² (enough for 32² models) in
/// `dir/data`; returns the folder.
pub fn tiny_dataset(dir: &Path) -> PathBuf {
    let (sim, data) = (dir.join("sim"), dir.join("data"));
    photomat(&[
        "simulate",
        "--count",
        "6",
        "--size",
        "96",
        "--seed",
        "3",
        "--out",
        path_str(&sim),
    ])
    .unwrap();
    photomat(&[
        "prepare",
        "--photos",
        path_str(&sim.join("photos")),
        "--out",
        path_str(&data),
        "--size",
        "64",
    ])
    .unwrap();
    data
}

pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("UTF-8 temp path")
}
