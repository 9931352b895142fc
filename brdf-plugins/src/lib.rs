//! # photomat-brdfs
//!
//! The built-in BRDF plugins, one file per model, file stem = registered name (Mitsuba 3's
//! layout): [`lambert`], [`blinn_phong`], [`ggx`], [`ggx_aniso`], [`coated`] and the [`height`]
//! adapter. Each file's header
//! holds the model's parameter table; each file declares its plugin once with
//! `photomat_core::register_brdf!`, and the maps several models share come from
//! [`photomat_core::param::common`]. Adding a built-in is one new file here and nothing else:
//! `build.rs` declares every file of `src/` as a module, and the names, the tests' model list
//! and the conformance checks follow from the registry.
//!
//! Linking: a crate that only lists this one in Cargo.toml sees none of its plugins; name it
//! in code with `use photomat_brdfs as _;`.

// `pub mod coated; pub mod ggx; …`: one module per file of `src/`, written by `build.rs`.
include!(concat!(env!("OUT_DIR"), "/plugins.rs"));

use photomat_core::{Result, registrations_from};

/// Sorted names of the models this crate registers, read from the registry.
pub fn builtin_names() -> Result<Vec<&'static str>> {
    Ok(registrations_from(module_path!())?
        .into_iter()
        .map(|r| r.name)
        .collect())
}

/// The configurations the built-ins are tested and benchmarked in: every model by name, its
/// variants (`ggx(shadowing=correlated)`, …) and every adapter around the first model it
/// accepts (`coated`, `ggx`, …, `lambert`,
/// `height(ggx)`); see [`photomat_core::testing::configurations`].
pub fn builtin_configurations() -> Result<Vec<String>> {
    photomat_core::testing::configurations(&[module_path!()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtins_are_exactly_the_plugin_files() {
        // Catches a file without a registration and a
        // registration whose name is not its file's stem.
        let names = builtin_names().unwrap();
        assert!(!names.is_empty(), "no built-in is linked into the tests");
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        assert_eq!(
            names,
            photomat_core::testing::plugin_file_stems(&dir).unwrap()
        );
    }

    #[test]
    fn builtins_file_stem_equals_registered_name() {
        photomat_core::testing::check_file_stems(module_path!()).unwrap();
        for r in registrations_from(module_path!()).unwrap() {
            assert_eq!(
                r.module.rsplit("::").next(),
                Some(r.name),
                "{} registered from module {}",
                r.name,
                r.module
            );
        }
    }
}
