//! # photomat-export
//!
//! Renderer-ready exports of photomat materials:
//!
//! - [`textures`]: a material's maps as the 8-bit textures renderers read (sRGB base and
//!   specular colour, packed roughness, tangent-space normal, clear coat), with the per-plugin
//!   mapping and a record of what cannot be represented;
//! - [`gltf`]: a glTF 2.0 asset (unit quad + material with `KHR_materials_specular`);
//! - [`materialx`]: a MaterialX 1.38 document (`UsdPreviewSurface`, specular workflow);
//! - [`mod@hextile`]: HexTiling (Mikkelsen 2022) of a material's maps to any size without visible
//!   repetition, with one hex lattice shared by every map.
//!
//! ```no_run
//! use photomat_brdfs as _; // link the built-in plugins
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let material = photomat_core::map_files::load_maps("out/seed-0001/material".as_ref(), None)?;
//! let dir = std::path::Path::new("out/seed-0001/export");
//! let set = photomat_export::textures::write_textures(dir, material.brdf.as_ref(), &material.maps)?;
//! photomat_export::gltf::write_gltf(dir, "material", &set)?;
//! photomat_export::materialx::write_materialx(dir, "material", &set)?;
//! # Ok(()) }
//! ```

pub mod gltf;
pub mod hextile;
pub mod materialx;
pub mod textures;

pub use gltf::write_gltf;
pub use hextile::{HexTiling, hextile};
pub use materialx::write_materialx;
pub use textures::{Factors, TextureSet, write_textures};
