//! # photomat-brdfs
//!
//! The built-in BRDF plugins, one file per model, file stem = registered name (Mitsuba 3's
//! layout): [`lambert`], [`ggx`], [`coated`] and the [`height`] adapter. Each file's header
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

/// The configurations the built-ins are tested and benchmarked in: every model by name and
/// every adapter around the first model it accepts (`coated`, `ggx`, `lambert`,
/// `height(ggx)`); see [`photomat_core::testing::configurations`].
pub fn builtin_configurations() -> Result<Vec<String>> {
    photomat_core::testing::configurations(&[module_path!()])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plugin files: every `src/*.rs` but the crate root.
    fn plugin_file_stems() -> Vec<String> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        let mut stems: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "rs"))
            .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
            .filter(|stem| stem != "lib")
            .collect();
        stems.sort();
        stems
    }

    #[test]
    fn builtins_are_exactly_the_plugin_files() {
        // Catches a file without a registration and a
        // registration whose name is not its file's stem.
        let names = builtin_names().unwrap();
        assert!(!names.is_empty(), "no built-in is linked into the tests");
        assert_eq!(names, plugin_file_stems());
    }

    #[test]
    fn builtins_file_stem_equals_registered_name() {
        for r in registrations_from(module_path!()).unwrap() {
            assert_eq!(
                r.file_stem(),
                Some(r.name),
                "{} registered in {}",
                r.name,
                r.file
            );
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
