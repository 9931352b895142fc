//! The parameter maps that several models share, so that `diffuse` means the same map
//! (range, encoding, file colour space, default) in every model that takes one — built-in or
//! a user's plugin. A model whose map differs only in its documentation line reuses the spec
//! with struct update syntax: `ParamSpec { doc: "…", ..SPECULAR }`.
//!
//! The α floor quoted by [`ROUGHNESS`] lives in [`crate::microfacet`]; the unit-normal
//! decoding of [`NORMAL`] in [`super::Encoding::UnitNormal`].

use super::{ColorSpace, Encoding, ParamSpec};

/// Diffuse albedo ρ_d (rgb, linear reflectance).
pub const DIFFUSE: ParamSpec = ParamSpec {
    name: "diffuse",
    channels: 3,
    range: (0.0, 1.0),
    encoding: Encoding::Gamma22,
    color_space: ColorSpace::Gamma22,
    default: &[0.5, 0.5, 0.5],
    differentiable: true,
    doc: "diffuse albedo ρ_d, linear rgb",
};

/// Specular albedo = Schlick F0 (rgb).
pub const SPECULAR: ParamSpec = ParamSpec {
    name: "specular",
    channels: 3,
    range: (0.0, 1.0),
    encoding: Encoding::Gamma22,
    color_space: ColorSpace::Gamma22,
    default: &[0.04, 0.04, 0.04],
    differentiable: true,
    doc: "specular albedo = Schlick F0 at normal incidence, linear rgb",
};

/// Perceptual roughness r; α = max(r², 1e-4).
pub const ROUGHNESS: ParamSpec = ParamSpec {
    name: "roughness",
    channels: 1,
    range: (0.0, 1.0),
    encoding: Encoding::Linear,
    color_space: ColorSpace::Linear,
    default: &[0.5],
    differentiable: true,
    doc: "perceptual roughness r, GGX α = max(r², 1e-4)",
};

/// Shading normal in the plane's frame (x right, y up, z out of the surface).
pub const NORMAL: ParamSpec = ParamSpec {
    name: "normal",
    channels: 3,
    range: (-1.0, 1.0),
    encoding: Encoding::UnitNormal,
    color_space: ColorSpace::UnitVector,
    default: &[0.0, 0.0, 1.0],
    differentiable: true,
    doc: "shading normal (x right, y up, z out), normalised before use",
};
