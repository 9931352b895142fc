//! `photomat-custom`: the photomat command line with the user's own models linked in.
//!
//! Everything `photomat` does (`brdfs`, `render`, `brdf-eval`) comes from
//! `photomat_cli::run()`; this binary only adds the plugins of this crate to the registry.

// Linking pitfall (documented in `photomat_core::registry`): a crate that is never named in code contributes no plugins.
use photomat_custom_brdf_example as _;

fn main() -> std::process::ExitCode {
    photomat_cli::run()
}
