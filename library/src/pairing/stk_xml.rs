//! SuperTuxKart `materials.xml` files:
//!
//! ```xml
//! <materials>
//!   <material name="stk_generic_rock_a.png" normal-map="stk_generic_rock_a_Normal.png"
//!             gloss-map="stk_generic_rock_a_gloss.png" shader="normalmap"/>
//! </materials>
//! ```
//!
//! Names resolve next to the `materials.xml` or in the game's shared `data/textures/` folder
//! (found as a sibling of an ancestor, [`super::resolve`]). The gloss map's red channel is the
//! gloss ("polish"); its green and blue (metallic, emission) are empty in the shipped maps.
//! Karts and scenery models (`karts/`, `library/` objects) are UV atlases, not surfaces: the
//! importer's filter drops them by path ([`crate::filter`]).

use super::{Scheme, TextureSet, base_only, resolve};
use crate::tree::{SourceTree, parent};

/// Every `materials.xml` entry of `tree` whose texture exists.
pub fn sets(tree: &SourceTree) -> Vec<TextureSet> {
    let mut sets = Vec::new();
    for file in tree.files() {
        if !file.path.to_lowercase().ends_with("materials.xml") {
            continue;
        }
        let Ok(bytes) = tree.read(file) else {
            continue;
        };
        sets.extend(parse(tree, &file.path, &String::from_utf8_lossy(&bytes)));
    }
    sets
}

/// The entries of the `materials.xml` text at tree path `from`.
pub fn parse(tree: &SourceTree, from: &str, text: &str) -> Vec<TextureSet> {
    let Ok(doc) = roxmltree::Document::parse(text) else {
        return Vec::new();
    };
    let find = |name: &str| {
        resolve(tree, from, name).or_else(|| {
            // The shared textures folder: `data/textures/` beside the track or kart folders.
            let mut dir = parent(from);
            while !dir.is_empty() {
                let shared = format!("{dir}/textures/{name}");
                if let Some(file) = tree.find(&shared) {
                    return Some(file.path.clone());
                }
                dir = parent(dir);
            }
            None
        })
    };
    doc.descendants()
        .filter(|n| n.has_tag_name("material"))
        .filter_map(|n| {
            let base = find(n.attribute("name")?)?;
            let mut set = base_only(base, Scheme::StkXml, from);
            for (attribute, slot) in [
                ("normal-map", &mut set.normal),
                ("gloss-map", &mut set.gloss),
            ] {
                if let Some(name) = n.attribute(attribute) {
                    *slot = find(name);
                    if slot.is_none() {
                        set.missing.push(format!("{attribute} {name}"));
                    }
                }
            }
            Some(set)
        })
        .collect()
}
