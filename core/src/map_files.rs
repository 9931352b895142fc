//! The material-map folder: one material's parameter maps on disk, readable by people (PNG),
//! exact for programs (EXR) and self-describing (a JSON manifest).
//!
//! A folder written by [`save_maps`] holds:
//!
//! - `material.json` ([`MANIFEST_FILE`], a [`MapManifest`]): format tag and version, the model's
//!   canonical specification (`DifferentiableBrdf::name()`, e.g. `height(ggx, scale=0.02)`),
//!   the outermost model's scalar arguments, the resolution R and, per map, its name, channel
//!   count, file names, PNG bit depth, colour space and physical range.
//! - `<map>.exr`: float32 physical values, channels `Y` (1), `R G B` (3) or `C00 C01 …`
//!   (other counts; see [`crate::image_io`]). **Authoritative** when the manifest names it.
//! - `<map>.png` (1- and 3-channel maps): the map for people and image editors, 16-bit by
//!   default, 8-bit with [`PngBits::Eight`]; grey for 1 channel, RGB for 3. Stored values follow
//!   the map's [`ColorSpace`]: albedos `x^(1/2.2)`, roughness/height as they are, normals
//!   `0.5·n + 0.5`. Values outside what the colour space can hold (e.g. a `Linear` map whose
//!   spec range exceeds [0, 1]) are clamped in the PNG only; the EXR keeps them.
//!
//! With [`SaveOptions::compact`] (what `photomat sample --simplify` writes, [`crate::simplify`])
//! a map whose texels are all exactly equal is stored as `"value": [one number per channel]`
//! in its manifest entry, with no file, and a 3-channel map with exactly equal channels as
//! one-channel files marked `"grey": true`; loading expands both back to (1, C, R, R) exactly.
//!
//! Loading ([`load_maps`]) reads the EXR of every map when the manifest names one and falls back
//! to the PNG otherwise (so a hand-made folder of PNGs, or one whose `exr` entries were removed
//! after editing the PNGs, loads too); PNG normals are renormalised after decoding. Every file
//! the manifest names must exist; the PNG beside an EXR is checked for size and channel count
//! from its header. Values must be finite and inside the model's spec ranges up to
//! [`RANGE_TOLERANCE`]. Every problem is an [`Error::File`] naming the offending file.
//!
//! All files are written atomically ([`crate::image_io::write_atomic`]), maps first and the
//! manifest last, so a folder with a manifest never refers to half-written maps.
//!
//! # Shapes
//! [`save_maps`] takes maps of shape (1, C, R, R) (one material, square, any float dtype and
//! device); [`load_maps`] returns (1, C, R, R) f32 maps on the CPU.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use candle_core::{DType, Device};

use crate::brdf::{Brdf, DifferentiableBrdf};
use crate::image_io::{
    PlanarImage, encode_exr, encode_png, png_header, read_exr, read_png, write_atomic,
};
use crate::maps::MaterialMaps;
use crate::param::{ColorSpace, ParamSpec};
use crate::plugin_spec::{ArgValue, PluginSpec};
use crate::registry::lookup;
use crate::simplify::{constant_value, is_grey};
use crate::{Error, Result};

pub use crate::image_io::PngBits;

/// File name of the manifest inside a material folder.
pub const MANIFEST_FILE: &str = "material.json";

/// Value of the manifest's `format` field.
pub const FORMAT_TAG: &str = "photomat-material";

/// Manifest version this build writes and the newest it reads.
pub const FORMAT_VERSION: u32 = 1;

/// Allowed excess over a spec range when checking maps: f32 arithmetic that produced the maps
/// (normalising a normal, `lo + (hi−lo)·t`) overshoots a unit-scale bound by a few ulps
/// (~1e-7); 1e-4 is far above that and far below any visible parameter change.
pub const RANGE_TOLERANCE: f32 = 1e-4;

/// Shortest decoded PNG normal that is renormalised rather than rejected: quantised unit vectors
/// have length 1 ± 3e-5 (half a 16-bit step per component); a vector shorter than 1e-3 (a 50 %
/// grey texel) carries no direction.
const MIN_PNG_NORMAL_LENGTH: f32 = 1e-3;

