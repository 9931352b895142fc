//! 0 A.D. terrain definitions, `art/terrains/<biome>/<name>.xml`:
//!
//! ```xml
//! <terrain>
//!   <textures>
//!     <texture name="baseTex" file="types/aegean_anatolia/cliff_01.png"/>
//!     <texture name="normTex" file="types/aegean_anatolia/cliff_01_norm.png"/>
//!     <texture name="specTex" file="types/aegean_anatolia/cliff_01_spec.png"/>
//!   </textures>
//!   <material>terrain_norm_strong_spec.xml</material>
//! </terrain>
//! ```
//!
//! `file` is relative to `art/textures/terrain/`; the package ships only the engine's caches,
//! `<file>.cached.dds`, which are read instead when the file itself is absent. The material,
//! `art/materials/<material>`, holds `effectSettings` = (normal strength, specular exponent,
//! …). Many terrains reuse another texture's normal map: such a set is marked
//! [`TextureSet::borrowed_normal`] (its relief is plausible, not the texture's own).

use super::{Scheme, TextureSet, base_only};
use crate::tree::{SourceTree, file_name};

/// Every terrain definition of `tree` whose base texture exists.
pub fn sets(tree: &SourceTree) -> Vec<TextureSet> {
    let mut sets = Vec::new();
    for file in tree.files() {
        let Some((art, _)) = file.path.split_once("art/terrains/") else {
            continue;
        };
        if !file.path.to_lowercase().ends_with(".xml") {
            continue;
        }
        let Ok(bytes) = tree.read(file) else {
            continue;
        };
        let text = String::from_utf8_lossy(&bytes);
        if let Some(set) = parse(tree, art, &file.path, &text) {
            sets.push(set);
        }
    }
    sets
}

/// The set of the terrain definition `text` at tree path `from`, whose `art/` folder is at
/// tree path `art_prefix` + `art/`.
pub fn parse(tree: &SourceTree, art_prefix: &str, from: &str, text: &str) -> Option<TextureSet> {
    let doc = roxmltree::Document::parse(text).ok()?;
    let named = |name: &str| -> Option<String> {
        let node = doc
            .descendants()
            .find(|n| n.has_tag_name("texture") && n.attribute("name") == Some(name))?;
        node.attribute("file").map(str::to_string)
    };
    let texture = |file: &str| -> Option<String> {
        let path = format!("{art_prefix}art/textures/terrain/{file}");
        tree.find(&path)
            .or_else(|| tree.find(&format!("{path}.cached.dds")))
            .map(|f| f.path.clone())
    };
    let base = texture(&named("baseTex")?)?;
    let mut set = base_only(base, Scheme::TerrainXml, from);
    for (role, slot) in [("normTex", &mut set.normal), ("specTex", &mut set.specular)] {
        if let Some(file) = named(role) {
            *slot = texture(&file);
            if slot.is_none() {
                set.missing.push(format!("{role} {file}"));
            }
        }
    }
    set.borrowed_normal = set
        .normal
        .as_deref()
        .is_some_and(|normal| stem(normal).trim_end_matches("_norm") != stem(&set.base));
    let material = doc
        .descendants()
        .find(|n| n.has_tag_name("material"))
        .and_then(|n| n.text());
    if let Some(settings) = material.and_then(|m| effect_settings(tree, art_prefix, m.trim())) {
        set.normal_strength = settings.first().copied();
        set.specular_power = settings.get(1).copied();
    }
    Some(set)
}

/// The `effectSettings` uniform of the material `art/materials/<name>`.
fn effect_settings(tree: &SourceTree, art_prefix: &str, name: &str) -> Option<Vec<f64>> {
    let file = tree.find(&format!("{art_prefix}art/materials/{name}"))?;
    let bytes = tree.read(file).ok()?;
    let text = String::from_utf8_lossy(&bytes);
    let doc = roxmltree::Document::parse(&text).ok()?;
    let value = doc
        .descendants()
        .find(|n| n.has_tag_name("uniform") && n.attribute("name") == Some("effectSettings"))?
        .attribute("value")?;
    value
        .split_whitespace()
        .map(|v| v.parse::<f64>().ok())
        .collect()
}

/// A texture's file name without its extensions (`cliff_01.png.cached.dds` → `cliff_01`).
fn stem(path: &str) -> &str {
    let name = file_name(path);
    name.split('.').next().unwrap_or(name)
}
