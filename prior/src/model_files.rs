//! A trained relief prior on disk: `prior.json` ([`PRIOR_MANIFEST_FILE`]: format tag, the
//! model by name, the architecture, provenance) and `prior.safetensors` (the weights), in a
//! model folder's `priors/<name>/` (one prior per model, found by [`find_prior`]) or in a
//! training run's folder. Loading checks the architecture against the limits before any weight
//! is allocated and the model against the registry.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_core::checkpoint::{load_vars_checked, save_vars_atomic};
use photomat_core::image_io::write_atomic;
use photomat_core::{Brdf, Highlight, MaterialMaps, lookup};
use serde::{Deserialize, Serialize};

use crate::input::prior_input;
use crate::maps::{colour_specs, decode_colour, model_maps};
use crate::network::{PriorConfig, PriorNet};

/// The manifest of a prior.
pub const PRIOR_MANIFEST_FILE: &str = "prior.json";
/// The weights of a prior.
pub const PRIOR_WEIGHTS_FILE: &str = "prior.safetensors";
/// The folder of a model folder's priors, one sub-folder per model.
pub const PRIORS_DIR: &str = "priors";
/// Value of the manifest's `format` field.
pub const FORMAT_TAG: &str = "photomat-prior";
/// Manifest version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// The contents of `prior.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PriorManifest {
    pub format: String,
    pub version: u32,
    /// Canonical specification of the model the prior predicts maps of.
    pub brdf: String,
    pub architecture: PriorConfig,
    /// How it was trained (data, steps, validation score), informational.
    pub provenance: serde_json::Value,
}

/// A relief prior: the network and the model it serves.
pub struct PriorModel {
    brdf: Brdf,
    net: PriorNet,
    vars: VarMap,
    manifest: PriorManifest,
}

/// What a prior predicts for a photo.
pub struct PriorMaps {
    /// The model of the maps (a height model with the predicted relief's scale).
    pub brdf: Brdf,
    /// (1, C, N, N) maps with their texel size.
    pub maps: MaterialMaps,
    /// The heights in world units (1, 1, N, N).
    pub height: Tensor,
}

impl PriorModel {
    /// A new prior for `brdf` with architecture `config`, weights drawn under `vars`.
    pub fn new(
        brdf: Brdf,
        config: PriorConfig,
        vars: VarMap,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let expected = colour_specs(&brdf)
            .iter()
            .map(|s| s.channels)
            .sum::<usize>();
        if config.colour_channels != expected {
            bail!(
                "a prior for {} needs {expected} colour channels, the architecture has {}",
                brdf.name(),
                config.colour_channels
            );
        }
        let vb = VarBuilder::from_varmap(&vars, DType::F32, device);
        let net = PriorNet::new(&config, vb)?;
        let manifest = PriorManifest {
            format: FORMAT_TAG.into(),
            version: FORMAT_VERSION,
            brdf: brdf.name(),
            architecture: config,
            provenance: serde_json::Value::Null,
        };
        Ok(Self {
            brdf,
            net,
            vars,
            manifest,
        })
    }

    /// A new prior for `brdf` with weights drawn from `seed` (the project's seeded
    /// initialisers, [`photomat_generator::seeded_var_builder`]: the same seed gives the same
    /// weights on every machine).
    pub fn new_seeded(
        brdf: Brdf,
        config: PriorConfig,
        seed: u64,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let vars = VarMap::new();
        // Creates every variable with its seeded value; `new` then finds them in `vars`.
        PriorNet::new(
            &config,
            photomat_generator::seeded_var_builder(&vars, seed, DType::F32, device),
        )?;
        Self::new(brdf, config, vars, device)
    }

    /// Loads the prior in `dir` (module docs); errors name the file.
    pub fn load(dir: &Path, device: &Device) -> anyhow::Result<Self> {
        let path = dir.join(PRIOR_MANIFEST_FILE);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: cannot read the prior's manifest", path.display()))?;
        let manifest: PriorManifest = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a prior manifest", path.display()))?;
        if manifest.format != FORMAT_TAG || manifest.version != FORMAT_VERSION {
            bail!(
                "{}: format {} version {}; this build reads {FORMAT_TAG} version {FORMAT_VERSION}",
                path.display(),
                manifest.format,
                manifest.version
            );
        }
        manifest
            .architecture
            .validate()
            .with_context(|| format!("{}: invalid architecture", path.display()))?;
        let brdf =
            lookup(&manifest.brdf).with_context(|| format!("{}: its model", path.display()))?;
        let mut prior = Self::new(brdf, manifest.architecture.clone(), VarMap::new(), device)?;
        load_vars_checked(&prior.vars, &dir.join(PRIOR_WEIGHTS_FILE))?;
        prior.manifest = manifest;
        Ok(prior)
    }

    /// Writes `dir/prior.safetensors` then `dir/prior.json` (a folder with a manifest is
    /// complete), with `provenance`.
    pub fn save(&self, dir: &Path, provenance: serde_json::Value) -> anyhow::Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        save_vars_atomic(&self.vars, &dir.join(PRIOR_WEIGHTS_FILE))?;
        let manifest = PriorManifest {
            provenance,
            ..self.manifest.clone()
        };
        write_atomic(
            &dir.join(PRIOR_MANIFEST_FILE),
            &serde_json::to_vec_pretty(&manifest)?,
        )?;
        Ok(())
    }

    pub fn brdf(&self) -> &Brdf {
        &self.brdf
    }

    pub fn net(&self) -> &PriorNet {
        &self.net
    }

    pub fn vars(&self) -> &VarMap {
        &self.vars
    }

    pub fn manifest(&self) -> &PriorManifest {
        &self.manifest
    }

    /// The maps the prior predicts for the photo `photo` (1, 3, N, N, display values) taken
    /// with the flash above `highlight` on a square of side `side` world units; N a multiple
    /// of the network's stride.
    pub fn predict(
        &self,
        photo: &Tensor,
        highlight: Highlight,
        side: f64,
    ) -> anyhow::Result<PriorMaps> {
        let (_, _, n, _) = photo.dims4()?;
        let x = prior_input(photo, &[highlight], side)?;
        let out = self.net.forward(&x)?;
        let colour = decode_colour(&colour_specs(&self.brdf), &out.colour)?;
        let texel = side / n as f64;
        let (brdf, maps) = model_maps(&self.brdf, &colour, &out.height, texel)?;
        Ok(PriorMaps {
            brdf,
            maps: maps.map_tensors(|t| Ok(t.detach()))?,
            height: out.height.detach(),
        })
    }
}

/// The prior for `brdf` in the model folder `dir` (`priors/<name>/` whose manifest names the
/// same canonical model), if it has one.
pub fn find_prior(dir: &Path, brdf: &Brdf) -> anyhow::Result<Option<PathBuf>> {
    let priors = dir.join(PRIORS_DIR);
    let Ok(entries) = std::fs::read_dir(&priors) else {
        return Ok(None);
    };
    let want = brdf.name();
    let mut found = Vec::new();
    for entry in entries {
        let folder = entry?.path();
        let Ok(text) = std::fs::read_to_string(folder.join(PRIOR_MANIFEST_FILE)) else {
            continue;
        };
        let Ok(manifest) = serde_json::from_str::<PriorManifest>(&text) else {
            continue;
        };
        // A height prior serves its model at any scale: the scale is fitted per photo.
        let family = |spec: &str| spec.split("scale=").next().unwrap_or(spec).to_string();
        if manifest.brdf == want || family(&manifest.brdf) == family(&want) {
            found.push(folder);
        }
    }
    found.sort();
    Ok(found.into_iter().next())
}