/// How [`save_maps`] writes the PNG files, and what else the manifest records.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SaveOptions {
    /// Bits per PNG channel (16 by default: linear maps such as roughness and height band
    /// visibly at 8 bits).
    pub png_bits: PngBits,
    /// How the model was chosen among several (`photomat sample --brdf auto`), recorded as
    /// the manifest's `selection`.
    pub selection: Option<serde_json::Value>,
    /// Store a map whose texels are exactly equal as its value in the manifest (no file), and
    /// a 3-channel map whose channels are exactly equal as a one-channel file
    /// ([`crate::simplify`] makes such maps). Off by default: every map gets its files.
    pub compact: bool,
    /// What [`crate::simplify::simplify`] did, recorded as the manifest's `simplification`.
    pub simplification: Option<serde_json::Value>,
    /// Where the maps came from (e.g. a material library's package, files and licences),
    /// recorded as the manifest's `source`.
    pub source: Option<serde_json::Value>,
    /// Write no EXR: every 1- and 3-channel map is stored as its PNG alone (what loading falls
    /// back to), for collections of maps whose sources were 8-bit images anyway, such as a
    /// material library. Maps of other channel counts still get their EXR.
    pub png_only: bool,
}

/// The `material.json` manifest.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapManifest {
    /// Always [`FORMAT_TAG`].
    pub format: String,
    /// Format version ([`FORMAT_VERSION`] when written by this build).
    pub version: u32,
    /// Canonical model specification: `lookup(brdf)` rebuilds the model.
    pub brdf: String,
    /// Scalar arguments of the outermost model (also spelled out in `brdf`, which wins; a
    /// manifest whose `args` disagree with `brdf` is rejected). Omitted when empty.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub args: BTreeMap<String, ArgValue>,
    /// Side R of the square maps, in texels.
    pub resolution: usize,
    /// World units per texel, for maps of a spatial model (`MaterialMaps::texel_size`: the
    /// same at every sample side, so derived normals keep their slope). Omitted for maps of
    /// the unit square (texel 1/R).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texel_size: Option<f64>,
    /// One entry per parameter map, in the model's channel order.
    pub maps: Vec<MapEntry>,
    /// How the model was chosen among candidates, when it was (the chooser's record: every
    /// candidate's error and cost, the tolerance). Informational; omitted otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub selection: Option<serde_json::Value>,
    /// Which maps were simplified to a constant or to grey, and the error that added
    /// ([`crate::simplify`]). Informational; omitted otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simplification: Option<serde_json::Value>,
    /// Where the maps came from, when the writer recorded it (a material library's package,
    /// source files, version and licences). Informational; omitted otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<serde_json::Value>,
}

/// One map of a [`MapManifest`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapEntry {
    /// Parameter name (`diffuse`, `roughness`, …).
    pub name: String,
    /// Channel count.
    pub channels: usize,
    /// PNG file name inside the folder (absent for channel counts a PNG cannot hold).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub png: Option<String>,
    /// Float32 EXR file name inside the folder (authoritative when present).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exr: Option<String>,
    /// Bits per channel of the PNG as written (informative: the file's own depth is decoded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub png_bits: Option<PngBits>,
    /// How the PNG stores the values.
    pub color_space: ColorSpace,
    /// Physical range `[lo, hi]` of the model's spec (informative: loading checks against the
    /// spec of the model that will use the maps).
    pub range: [f32; 2],
    /// A constant map: its physical value per channel, and then no file is named.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<Vec<f32>>,
    /// A grey 3-channel map: its files hold one channel, the value of all three.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub grey: bool,
}

impl MapEntry {
    /// Channels of the map's files: 1 for a grey map, its channel count otherwise.
    pub fn stored_channels(&self) -> usize {
        if self.grey { 1 } else { self.channels }
    }
}

