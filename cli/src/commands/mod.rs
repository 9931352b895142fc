//! One module per `photomat` subcommand: its clap arguments (`Args`) and its `run`.

pub mod bench;
pub mod brdf_eval;
pub mod brdfs;
pub mod demo;
pub mod eval_detector;
pub mod eval_gan;
pub mod prepare;
pub mod previews;
pub mod relight;
pub mod render;
pub mod sample;
pub mod simulate;
pub mod train_estimator;
pub mod train_gan;

/// The f64 with the f32's shortest decimal form: spec constants written `0.04` in a plugin
/// show (and evaluate in f64) as 0.04 rather than 0.03999999910593033, the f32's exact value.
pub(crate) fn shortest(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}
