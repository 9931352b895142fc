//! # photomat-custom-brdf-example
//!
//! How a user adds a BRDF model to photomat from their own crate, without editing photomat:
//! one file per model whose stem is the registered name ([`blinn_phong`]), registered with
//! `photomat_core::register_brdf!`, and a binary (`src/main.rs`) that links this crate and
//! hands control to `photomat_cli::run()`.
//!
//! Linking pitfall (DESIGN §3): a crate that is never named in code contributes no plugins,
//! so every binary and test that should see `blinn_phong` writes
//! `use photomat_custom_brdf_example as _;`.

pub mod blinn_phong;

/// The name this crate registers.
pub const REGISTERED_NAMES: &[&str] = &["blinn_phong"];
