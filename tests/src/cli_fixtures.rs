//! Fixtures of the command-line integration tests: `photomat` run in process, an untrained
//! tiny GAN model folder, the tiny estimator architecture, and a tiny simulated, prepared
//! flash-photo data set.

use std::path::{Path, PathBuf};

use candle_core::Device;
use photomat_generator::{GanModel, GeneratorConfig};

/// Run `photomat ARGS…` in process, returning stdout.
pub fn photomat(args: &[&str]) -> anyhow::Result<String> {
    let mut out = Vec::new();
    photomat_cli::run_with_output(
        std::iter::once("photomat").chain(args.iter().copied()),
        &mut out,
    )?;
    Ok(String::from_utf8(out).expect("UTF-8 output"))
}

/// The error of `photomat ARGS…` formatted as the binary prints it; panics if it succeeds.
pub fn photomat_error(args: &[&str]) -> String {
    match photomat(args) {
        Ok(out) => panic!("photomat {args:?} should fail, printed:\n{out}"),
        Err(e) => photomat_cli::format_error(&e),
    }
}

/// A path as the `&str` the command line takes.
pub fn path_str(p: &Path) -> &str {
    p.to_str().expect("UTF-8 temp path")
}

/// The tiny estimator architecture of the tests: reads [`tiny_gan_config`]'s 8 feature
/// channels, two levels, `out_channels` maps.
pub fn tiny_estimator_config(out_channels: usize) -> photomat_estimator::EstimatorConfig {
    photomat_estimator::EstimatorConfig {
        in_channels: 8,
        encoder_channels: vec![4, 8],
        decoder_channels: vec![4],
        out_channels,
        ..Default::default()
    }
}

/// The tiny GAN architecture of the tests (seconds per training step), at side `resolution`.
pub fn tiny_gan_config(resolution: usize) -> GeneratorConfig {
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
    GanModel::new(&tiny_gan_config(resolution), seed, &Device::Cpu)
        .unwrap()
        .save(&path, serde_json::json!({ "test": true }))
        .unwrap();
    path
}

/// A data set of 6 simulated flash photos (PNG, 2·`size` pixels) prepared at `size`² in
/// `dir/data` — enough for models up to `size / 2`; returns the folder.
pub fn simulated_dataset(dir: &Path, size: u32) -> PathBuf {
    let (sim, data) = (dir.join("sim"), dir.join("data"));
    photomat(&[
        "simulate",
        "--count",
        "6",
        "--size",
        &(2 * size).to_string(),
        "--seed",
        "3",
        "--format",
        "png",
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
        &size.to_string(),
    ])
    .unwrap();
    data
}
