//! A trained estimator on disk: E's architecture, the BRDF model it decodes into and its
//! weights. `photomat train-estimator` writes one next to a copy of the GAN model
//! (`photomat_generator::model_files`), so that one folder holds everything `photomat sample`
//! needs.
//!
//! Files, each written atomically (temporary file + rename):
//! - [`ESTIMATOR_MANIFEST_FILE`] (`estimator.json`): format tag, version, the BRDF spec in
//!   canonical form (e.g. `height(ggx, scale=0.02)`), the architecture ([`EstimatorConfig`])
//!   and free-form provenance;
//! - [`ESTIMATOR_WEIGHTS_FILE`] (`estimator.safetensors`): E's parameters (names of
//!   [`Estimator`]).
//!
//! Loading resolves the BRDF by name in the plugin registry — a model trained for a user
//! plugin loads in any binary that links that plugin and fails with the registry's list of
//! known names elsewhere — and checks that its channel count still equals E's output width.

use std::path::Path;

use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_core::checkpoint::{load_vars_checked, save_vars_atomic};
use photomat_core::image_io::write_atomic;
use photomat_core::{Brdf, Error, MaterialMaps, Result};
use serde::{Deserialize, Serialize};

use crate::{Estimator, EstimatorConfig};

/// Manifest file of an estimator.
pub const ESTIMATOR_MANIFEST_FILE: &str = "estimator.json";
/// Weights file of an estimator.
pub const ESTIMATOR_WEIGHTS_FILE: &str = "estimator.safetensors";
/// `format` tag of the manifest.
pub const ESTIMATOR_FORMAT_TAG: &str = "photomat-estimator";
/// Manifest version this build reads and writes.
pub const ESTIMATOR_FORMAT_VERSION: u32 = 1;

/// Contents of `estimator.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EstimatorManifest {
    /// Always [`ESTIMATOR_FORMAT_TAG`].
    pub format: String,
    /// [`ESTIMATOR_FORMAT_VERSION`] when written by this build.
    pub version: u32,
    /// Canonical spec of the BRDF model E decodes into.
    pub brdf: String,
    /// Architecture of E.
    pub architecture: EstimatorConfig,
    /// Where the weights come from (free-form JSON; `null` for untrained models).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// E with its parameters and the BRDF model it decodes into.
#[derive(Clone)]
pub struct EstimatorModel {
    brdf: Brdf,
    vars: VarMap,
    estimator: Estimator,
}

impl std::fmt::Debug for EstimatorModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EstimatorModel")
            .field("brdf", &self.brdf.name())
            .field("config", self.estimator.config())
            .finish_non_exhaustive()
    }
}

impl EstimatorModel {
    /// A new model for `brdf` with architecture `config` (whose `out_channels` must equal
    /// `brdf.channels()`), parameters initialised by candle's default initialisers in f32 on
    /// `device`; or over `vars` that already hold them.
    pub fn new(brdf: Brdf, config: EstimatorConfig, vars: VarMap, device: &Device) -> Result<Self> {
        if config.out_channels != brdf.channels() {
            return Err(Error::Invalid(format!(
                "estimator architecture outputs {} channels but BRDF model '{}' takes {}",
                config.out_channels,
                brdf.name(),
                brdf.channels()
            )));
        }
        let estimator = Estimator::new(config, VarBuilder::from_varmap(&vars, DType::F32, device))?;
        Ok(Self {
            brdf,
            vars,
            estimator,
        })
    }

    /// A new model like [`EstimatorModel::new`] whose initial parameters are drawn from
    /// `seed` (the reference initialisers, values from a SplitMix64 stream per variable name,
    /// [`photomat_generator::seeded_var_builder`]): the same seed gives the same model on
    /// every machine, which makes training runs reproducible.
    pub fn new_seeded(
        brdf: Brdf,
        config: EstimatorConfig,
        seed: u64,
        device: &Device,
    ) -> Result<Self> {
        let vars = VarMap::new();
        // Creates every variable with its seeded value; `new` then finds them in `vars`.
        Estimator::new(
            config.clone(),
            photomat_generator::seeded_var_builder(&vars, seed, DType::F32, device),
        )?;
        Self::new(brdf, config, vars, device)
    }

    /// Loads `dir/estimator.json` and `dir/estimator.safetensors` onto `device`, frozen (E over
    /// detached weights; `vars()` keeps the loaded variables).
    pub fn load(dir: &Path, device: &Device) -> Result<Self> {
        let manifest = read_estimator_manifest(dir)?;
        let brdf = photomat_core::lookup(&manifest.brdf).map_err(|e| {
            Error::file(
                dir.join(ESTIMATOR_MANIFEST_FILE),
                format!("the estimator's BRDF model cannot be built: {e}"),
            )
        })?;
        let weights = dir.join(ESTIMATOR_WEIGHTS_FILE);
        let vars = VarMap::new();
        let model = Self::new(brdf, manifest.architecture, vars, device)
            .map_err(|e| Error::file(dir.join(ESTIMATOR_MANIFEST_FILE), e.to_string()))?;
        load_vars_checked(&model.vars, &weights)?;
        // Frozen, as `GanModel::load`: a large material's intermediates are freed layer by
        // layer instead of living as long as the maps.
        let estimator = Estimator::new(
            model.estimator.config().clone(),
            photomat_train::varmap::frozen_var_builder(&model.vars, DType::F32, device),
        )?;
        Ok(Self { estimator, ..model })
    }

