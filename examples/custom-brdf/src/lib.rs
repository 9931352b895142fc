//! # photomat-custom-brdf-example
//!
//! How a user adds a BRDF model to photomat from their own crate, without editing photomat:
//! one file per model whose stem is the registered name ([`blinn_phong_gloss`]), declared once with
//! `photomat_core::register_brdf!` (its maps reuse `photomat_core::param::common`), and a
//! binary (`src/main.rs`) that links this crate and hands control to `photomat_cli::run()`.
//! Its tests run photomat's conformance kit (`photomat_core::testing::check_model`).
//!
//! Linking pitfall (documented in `photomat_core::registry`): a crate that is never named in code contributes no plugins,
//! so every binary and test that should see `blinn_phong_gloss` writes
//! `use photomat_custom_brdf_example as _;`.

pub mod blinn_phong_gloss;

/// Sorted names of the models this crate registers, read from the registry.
pub fn registered_names() -> photomat_core::Result<Vec<&'static str>> {
    Ok(photomat_core::registrations_from(module_path!())?
        .into_iter()
        .map(|r| r.name)
        .collect())
}
