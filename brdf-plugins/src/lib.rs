//! # photomat-brdfs
//!
//! The built-in BRDF plugins, one file per model, file stem = registered name
//! (`shared/STYLE.md`, Mitsuba's layout): [`lambert`], [`ggx`], [`coated`] and the [`height`]
//! adapter. Each file's header holds the model's parameter table.
//!
//! Linking: a crate that only lists this one in Cargo.toml sees none of its plugins; name it
//! in code with `use photomat_brdfs as _;`.

pub mod coated;
mod common;
pub mod ggx;
pub mod height;
pub mod lambert;

/// Sorted names of the models this crate registers (the registry guard tests compare the
/// registry against this list plus whatever a binary links in on top).
pub const BUILTIN_NAMES: &[&str] = &["coated", "ggx", "height", "lambert"];
