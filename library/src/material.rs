//! A library material on disk (docs/data.md, "What the importer writes"): two photomat
//! material folders of the same surface,
//!
//! - `ggx/`: the `ggx` maps with the artist's normal map (diffuse, specular, roughness,
//!   normal), what flash photos of the material are rendered with and what the independent
//!   renderer's test photos use;
//! - `height/`: the `height(ggx, scale=S)` maps, the normal map's periodic integral as the
//!   height (diffuse, specular, roughness, height), what relief priors and estimators of
//!   height models are trained and measured against;
//!
//! both with the material's texel size (world units, the material spanning one photo's square)
//! and its provenance ([`Provenance`], the manifests' `source`). Maps are 16-bit PNG only
//! (the sources are 8-bit images; a constant map is a value in the manifest).

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use photomat_core::image_io::PlanarImage;
use photomat_core::map_files::{LoadedMaterial, SaveOptions, load_maps, save_maps};
use photomat_core::{Brdf, MaterialMaps, Result, lookup};
use serde::{Deserialize, Serialize};

use crate::convert::{MaterialImages, RoughnessSource};
use crate::normals::GreenConvention;
use crate::pairing::{Scheme, TextureSet};

/// The folder of the `ggx` maps inside a material's folder.
pub const GGX_FOLDER: &str = "ggx";
/// The folder of the `height(ggx, scale=S)` maps inside a material's folder.
pub const HEIGHT_FOLDER: &str = "height";

/// One source file of a material and its licence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceFileRecord {
    /// Tree path in the package (`usr/share/games/redeclipse/data/trak/trak5/wall4a.jpg`).
    pub path: String,
    /// The `License:` of the package's copyright file for it (`unknown` without one).
    pub licence: String,
    /// Its `Copyright:` holders.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub holders: Vec<String>,
}

/// Where a library material came from and how it was read: every manifest's `source`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    pub package: String,
    pub version: String,
    /// How the files were paired, and by which file.
    pub scheme: Scheme,
    pub defined_in: String,
    /// The files, by role (`base`, `normal`, `specular`, `gloss`, `roughness`, `height`).
    pub files: Vec<(String, SourceFileRecord)>,
    /// The licences of the files, each once, sorted.
    pub licences: Vec<String>,
    /// How the normal map's green channel was read.
    pub green: GreenConvention,
    pub roughness: RoughnessSource,
    /// Whether a specular map gave the F0's pattern.
    pub specular_map: bool,
    /// The engine's normal strength applied to the slopes, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal_strength: Option<f64>,
}

impl Provenance {
    /// The provenance of `set` from a package: `licence_of` gives each file's licence.
    pub fn new(
        package: &crate::package::Package,
        set: &TextureSet,
        images: &MaterialImages,
        licence_of: &dyn Fn(&str) -> SourceFileRecord,
    ) -> Self {
        let roles = [
            ("base", Some(&set.base)),
            ("normal", set.normal.as_ref()),
            ("specular", set.specular.as_ref()),
            ("gloss", set.gloss.as_ref()),
            ("roughness", set.roughness.as_ref()),
            ("height", set.height.as_ref()),
        ];
        let files: Vec<(String, SourceFileRecord)> = roles
            .into_iter()
            .filter_map(|(role, path)| Some((role.to_string(), licence_of(path?))))
            .collect();
        let mut licences: Vec<String> = files.iter().map(|(_, f)| f.licence.clone()).collect();
        licences.sort();
        licences.dedup();
        Self {
            package: package.name.clone(),
            version: package.version.clone(),
            scheme: set.scheme,
            defined_in: set.defined_in.clone(),
            files,
            licences,
            green: images.green,
            roughness: images.roughness_source,
            specular_map: images.specular_map,
            normal_strength: set.normal_strength,
        }
    }
}

/// A planar image as a (1, C, N, N) tensor on the CPU.
fn tensor(image: &PlanarImage) -> Result<Tensor> {
    image.to_tensor(&Device::Cpu)
}

/// The `ggx` model and maps of `images`.
pub fn ggx_maps(images: &MaterialImages) -> Result<(Brdf, MaterialMaps)> {
    let maps = MaterialMaps::new()
        .with("diffuse", tensor(&images.diffuse)?)
        .with("specular", tensor(&images.specular)?)
        .with("roughness", tensor(&images.roughness)?)
        .with("normal", tensor(&images.normal)?)
        .with_texel_size(Some(images.texel_size));
    Ok((lookup("ggx")?, maps))
}

/// The `height(ggx, scale=S)` model and maps of `images` (S: the height map's scale).
pub fn height_maps(images: &MaterialImages) -> Result<(Brdf, MaterialMaps)> {
    let n = images.side();
    let height = PlanarImage::new(1, n, n, images.height.values.clone())?;
    let maps = MaterialMaps::new()
        .with("diffuse", tensor(&images.diffuse)?)
        .with("specular", tensor(&images.specular)?)
        .with("roughness", tensor(&images.roughness)?)
        .with("height", tensor(&height)?)
        .with_texel_size(Some(images.texel_size));
    let spec = format!("height(ggx, scale={})", images.height.scale);
    Ok((lookup(&spec)?, maps))
}

/// Writes the two folders of a material into `dir` (module docs); returns the bytes written.
pub fn write_material(dir: &Path, images: &MaterialImages, provenance: &Provenance) -> Result<u64> {
    let options = SaveOptions {
        compact: true,
        png_only: true,
        source: Some(serde_json::to_value(provenance).map_err(|e| {
            photomat_core::Error::Invalid(format!("cannot record the provenance: {e}"))
        })?),
        ..SaveOptions::default()
    };
    let (ggx, maps) = ggx_maps(images)?;
    let mut bytes = save_maps(&dir.join(GGX_FOLDER), ggx.as_ref(), &maps, &options)?;
    let (height, maps) = height_maps(images)?;
    bytes += save_maps(&dir.join(HEIGHT_FOLDER), height.as_ref(), &maps, &options)?;
    Ok(bytes)
}

/// A library material's two folders, by their paths.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MaterialFolders {
    pub ggx: PathBuf,
    pub height: PathBuf,
}

impl MaterialFolders {
    /// The folders of the material at `dir`.
    pub fn of(dir: &Path) -> Self {
        Self {
            ggx: dir.join(GGX_FOLDER),
            height: dir.join(HEIGHT_FOLDER),
        }
    }

    /// Loads the `ggx` maps (the artist's normals).
    pub fn load_ggx(&self) -> Result<LoadedMaterial> {
        load_maps(&self.ggx, None)
    }

    /// Loads the `height(ggx, scale=S)` maps.
    pub fn load_height(&self) -> Result<LoadedMaterial> {
        load_maps(&self.height, None)
    }
}