/// A material read from a folder.
#[derive(Clone)]
pub struct LoadedMaterial {
    /// The model the maps were validated against (the override, or `lookup(manifest.brdf)`).
    pub brdf: Brdf,
    /// (1, C, R, R) f32 maps on the CPU, one per parameter of `brdf`.
    pub maps: MaterialMaps,
    /// The manifest as read.
    pub manifest: MapManifest,
}

/// Write `maps` of model `brdf` into the folder `dir` (created if missing): one EXR and, for
/// 1- and 3-channel maps, one PNG per map, then `material.json`, each atomically. With
/// [`SaveOptions::compact`] an exactly constant map is a value in the manifest instead, and an
/// exactly grey 3-channel map gets one-channel files. Files of the same names are replaced;
/// other files in the folder are left alone. Returns the bytes written (files and manifest).
///
/// The maps must fit the model's specs, be one material (batch 1), square, finite and inside
/// the spec ranges (up to [`RANGE_TOLERANCE`]): a folder this function writes always loads.
pub fn save_maps(
    dir: &Path,
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    options: &SaveOptions,
) -> Result<u64> {
    let folder = plan_folder(brdf, maps, options)?;
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::file(dir, format!("cannot create the material folder: {e}")))?;
    folder.encode_each(dir, &mut |name, bytes| write_atomic(&dir.join(name), bytes))
}

/// The bytes [`save_maps`] would write for these maps and options, computed in memory (how
/// much a simplification saves).
pub fn folder_bytes(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    options: &SaveOptions,
) -> Result<u64> {
    plan_folder(brdf, maps, options)?.encode_each(Path::new(""), &mut |_, _| Ok(()))
}

/// A material folder before encoding: the manifest and, per entry, the image its files hold
/// (`None` for a constant map).
struct PlannedFolder {
    manifest: MapManifest,
    images: Vec<Option<PlanarImage>>,
    png_bits: PngBits,
}

impl PlannedFolder {
    /// Encodes every file, maps first and the manifest last, handing each to `sink`; returns
    /// the total of their lengths. Errors name the file inside `dir`.
    fn encode_each(
        &self,
        dir: &Path,
        sink: &mut dyn FnMut(&str, &[u8]) -> Result<()>,
    ) -> Result<u64> {
        let mut total = 0u64;
        let mut put = |name: &str, bytes: std::result::Result<Vec<u8>, String>| -> Result<()> {
            let bytes = bytes.map_err(|e| Error::file(dir.join(name), e))?;
            total += bytes.len() as u64;
            sink(name, &bytes)
        };
        let text = |e: Error| e.to_string();
        for (entry, image) in self.manifest.maps.iter().zip(&self.images) {
            let Some(image) = image else { continue };
            if let Some(exr) = &entry.exr {
                put(exr, encode_exr(image).map_err(text))?;
            }
            if let Some(png) = &entry.png {
                let stored = image.map(|v| entry.color_space.to_stored(v));
                put(png, encode_png(&stored, self.png_bits).map_err(text))?;
            }
        }
        let manifest = serde_json::to_string_pretty(&self.manifest)
            .map(|t| format!("{t}\n").into_bytes())
            .map_err(|e| format!("cannot serialise the manifest: {e}"));
        put(MANIFEST_FILE, manifest)?;
        Ok(total)
    }
}

