//! A trained relightable generator on disk: the inference half of a `photomat train-gan` run,
//! everything later stages need (the estimator's training, `photomat relight`, `photomat
//! sample`) and nothing of the optimiser.
//!
//! A GAN model folder holds two files, each written atomically (temporary file + rename, so
//! an interrupted save leaves the previous version intact):
//! - [`GAN_MANIFEST_FILE`] (`gan.json`): format tag, version, the architecture
//!   ([`GeneratorConfig`]) and free-form provenance written by whoever saved it (training
//!   step, kimg, data set, seed);
//! - [`GAN_WEIGHTS_FILE`] (`gan.safetensors`): G — the EMA copy when it comes from training —
//!   under the prefix `g.` (including the tracked `g.mapping.w_avg`) and M under `m.`.
//!
//! Loading checks the manifest's tag and version and then the weights against the
//! architecture ([`crate::load_checkpoint`]): a folder of another architecture fails with the
//! mismatching tensor named.

use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Result, Tensor, bail};
use candle_nn::{VarBuilder, VarMap};
use photomat_core::image_io::write_atomic;
use serde::{Deserialize, Serialize};

use crate::{
    Generator, GeneratorConfig, NoiseInput, Relight, load_checkpoint, save_checkpoint,
    seeded_var_builder,
};

/// Manifest file of a GAN model folder.
pub const GAN_MANIFEST_FILE: &str = "gan.json";
/// Weights file of a GAN model folder.
pub const GAN_WEIGHTS_FILE: &str = "gan.safetensors";
/// `format` tag of the manifest.
pub const GAN_FORMAT_TAG: &str = "photomat-gan";
/// Manifest version this build reads and writes.
pub const GAN_FORMAT_VERSION: u32 = 1;
/// Prefix of G's parameters in the weights file.
pub const G_PREFIX: &str = "g";
/// Prefix of M's parameters in the weights file.
pub const M_PREFIX: &str = "m";

/// Contents of `gan.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GanManifest {
    /// Always [`GAN_FORMAT_TAG`].
    pub format: String,
    /// [`GAN_FORMAT_VERSION`] when written by this build.
    pub version: u32,
    /// Architecture of G and M.
    pub architecture: GeneratorConfig,
    /// Where the weights come from (free-form JSON; `null` for untrained models).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// G and M with their parameters: a neural-material generator ready for inference.
#[derive(Clone)]
pub struct GanModel {
    config: GeneratorConfig,
    vars: VarMap,
    generator: Generator,
    relight: Relight,
    device: Device,
}

impl std::fmt::Debug for GanModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GanModel")
            .field("config", &self.config)
            .field("device", &self.device)
            .finish_non_exhaustive()
    }
}

impl GanModel {
    /// An untrained model of `config` whose parameters are drawn from `seed`
    /// ([`seeded_var_builder`]), in f32 on `device`.
    pub fn new(config: &GeneratorConfig, seed: u64, device: &Device) -> Result<Self> {
        config.validate()?;
        let vars = VarMap::new();
        let vb = seeded_var_builder(&vars, seed, DType::F32, device);
        Self::from_var_builder(config, vars, vb, device)
    }

    /// The model over existing variables: `vars` must hold (or will receive) G under `g.` and
    /// M under `m.`. Used by the trainer to wrap its EMA copy of G and its M.
    pub fn from_vars(config: &GeneratorConfig, vars: VarMap, device: &Device) -> Result<Self> {
        config.validate()?;
        let vb = VarBuilder::from_varmap(&vars, DType::F32, device);
        Self::from_var_builder(config, vars, vb, device)
    }

    fn from_var_builder(
        config: &GeneratorConfig,
        vars: VarMap,
        vb: VarBuilder,
        device: &Device,
    ) -> Result<Self> {
        let generator = Generator::new(config, vb.pp(G_PREFIX))?;
        let relight = Relight::new(config, vb.pp(M_PREFIX))?;
        Ok(Self {
            config: config.clone(),
            vars,
            generator,
            relight,
            device: device.clone(),
        })
    }

    /// Loads a GAN model folder (see the module docs) onto `device`, frozen: G and M are
    /// built over detached copies of the loaded weights
    /// ([`photomat_train::varmap::frozen_var_builder`]), so that a large material's
    /// intermediates are freed layer by layer. `vars()` still holds the loaded variables (for
    /// `save`).
    pub fn load(dir: &Path, device: &Device) -> Result<Self> {
        let manifest = read_gan_manifest(dir)?;
        let config = &manifest.architecture;
        let model = Self::new(config, 0, device)?;
        load_checkpoint(&model.vars, dir.join(GAN_WEIGHTS_FILE))?;
        let vb = photomat_train::varmap::frozen_var_builder(&model.vars, DType::F32, device);
        Self::from_var_builder(config, model.vars, vb, device)
    }