    /// Writes `estimator.safetensors` then `estimator.json` into `dir` (created if missing):
    /// a folder whose manifest exists is complete.
    pub fn save(&self, dir: &Path, provenance: serde_json::Value) -> Result<()> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::file(dir, format!("cannot create: {e}")))?;
        save_vars_atomic(&self.vars, &dir.join(ESTIMATOR_WEIGHTS_FILE))?;
        let manifest = EstimatorManifest {
            format: ESTIMATOR_FORMAT_TAG.into(),
            version: ESTIMATOR_FORMAT_VERSION,
            brdf: self.brdf.name(),
            architecture: self.estimator.config().clone(),
            provenance,
        };
        let json = serde_json::to_vec_pretty(&manifest)
            .map_err(|e| Error::Invalid(format!("estimator manifest: {e}")))?;
        write_atomic(&dir.join(ESTIMATOR_MANIFEST_FILE), &json)
    }

    /// The BRDF model E decodes into.
    pub fn brdf(&self) -> &Brdf {
        &self.brdf
    }

    /// E.
    pub fn estimator(&self) -> &Estimator {
        &self.estimator
    }

    /// E's parameters.
    pub fn vars(&self) -> &VarMap {
        &self.vars
    }

    /// Parameter maps of the BRDF for neural materials `features`.
    ///
    /// # Shapes
    /// (B, in_channels, H, W) → one (B, channels, H, W) map per `ParamSpec`.
    pub fn estimate(&self, features: &Tensor) -> Result<MaterialMaps> {
        self.estimator.estimate(features, self.brdf.as_ref())
    }
}

/// Reads and checks `dir/estimator.json`; errors name the file and the problem.
pub fn read_estimator_manifest(dir: &Path) -> Result<EstimatorManifest> {
    let path = dir.join(ESTIMATOR_MANIFEST_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| {
        Error::file(
            &path,
            format!("cannot read the estimator manifest ({e}); is this a `photomat train-estimator` output folder?"),
        )
    })?;
    let manifest: EstimatorManifest = serde_json::from_str(&text)
        .map_err(|e| Error::file(&path, format!("not an estimator manifest: {e}")))?;
    if manifest.format != ESTIMATOR_FORMAT_TAG {
        return Err(Error::file(
            &path,
            format!(
                "format is `{}`, expected `{ESTIMATOR_FORMAT_TAG}`",
                manifest.format
            ),
        ));
    }
    if manifest.version != ESTIMATOR_FORMAT_VERSION {
        return Err(Error::file(
            &path,
            format!(
                "format version {} is not supported (this build reads {ESTIMATOR_FORMAT_VERSION})",
                manifest.version
            ),
        ));
    }
    manifest
        .architecture
        .validate()
        .map_err(|e| Error::file(&path, format!("invalid architecture: {e}")))?;
    Ok(manifest)
}

#[cfg(test)]
mod tests {
    use super::*;
    use photomat_brdfs as _;

    fn small(n: usize) -> EstimatorConfig {
        EstimatorConfig {
            in_channels: 4,
            encoder_channels: vec![4, 8],
            decoder_channels: vec![4],
            out_channels: n,
            ..Default::default()
        }
    }

    #[test]
    fn save_load_round_trip_gives_identical_maps() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        let brdf = photomat_core::lookup("height(ggx)")?;
        let n = brdf.channels();
        let model = EstimatorModel::new(brdf, small(n), VarMap::new(), &Device::Cpu)?;
        model.save(dir.path(), serde_json::json!({"steps": 1}))?;
        let loaded = EstimatorModel::load(dir.path(), &Device::Cpu)?;
        assert_eq!(loaded.brdf().name(), "height(ggx, scale=0.02)");
        let f = Tensor::randn(0f32, 1., (1, 4, 8, 8), &Device::Cpu)?;
        let a = model.estimator().forward(&f)?;
        let b = loaded.estimator().forward(&f)?;
        assert_eq!((a - b)?.abs()?.max_all()?.to_scalar::<f32>()?, 0.0);
        Ok(())
    }

    #[test]
    fn wrong_width_and_unknown_brdf_are_reported() -> anyhow::Result<()> {
        let brdf = photomat_core::lookup("lambert")?;
        let err = EstimatorModel::new(brdf, small(8), VarMap::new(), &Device::Cpu).unwrap_err();
        assert!(err.to_string().contains("lambert"), "{err}");

        let dir = tempfile::tempdir()?;
        let ggx = photomat_core::lookup("ggx")?;
        let n = ggx.channels();
        EstimatorModel::new(ggx, small(n), VarMap::new(), &Device::Cpu)?
            .save(dir.path(), serde_json::Value::Null)?;
        let mut manifest = read_estimator_manifest(dir.path())?;
        manifest.brdf = "no_such_model".into();
        std::fs::write(
            dir.path().join(ESTIMATOR_MANIFEST_FILE),
            serde_json::to_vec(&manifest)?,
        )?;
        let err = EstimatorModel::load(dir.path(), &Device::Cpu)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("estimator.json") && err.contains("no_such_model"),
            "{err}"
        );
        Ok(())
    }
}
