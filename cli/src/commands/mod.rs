//! One module per `photomat` subcommand: its clap arguments (`Args`) and its `run`.

pub mod brdf_eval;
pub mod brdfs;
pub mod render;