    /// Writes the model folder `dir` (created if missing) with `provenance` in its manifest.
    /// Weights first, manifest last: a folder whose manifest exists is complete.
    pub fn save(&self, dir: &Path, provenance: serde_json::Value) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| {
            candle_core::Error::msg(format!("cannot create {}: {e}", dir.display()))
        })?;
        save_checkpoint(&self.vars, dir.join(GAN_WEIGHTS_FILE))?;
        let manifest = GanManifest {
            format: GAN_FORMAT_TAG.into(),
            version: GAN_FORMAT_VERSION,
            architecture: self.config.clone(),
            provenance,
        };
        let json = serde_json::to_vec_pretty(&manifest).map_err(candle_core::Error::wrap)?;
        write_atomic(&dir.join(GAN_MANIFEST_FILE), &json).map_err(candle_core::Error::wrap)
    }

    /// The architecture.
    pub fn config(&self) -> &GeneratorConfig {
        &self.config
    }

    /// The parameters (G under `g.`, M under `m.`).
    pub fn vars(&self) -> &VarMap {
        &self.vars
    }

    /// G.
    pub fn generator(&self) -> &Generator {
        &self.generator
    }

    /// M.
    pub fn relight(&self) -> &Relight {
        &self.relight
    }

    /// The device the parameters live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The latent codes of `seeds`, one row each: z ~ N(0, I) drawn from a SplitMix64 stream
    /// per seed, so that a seed names the same material on every machine.
    ///
    /// # Shapes
    /// → (seeds.len(), latent_dim), f32.
    pub fn latents(&self, seeds: &[u64]) -> Result<Tensor> {
        let d = self.config.latent_dim;
        let values: Vec<f32> = seeds
            .iter()
            .flat_map(|&s| photomat_core::rng::SplitMix64(s).normals(d))
            .map(|v| v as f32)
            .collect();
        Tensor::from_vec(values, (seeds.len(), d), &self.device)
    }

    /// Noise images for every synthesis layer, drawn per seed like [`GanModel::latents`]
    /// (from a stream distinct from z's), in the order [`NoiseInput::Given`] expects.
    ///
    /// # Shapes
    /// → one (seeds.len(), 1, r, r) tensor per noise layer.
    pub fn noise_images(&self, seeds: &[u64]) -> Result<Vec<Tensor>> {
        self.noise_images_at(seeds, self.config.resolution)
    }

    /// [`GanModel::noise_images`] for an F of side `size` ([`GeneratorConfig::cells_for`]:
    /// any multiple of the cell size for a spatial G, R only otherwise); at `size` = R the
    /// same images as [`GanModel::noise_images`].
    ///
    /// # Shapes
    /// → one (seeds.len(), 1, s, s) tensor per noise layer ([`crate::Synthesis::noise_shapes_at`]).
    pub fn noise_images_at(&self, seeds: &[u64], size: usize) -> Result<Vec<Tensor>> {
        let shapes = self
            .generator
            .synthesis()
            .noise_shapes_at(seeds.len(), size)?;
        let mut streams: Vec<_> = seeds
            .iter()
            .map(|&s| photomat_core::rng::SplitMix64(s ^ NOISE_STREAM_KEY))
            .collect();
        shapes
            .iter()
            .map(|&(b, c, h, w)| {
                let values: Vec<f32> = streams
                    .iter_mut()
                    .flat_map(|rng| rng.normals(c * h * w))
                    .map(|v| v as f32)
                    .collect();
                Tensor::from_vec(values, (b, c, h, w), &self.device)
            })
            .collect()
    }

    /// The local latent fields of a spatial G for an F of side `size`, i.i.d. N(0, 1) per
    /// seed from a stream distinct from z's and the noise's. Errors for the fixed-size G and
    /// for sides that are not a multiple of the cell size.
    ///
    /// # Shapes
    /// → (seeds.len(), local_dim, n, n), n = size / cell size, f32.
    pub fn local_fields(&self, seeds: &[u64], size: usize) -> Result<Tensor> {
        let (b, c, h, w) = self.generator.synthesis().field_shape(seeds.len(), size)?;
        let values: Vec<f32> = seeds
            .iter()
            .flat_map(|&s| photomat_core::rng::SplitMix64(s ^ FIELD_STREAM_KEY).normals(c * h * w))
            .map(|v| v as f32)
            .collect();
        Tensor::from_vec(values, (b, c, h, w), &self.device)
    }

    /// The neural materials of `seeds` with truncation ψ (1 = none) and the seeds' own noise:
    /// deterministic per seed.
    ///
    /// # Shapes
    /// → (seeds.len(), feature_channels, R, R).
    pub fn features_for_seeds(&self, seeds: &[u64], psi: f64) -> Result<Tensor> {
        self.features_for_seeds_at(seeds, psi, self.config.resolution)
    }

    /// The neural materials of `seeds` at side `size` (a spatial G: any multiple of
    /// [`GeneratorConfig::cell_size`]; the fixed-size G: R only, with an error naming the
    /// possible sizes otherwise), from the seeds' own z, local field and noise: deterministic
    /// per seed and size.
    ///
    /// # Shapes
    /// → (seeds.len(), feature_channels, size, size).
    pub fn features_for_seeds_at(&self, seeds: &[u64], psi: f64, size: usize) -> Result<Tensor> {
        let z = self.latents(seeds)?;
        let noise = self.noise_images_at(seeds, size)?;
        let noise = NoiseInput::Given(&noise);
        if self.generator.synthesis().is_spatial() {
            let field = self.local_fields(seeds, size)?;
            self.generator.forward_field(&z, &field, psi, &noise)
        } else {
            self.generator.forward(&z, psi, &noise)
        }
    }
}