/// Checks the maps and decides every entry and file of their folder.
fn plan_folder(
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
    options: &SaveOptions,
) -> Result<PlannedFolder> {
    let model = brdf.name();
    let specs = brdf.params();
    maps.validate(&model, specs)?;
    let (batch, height, width) = maps.batch_and_size()?;
    if batch != 1 {
        return Err(Error::Invalid(format!(
            "save_maps writes one material, the maps hold a batch of {batch}: save each item \
             (map.narrow(0, i, 1)) into its own folder"
        )));
    }
    if height != width {
        return Err(Error::InvalidMaps {
            model,
            reason: format!("material maps must be square, got {height}×{width} (height×width)"),
        });
    }
    let mut entries = Vec::with_capacity(specs.len());
    let mut images = Vec::with_capacity(specs.len());
    for spec in specs {
        if !is_plain_file_stem(spec.name) {
            return Err(Error::InvalidMaps {
                model,
                reason: format!(
                    "map name '{}' cannot be a file name (use letters, digits, '_' and '-')",
                    spec.name
                ),
            });
        }
        let map = maps.get(spec.name)?;
        let image = PlanarImage::from_tensor(map)?;
        check_range(&image, spec).map_err(|reason| Error::InvalidMaps {
            model: model.clone(),
            reason: format!("map '{}' {reason}", spec.name),
        })?;
        let value = match options.compact {
            true => constant_value(map)?,
            false => None,
        };
        let grey = options.compact && value.is_none() && is_grey(map)?;
        let stored = if grey { 1 } else { spec.channels };
        let has_files = value.is_none();
        let png = (has_files && matches!(stored, 1 | 3)).then(|| format!("{}.png", spec.name));
        let exr = has_files && !(options.png_only && png.is_some());
        entries.push(MapEntry {
            name: spec.name.to_string(),
            channels: spec.channels,
            png_bits: png.as_ref().map(|_| options.png_bits),
            png,
            exr: exr.then(|| format!("{}.exr", spec.name)),
            color_space: spec.color_space,
            range: [spec.range.0, spec.range.1],
            value,
            grey,
        });
        images.push(has_files.then(|| match grey {
            true => image.first_channel(),
            false => image,
        }));
    }
    let manifest = MapManifest {
        format: FORMAT_TAG.to_string(),
        version: FORMAT_VERSION,
        args: PluginSpec::parse(&model)?.values.into_iter().collect(),
        brdf: model,
        resolution: height,
        texel_size: maps.texel_size(),
        maps: entries,
        selection: options.selection.clone(),
        simplification: options.simplification.clone(),
        source: options.source.clone(),
    };
    Ok(PlannedFolder {
        manifest,
        images,
        png_bits: options.png_bits,
    })
}

