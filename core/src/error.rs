//! The error type of photomat's library crates.
//!
//! Every user-facing failure names what went wrong and where (model name, map name, file),
//! following typetag's "unknown name lists the known names" and Mitsuba's "validate the
//! parameter dictionary at once" conventions (see `docs/plugins.md`, "Registry behaviour").

use std::path::PathBuf;

/// Result alias used throughout photomat.
pub type Result<T> = std::result::Result<T, Error>;

/// Everything that can go wrong in the engine.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A BRDF name that no linked plugin registered.
    #[error("unknown BRDF model '{name}'; registered models: {}", known.join(", "))]
    UnknownBrdf { name: String, known: Vec<String> },

    /// Two plugins registered the same name (each name must be unique across all linked crates).
    #[error("BRDF model name '{0}' is registered more than once; plugin names must be unique")]
    DuplicateBrdf(String),

    /// A model specification string such as `height(ggx, scale=0.02)` that cannot be parsed or
    /// carries arguments the model does not accept.
    #[error("invalid BRDF specification '{spec}': {reason}")]
    BadSpec { spec: String, reason: String },

    /// Material maps that do not fit a model's parameter specs.
    #[error("invalid material maps for '{model}': {reason}")]
    InvalidMaps { model: String, reason: String },

    /// A file that could not be read, written or validated.
    #[error("{}: {reason}", path.display())]
    File { path: PathBuf, reason: String },

    /// Any other invalid argument (shapes, resolutions, light positions).
    #[error("{0}")]
    Invalid(String),

    /// An error from the tensor library.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}

impl Error {
    /// A file error naming `path`.
    pub fn file(path: impl Into<PathBuf>, reason: impl std::fmt::Display) -> Self {
        Error::File {
            path: path.into(),
            reason: reason.to_string(),
        }
    }
}
