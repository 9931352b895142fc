//! One module per `photomat` subcommand: its clap arguments (`Args`) and its `run`.

pub mod bench;
pub mod brdf_eval;
pub mod brdfs;
pub mod capture;
pub mod demo;
pub mod eval_detector;
pub mod eval_gan;
pub mod library;
pub mod map_stats;
pub mod prepare;
pub mod rank_snapshots;
pub mod relight;
pub mod render;
pub mod sample;
pub mod simulate;
pub mod trade;
pub mod train_estimator;
pub mod train_gan;
pub mod train_prior;