/// Read the material folder `dir`. The maps are validated against `brdf_override` when given
/// (only the maps it takes are read; the manifest must list each with the right channel
/// count), else against `lookup(manifest.brdf)` (the manifest must list exactly its maps).
pub fn load_maps(dir: &Path, brdf_override: Option<Brdf>) -> Result<LoadedMaterial> {
    let manifest_path = dir.join(MANIFEST_FILE);
    let manifest = read_manifest(&manifest_path)?;
    let in_manifest = |reason: String| Error::file(&manifest_path, reason);
    let overridden = brdf_override.is_some();
    let brdf = match brdf_override {
        Some(brdf) => brdf,
        None => lookup(&manifest.brdf).map_err(|e| in_manifest(format!("field 'brdf': {e}")))?,
    };
    let model = brdf.name();
    let listed = || {
        manifest
            .maps
            .iter()
            .map(|m| m.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    // An override may use a subset of the maps (render a `ggx` material as `lambert`); the
    // manifest's own model must take exactly the maps listed.
    let unexpected = manifest
        .maps
        .iter()
        .filter(|_| !overridden)
        .find(|m| !brdf.params().iter().any(|s| s.name == m.name));
    if let Some(extra) = unexpected {
        return Err(in_manifest(format!(
            "lists map '{}', which model '{model}' does not take (it takes: {})",
            extra.name,
            spec_names(brdf.params())
        )));
    }
    let mut maps = MaterialMaps::new().with_texel_size(manifest.texel_size);
    for spec in brdf.params() {
        let entry = manifest
            .maps
            .iter()
            .find(|m| m.name == spec.name)
            .ok_or_else(|| {
                in_manifest(format!(
                    "has no '{}' map, which model '{model}' needs (the manifest lists: {})",
                    spec.name,
                    listed()
                ))
            })?;
        if entry.channels != spec.channels {
            return Err(in_manifest(format!(
                "map '{}' has {} channel(s), model '{model}' needs {}",
                spec.name, entry.channels, spec.channels
            )));
        }
        let image = load_map(dir, entry, spec, manifest.resolution)?;
        maps.insert(spec.name, image.to_tensor(&Device::Cpu)?);
    }
    maps.validate(&model, brdf.params())?;
    debug_assert!(maps.iter().all(|(_, t)| t.dtype() == DType::F32));
    Ok(LoadedMaterial {
        brdf,
        maps,
        manifest,
    })
}

/// Read and check `material.json`: JSON, format tag, version, resolution, unique map names,
/// file names inside the folder, `args` consistent with `brdf`.
pub fn read_manifest(path: &Path) -> Result<MapManifest> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        let hint = if e.kind() == std::io::ErrorKind::NotFound {
            " (a material folder holds material.json next to its maps; is this the right folder?)"
        } else {
            ""
        };
        Error::file(
            path,
            format!("cannot read the material manifest: {e}{hint}"),
        )
    })?;
    let bad = |reason: String| Error::file(path, reason);
    let value: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| bad(format!("corrupt material manifest, not valid JSON: {e}")))?;
    match value.get("format").and_then(|f| f.as_str()) {
        Some(FORMAT_TAG) => {}
        other => {
            return Err(bad(format!(
                "not a photomat material manifest (field 'format' is {}, expected \"{FORMAT_TAG}\")",
                other.map_or("missing".to_string(), |f| format!("\"{f}\""))
            )));
        }
    }
    let version = value.get("version").and_then(|v| v.as_u64());
    if let Some(v) = version.filter(|&v| v > FORMAT_VERSION as u64) {
        return Err(bad(format!(
            "written by a newer photomat (format version {v}; this build reads up to {FORMAT_VERSION})"
        )));
    }
    // Parsed from the text again (not from `value`) so that errors carry line and column.
    let manifest: MapManifest =
        serde_json::from_str(&text).map_err(|e| bad(format!("corrupt material manifest: {e}")))?;
    if manifest.resolution == 0 {
        return Err(bad("field 'resolution' must be at least 1".into()));
    }
    if let Some(t) = manifest.texel_size
        && !(t.is_finite() && t > 0.0)
    {
        return Err(bad(format!(
            "field 'texel_size' must be a positive number of world units, got {t}"
        )));
    }
    let mut names = BTreeSet::new();
    for entry in &manifest.maps {
        if !names.insert(entry.name.as_str()) {
            return Err(bad(format!("map '{}' is listed twice", entry.name)));
        }
        let files = entry.png.is_some() || entry.exr.is_some();
        match &entry.value {
            None if !files => {
                return Err(bad(format!(
                    "map '{}' names neither a png nor an exr file, nor a constant 'value'",
                    entry.name
                )));
            }
            Some(_) if files => {
                return Err(bad(format!(
                    "map '{}' names files and a constant 'value'; keep one of them",
                    entry.name
                )));
            }
            Some(value) if value.len() != entry.channels => {
                return Err(bad(format!(
                    "map '{}': 'value' holds {} number(s) for {} channel(s)",
                    entry.name,
                    value.len(),
                    entry.channels
                )));
            }
            _ => {}
        }
        if entry.grey
            && (entry.channels != 3
                || entry.value.is_some()
                || entry.color_space == ColorSpace::UnitVector)
        {
            return Err(bad(format!(
                "map '{}': 'grey' (one-channel files for three equal channels) needs a \
                 3-channel map that is not a unit vector, stored in files",
                entry.name
            )));
        }
        for file in entry.png.iter().chain(&entry.exr) {
            if !is_plain_file_name(file) {
                return Err(bad(format!(
                    "map '{}': file '{file}' must be a plain file name inside the folder",
                    entry.name
                )));
            }
        }
    }
    let spec = PluginSpec::parse(&manifest.brdf).map_err(|e| bad(format!("field 'brdf': {e}")))?;
    if !manifest.args.is_empty() {
        // An unknown model is the problem to report, not its arguments.
        let known = crate::registry::registered_names()?;
        if !known.contains(&spec.name.as_str()) {
            return Err(bad(format!(
                "field 'brdf': unknown BRDF model '{}'; registered models: {}",
                spec.name,
                known.join(", ")
            )));
        }
    }
    let spelled: BTreeMap<String, ArgValue> = spec.values.into_iter().collect();
    if !manifest.args.is_empty() && manifest.args != spelled {
        return Err(bad(format!(
            "field 'args' {:?} disagrees with the arguments in brdf '{}'; edit the brdf string",
            manifest.args, manifest.brdf
        )));
    }
    Ok(manifest)
}

