//! Which files make one material: a base colour and its normal, specular, gloss and height maps,
//! as a package pairs them (docs/data.md, "Which files make a material").
//!
//! Where a package has material files, they are the truth and every recogniser reads them:
//! - [`cube_cfg`]: Cube 2 engine `.cfg` texture slots (Red Eclipse, `cube2-data`);
//! - [`terrain_xml`]: 0 A.D. terrain definitions (`art/terrains/**/*.xml`);
//! - [`stk_xml`]: SuperTuxKart `materials.xml`.
//!
//! Textures that no material file names are paired by their file names ([`suffix`]: a base
//! `X.png` with `X_n.png`, `X_norm.png`, `X_spec.png`, …), which is all a plain folder of
//! texture sets offers. [`find_sets`] runs them all over a tree; a base colour named by a
//! material file is not paired again by its name.

pub mod cube_cfg;
pub mod stk_xml;
pub mod suffix;
pub mod terrain_xml;

use std::collections::BTreeSet;

use serde::{Deserialize, Serialize};

use crate::decode::is_texture;
use crate::tree::{SourceTree, parent};

/// How a [`TextureSet`] was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scheme {
    /// A Cube 2 `.cfg` texture slot.
    CubeCfg,
    /// A 0 A.D. terrain definition.
    TerrainXml,
    /// A SuperTuxKart `materials.xml` entry.
    StkXml,
    /// File-name suffixes.
    Suffix,
}

/// The files of one material, as paths of a [`SourceTree`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureSet {
    /// The base colour (display-encoded RGB).
    pub base: String,
    /// The tangent-space normal map.
    pub normal: Option<String>,
    /// A specular intensity or colour map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specular: Option<String>,
    /// A gloss (smoothness) map, 1 = mirror-like.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gloss: Option<String>,
    /// A roughness map (1 − gloss).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roughness: Option<String>,
    /// A height or depth map.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<String>,
    /// The engine lights the material itself (a glow or emission map): not a surface a flash
    /// photo shows as the maps say.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub emissive: bool,
    /// The normal map was made for another base colour (0 A.D. terrains reuse normals across
    /// textures): plausible relief, not this texture's.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub borrowed_normal: bool,
    /// The engine's specular exponent for the material, when its material file gives one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub specular_power: Option<f64>,
    /// The factor the engine multiplies the normal map's slopes by, when its material file
    /// gives one (0 A.D.'s "strong" terrains: 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal_strength: Option<f64>,
    pub scheme: Scheme,
    /// The material file that paired it (for [`Scheme::Suffix`], the base's folder).
    pub defined_in: String,
    /// Companions the material file names that the tree does not hold, as written there
    /// (`n trak/x_n.png`): the importer reports them, naming the file.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing: Vec<String>,
}

/// Every texture set of `tree`, each base colour once (module docs), sorted by base path.
pub fn find_sets(tree: &SourceTree) -> Vec<TextureSet> {
    let mut sets = cube_cfg::sets(tree);
    sets.extend(terrain_xml::sets(tree));
    sets.extend(stk_xml::sets(tree));
    let mut named: BTreeSet<String> = BTreeSet::new();
    for set in &sets {
        named.insert(set.base.clone());
        named.extend(set.normal.iter().cloned());
        named.extend(set.specular.iter().cloned());
        named.extend(set.gloss.iter().cloned());
        named.extend(set.roughness.iter().cloned());
        named.extend(set.height.iter().cloned());
    }
    // Folders whose textures a material file names are the material files' to pair: name
    // pairing there would only find what the engine does not use.
    let covered: BTreeSet<&str> = named.iter().map(|p| parent(p)).collect();
    let loose: Vec<&str> = tree
        .files()
        .iter()
        .map(|f| f.path.as_str())
        .filter(|p| is_texture(p) && !named.contains(*p) && !covered.contains(parent(p)))
        .collect();
    sets.extend(suffix::pair(&loose));
    sets.sort_by(|a, b| a.base.cmp(&b.base).then(a.scheme.cmp(&b.scheme)));
    // A base colour two material files (or two slots) name is one material: the first kept.
    sets.dedup_by(|b, a| a.base == b.base);
    sets
}

/// A set of the base colour `base` with no companions yet.
pub(crate) fn base_only(base: String, scheme: Scheme, defined_in: &str) -> TextureSet {
    TextureSet {
        base,
        normal: None,
        specular: None,
        gloss: None,
        roughness: None,
        height: None,
        emissive: false,
        borrowed_normal: false,
        specular_power: None,
        normal_strength: None,
        scheme,
        defined_in: defined_in.to_string(),
        missing: Vec::new(),
    }
}

/// The path of a texture that a material file at `from` names as `name`: relative to the
/// file's folder or to one of its ancestors (engines resolve against their data root, which
/// the file does not say), with the extension the file gives or, missing that, any texture
/// extension the tree has (`.png` for a `.jpg` named, as Cube 2 falls back).
pub(crate) fn resolve(tree: &SourceTree, from: &str, name: &str) -> Option<String> {
    let name = name.trim().trim_matches('"').replace('\\', "/");
    if name.is_empty() {
        return None;
    }
    let stem = match name.rsplit_once('.') {
        Some((stem, ext)) if !ext.contains('/') => stem.to_string(),
        _ => name.clone(),
    };
    let mut dir = parent(from).to_string();
    loop {
        let join = |n: &str| {
            if dir.is_empty() {
                n.to_string()
            } else {
                format!("{dir}/{n}")
            }
        };
        if let Some(file) = tree.find(&join(&name)) {
            return Some(file.path.clone());
        }
        for ext in crate::decode::TEXTURE_EXTENSIONS {
            if let Some(file) = tree.find(&join(&format!("{stem}.{ext}"))) {
                return Some(file.path.clone());
            }
        }
        if dir.is_empty() {
            return None;
        }
        dir = parent(&dir).to_string();
    }
}