/// Key mixed into a seed for its noise images, so that z and the noise are different streams.
const NOISE_STREAM_KEY: u64 = 0x6E6F_6973_655F_696D; // "noise_im"
/// Key mixed into a seed for its local latent field (spatial G).
const FIELD_STREAM_KEY: u64 = 0x6C6F_6361_6C5F_6669; // "local_fi"

/// Copies the GAN model folder `from` (`gan.json` + `gan.safetensors`) into `to` (created if
/// missing; atomically each, weights first, so that a folder whose manifest exists is
/// complete), unless both name the same folder.
pub fn copy_gan_model(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to)
        .map_err(|e| candle_core::Error::msg(format!("cannot create {}: {e}", to.display())))?;
    let same = match (from.canonicalize(), to.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        return Ok(());
    }
    for name in [GAN_WEIGHTS_FILE, GAN_MANIFEST_FILE] {
        let source = from.join(name);
        let bytes = std::fs::read(&source).map_err(|e| {
            candle_core::Error::msg(format!(
                "{}: cannot read the GAN model: {e}",
                source.display()
            ))
        })?;
        write_atomic(&to.join(name), &bytes).map_err(candle_core::Error::wrap)?;
    }
    Ok(())
}

/// Reads and checks `dir/gan.json`; errors name the file and the problem.
pub fn read_gan_manifest(dir: &Path) -> Result<GanManifest> {
    let path: PathBuf = dir.join(GAN_MANIFEST_FILE);
    let text = std::fs::read_to_string(&path).map_err(|e| {
        candle_core::Error::msg(format!(
            "{}: cannot read the GAN manifest ({e}); is {} a `photomat train-gan` output folder?",
            path.display(),
            dir.display()
        ))
    })?;
    let manifest: GanManifest = serde_json::from_str(&text).map_err(|e| {
        candle_core::Error::msg(format!("{}: not a GAN manifest: {e}", path.display()))
    })?;
    if manifest.format != GAN_FORMAT_TAG {
        bail!(
            "{}: format is `{}`, expected `{GAN_FORMAT_TAG}`",
            path.display(),
            manifest.format
        );
    }
    if manifest.version != GAN_FORMAT_VERSION {
        bail!(
            "{}: format version {} is not supported by this build (reads version {GAN_FORMAT_VERSION})",
            path.display(),
            manifest.version
        );
    }
    manifest.architecture.validate().map_err(|e| {
        candle_core::Error::msg(format!("{}: invalid architecture: {e}", path.display()))
    })?;
    Ok(manifest)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> GeneratorConfig {
        GeneratorConfig {
            resolution: 32,
            channel_multiplier: 1.0 / 64.0,
            latent_dim: 16,
            feature_channels: 8,
            relight_hidden: 8,
            ..Default::default()
        }
    }

    #[test]
    fn save_load_round_trip_gives_identical_features() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        let model = GanModel::new(&tiny(), 7, &Device::Cpu)?;
        model.save(dir.path(), serde_json::json!({"step": 3}))?;
        let loaded = GanModel::load(dir.path(), &Device::Cpu)?;
        assert_eq!(loaded.config(), model.config());
        let a = model.features_for_seeds(&[1, 2], 1.0)?;
        let b = loaded.features_for_seeds(&[1, 2], 1.0)?;
        let diff = (a - b)?.abs()?.max_all()?.to_scalar::<f32>()?;
        assert_eq!(diff, 0.0);
        assert_eq!(read_gan_manifest(dir.path())?.provenance["step"], 3);
        Ok(())
    }

    #[test]
    fn seeds_name_materials() -> anyhow::Result<()> {
        let model = GanModel::new(&tiny(), 7, &Device::Cpu)?;
        let z = model.latents(&[5, 6, 5])?.to_vec2::<f32>()?;
        assert_eq!(z[0], z[2]);
        assert_ne!(z[0], z[1]);
        let mean = z[1].iter().sum::<f32>() / z[1].len() as f32;
        assert!(mean.abs() < 0.75, "z of seed 6 has mean {mean}");
        Ok(())
    }

    #[test]
    fn loading_another_architecture_names_the_mismatch() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        GanModel::new(&tiny(), 7, &Device::Cpu)?.save(dir.path(), serde_json::Value::Null)?;
        // Swap the manifest for a wider architecture: the weights no longer fit.
        let mut manifest = read_gan_manifest(dir.path())?;
        manifest.architecture.channel_multiplier = 1.0 / 32.0;
        std::fs::write(
            dir.path().join(GAN_MANIFEST_FILE),
            serde_json::to_vec(&manifest)?,
        )?;
        let err = GanModel::load(dir.path(), &Device::Cpu)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("does not match") && err.contains("g.synthesis"),
            "{err}"
        );
        Ok(())
    }

    #[test]
    fn a_folder_without_manifest_is_reported_by_path() {
        let dir = tempfile::tempdir().unwrap();
        let err = GanModel::load(dir.path(), &Device::Cpu)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("gan.json") && err.contains("train-gan"),
            "{err}"
        );
    }

    #[test]
    fn an_oversized_architecture_is_refused_before_any_allocation() -> anyhow::Result<()> {
        let dir = tempfile::tempdir()?;
        GanModel::new(&tiny(), 7, &Device::Cpu)?.save(dir.path(), serde_json::Value::Null)?;
        let path = dir.path().join(GAN_MANIFEST_FILE);
        let original: serde_json::Value = serde_json::from_slice(&std::fs::read(&path)?)?;
        // Each would ask for terabytes if it reached the weight allocation.
        for (field, value) in [
            ("latent_dim", serde_json::json!(1_000_000_000u64)),
            ("relight_hidden", serde_json::json!(1_000_000)),
            ("channel_multiplier", serde_json::json!(1e6)),
            ("feature_channels", serde_json::json!(100_000)),
        ] {
            let mut manifest = original.clone();
            manifest["architecture"][field] = value;
            std::fs::write(&path, serde_json::to_vec(&manifest)?)?;
            let err = GanModel::load(dir.path(), &Device::Cpu)
                .unwrap_err()
                .to_string();
            let name = field.replace('_', " ");
            assert!(
                err.contains("gan.json")
                    && (err.contains(field) || err.contains(&name))
                    && err.contains("limit"),
                "{field}: {err}"
            );
        }
        Ok(())
    }

    #[test]
    fn without_noise_inputs_the_noise_changes_nothing() -> anyhow::Result<()> {
        use crate::NoiseInput;
        let features = |noise_inputs: bool| -> anyhow::Result<(Tensor, Tensor)> {
            let config = GeneratorConfig {
                noise_inputs,
                ..tiny()
            };
            let model = GanModel::new(&config, 7, &Device::Cpu)?;
            // Fresh strengths are 0; give every layer's noise a visible weight.
            for (name, var) in model.vars().data().lock().unwrap().iter() {
                if name.ends_with("noise_strength") {
                    var.set(&var.as_tensor().ones_like()?)?;
                }
            }
            let z = model.latents(&[3])?;
            let g = model.generator();
            Ok((
                g.forward(&z, 1.0, &NoiseInput::Random)?,
                g.forward(&z, 1.0, &NoiseInput::Random)?,
            ))
        };
        let diff = |(a, b): (Tensor, Tensor)| -> anyhow::Result<f32> {
            Ok((a - b)?.abs()?.max_all()?.to_scalar::<f32>()?)
        };
        assert!(diff(features(true)?)? > 1e-3);
        assert_eq!(diff(features(false)?)?, 0.0);
        // gan.json keeps the option only when it is off, so older files read as before.
        let json = |on: bool| {
            serde_json::to_value(GeneratorConfig {
                noise_inputs: on,
                ..tiny()
            })
        };
        assert!(json(true)?.get("noise_inputs").is_none());
        assert_eq!(json(false)?["noise_inputs"], false);
        let back: GeneratorConfig = serde_json::from_value(json(false)?)?;
        assert!(!back.noise_inputs);
        Ok(())
    }
}