/// Read one map's authoritative file and check it; returns physical values.
fn load_map(
    dir: &Path,
    entry: &MapEntry,
    spec: &ParamSpec,
    resolution: usize,
) -> Result<PlanarImage> {
    if let Some(value) = &entry.value {
        let plane = resolution * resolution;
        let data = value
            .iter()
            .flat_map(|&v| std::iter::repeat_n(v, plane))
            .collect();
        let image = PlanarImage::new(entry.channels, resolution, resolution, data)?;
        let manifest = dir.join(MANIFEST_FILE);
        if value.iter().any(|v| !v.is_finite()) {
            return Err(Error::file(
                &manifest,
                format!("map '{}': 'value' {value:?} is not finite", entry.name),
            ));
        }
        check_range(&image, spec)
            .map_err(|reason| Error::file(&manifest, format!("map '{}' {reason}", spec.name)))?;
        return Ok(image);
    }
    let path_of = |file: &String| dir.join(file);
    let (png, exr) = (
        entry.png.as_ref().map(path_of),
        entry.exr.as_ref().map(path_of),
    );
    for path in png.iter().chain(&exr) {
        if path.exists() && !path.is_file() {
            return Err(Error::file(
                path,
                format!(
                    "is not a file (a folder?): material.json lists it as map '{}'",
                    entry.name
                ),
            ));
        }
        if !path.is_file() {
            let hint = if Some(path) == exr.as_ref() && png.is_some() {
                " (to load the PNG instead, remove this map's \"exr\" entry from material.json)"
            } else {
                ""
            };
            return Err(Error::file(
                path,
                format!(
                    "missing: material.json lists it for map '{}'{hint}",
                    entry.name
                ),
            ));
        }
    }
    let (path, image) = match (exr, png) {
        (Some(exr), png) => {
            if let Some(png) = png {
                let (channels, height, width) = png_header(&png)?;
                check_layout(&png, entry, channels, height, width, resolution)?;
            }
            let image = read_exr(&exr)?;
            check_layout(
                &exr,
                entry,
                image.channels,
                image.height,
                image.width,
                resolution,
            )?;
            if let Some(i) = image.data.iter().position(|v| !v.is_finite()) {
                let (c, row, col) = image.position(i);
                return Err(Error::file(
                    &exr,
                    format!(
                        "holds a non-finite value ({}) at row {row}, column {col}, channel {}",
                        image.data[i],
                        crate::image_io::exr_channel_names(image.channels)[c]
                    ),
                ));
            }
            (exr, image)
        }
        (None, Some(png)) => {
            let (stored, _bits) = read_png(&png)?;
            check_layout(
                &png,
                entry,
                stored.channels,
                stored.height,
                stored.width,
                resolution,
            )?;
            let mut image = stored.map(|s| entry.color_space.from_stored(s));
            if entry.color_space == ColorSpace::UnitVector && image.channels == 3 {
                renormalise(&png, &mut image)?;
            }
            (png, image)
        }
        (None, None) => unreachable!("read_manifest rejects entries without files or value"),
    };
    let image = match entry.grey {
        true => image.repeat_channel(entry.channels)?,
        false => image,
    };
    check_range(&image, spec)
        .map_err(|reason| Error::file(&path, format!("map '{}' {reason}", spec.name)))?;
    Ok(image)
}

