//! # photomat-core
//!
//! The conventions every photomat crate shares (`docs/conventions.md`): the
//! [`DifferentiableBrdf`] trait and its parameter specs, the plugin [`registry`], the shared
//! [`microfacet`] maths, the collocated-[`flash`] plane geometry, the differentiable
//! [`mod@render`]er with its per-texel vector algebra ([`vecops`], fused in [`texel_ops`]), the
//! material-map folder format ([`map_files`]), the seeded random generator every crate draws
//! from ([`rng`]), the conformance kit every plugin's tests run ([`testing`]) and the
//! derivative checks of fused ops' tests ([`op_derivatives`]); the spread of a material's maps
//! ([`map_stats`]) and the distance between two sets' distributions of it ([`map_distribution`]); and the rules every command
//! that writes files follows: locked folders ([`folder_lock`]), results replaced whole or not
//! at all ([`output_folder`]), memory checked before it is spent ([`memory`]).
//!
//! Models live in `photomat-brdfs` (and in users' own crates); each declares itself once
//! with [`register_brdf!`] and is built by name with [`lookup`]:
//!
//! ```ignore
//! use photomat_brdfs as _; // link the built-in plugins
//! let model = photomat_core::lookup("height(ggx)")?;
//! assert_eq!(model.channels(), 8);
//! ```

pub mod adapter;
pub mod brdf;
pub mod checkpoint;
pub mod error;
pub mod flash;
pub mod folder_lock;
pub mod image_io;
pub mod lights;
pub mod lobes;
pub mod map_distribution;
pub mod map_files;
pub mod map_stats;
pub mod maps;
pub mod memory;
pub mod microfacet;
pub mod model;
pub mod op_derivatives;
pub mod output_folder;
pub mod param;
pub mod paths;
pub mod plugin_spec;
pub mod previews;
pub mod registry;
pub mod render;
pub mod rng;
pub mod shading;
pub mod sheet;
pub mod simplify;
pub mod testing;
pub mod texel_ops;
pub mod vecops;

pub use adapter::{AdaptedBrdf, MapAdapter};
pub use brdf::{Brdf, DifferentiableBrdf};
pub use error::{Error, Result};
pub use flash::{FlashGeometry, Highlight};
pub use folder_lock::FolderLock;
pub use lights::LightSet;
pub use maps::MaterialMaps;
pub use model::{ModelBrdf, Reflectance};
pub use output_folder::{OutputFolder, ResultKind};
pub use param::{ColorSpace, Encoding, ParamSpec};
pub use plugin_spec::{ArgValue, PluginSpec};
pub use registry::{
    ArgKind, ArgSpec, BrdfArgs, BrdfRegistration, lookup, registered_names, registrations,
    registrations_from,
};
pub use render::{encode_display, render, render_radiance, render_radiance_with, render_with};
pub use rng::SplitMix64;
pub use shading::ShadingGeometry;

/// Re-exports for [`register_brdf!`]; not part of the public API.
#[doc(hidden)]
pub mod __private {
    pub use inventory;
}