/// Channel count and size of one file against the manifest.
fn check_layout(
    path: &Path,
    entry: &MapEntry,
    channels: usize,
    height: usize,
    width: usize,
    resolution: usize,
) -> Result<()> {
    if channels != entry.stored_channels() {
        return Err(Error::file(
            path,
            format!(
                "has {channels} channel(s), map '{}' needs {} (material.json{})",
                entry.name,
                entry.stored_channels(),
                if entry.grey { ": a grey map" } else { "" }
            ),
        ));
    }
    if height != width {
        return Err(Error::file(
            path,
            format!("is {width}×{height} pixels (width×height); material maps must be square"),
        ));
    }
    if height != resolution {
        return Err(Error::file(
            path,
            format!(
                "is {width}×{height} pixels, but material.json gives the resolution of every map \
                 as {resolution}×{resolution}"
            ),
        ));
    }
    Ok(())
}

/// Renormalise decoded PNG normals in place (quantisation shortens or lengthens them slightly).
fn renormalise(path: &Path, image: &mut PlanarImage) -> Result<()> {
    let plane = image.texels();
    for t in 0..plane {
        let v = [
            image.data[t],
            image.data[plane + t],
            image.data[2 * plane + t],
        ];
        let len = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        if len < MIN_PNG_NORMAL_LENGTH {
            return Err(Error::file(
                path,
                format!(
                    "row {}, column {} decodes to a zero normal (stored as 0.5·n + 0.5, a unit \
                     normal is never 50 % grey in every channel)",
                    t / image.width,
                    t % image.width
                ),
            ));
        }
        for (c, x) in v.iter().enumerate() {
            image.data[c * plane + t] = x / len;
        }
    }
    Ok(())
}

/// `Err(description)` if a value lies outside `spec.range` by more than [`RANGE_TOLERANCE`]
/// or is not finite.
fn check_range(image: &PlanarImage, spec: &ParamSpec) -> std::result::Result<(), String> {
    let (lo, hi) = spec.range;
    let outside = |v: f32| !(v >= lo - RANGE_TOLERANCE && v <= hi + RANGE_TOLERANCE);
    match image.data.iter().position(|&v| outside(v)) {
        None => Ok(()),
        Some(i) => {
            let (c, row, col) = image.position(i);
            Err(format!(
                "has value {} at row {row}, column {col}, channel {c}, outside its range \
                 [{lo}, {hi}]",
                image.data[i]
            ))
        }
    }
}

/// Comma-separated names of `specs`.
fn spec_names(specs: &[ParamSpec]) -> String {
    specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
}

/// Letters, digits, `_` and `-` only (a map name usable as a file stem on every system).
fn is_plain_file_stem(name: &str) -> bool {
    !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// A single path component that is not `.`/`..` (stays inside the material folder).
fn is_plain_file_name(name: &str) -> bool {
    let path = PathBuf::from(name);
    let mut components = path.components();
    matches!(
        (components.next(), components.next()),
        (Some(std::path::Component::Normal(c)), None) if c == name
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manifest_file_names_stay_inside_the_folder() {
        assert!(is_plain_file_name("diffuse.png"));
        for bad in ["", "../x.png", "/etc/passwd", "a/b.png", ".", ".."] {
            assert!(!is_plain_file_name(bad), "{bad}");
        }
    }

    #[test]
    fn check_range_allows_the_documented_tolerance_only() {
        let spec = ParamSpec {
            name: "r",
            channels: 1,
            range: (0.0, 1.0),
            encoding: crate::param::Encoding::Linear,
            color_space: ColorSpace::Linear,
            default: &[0.5],
            differentiable: true,
            doc: "",
        };
        let ok = PlanarImage::new(
            1,
            1,
            2,
            vec![-0.5 * RANGE_TOLERANCE, 1.0 + 0.5 * RANGE_TOLERANCE],
        );
        assert!(check_range(&ok.unwrap(), &spec).is_ok());
        for bad in [
            1.0 + 2.0 * RANGE_TOLERANCE,
            -2.0 * RANGE_TOLERANCE,
            f32::NAN,
            f32::INFINITY,
        ] {
            let image = PlanarImage::new(1, 1, 2, vec![0.5, bad]).unwrap();
            let err = check_range(&image, &spec).unwrap_err();
            assert!(err.contains("row 0, column 1"), "{err}");
        }
    }
}
