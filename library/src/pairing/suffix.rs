//! Texture sets paired by file name, for folders that no material file describes: the
//! companions of a base colour `X` are the files of the same folder named `X` + a separator
//! (`_` or `-`) + one of the suffixes below, compared without letter case; a base colour may
//! carry a suffix of its own (`X_d`, `X_diffuse`, `X_col`, …) that the pairing drops.
//!
//! | map | suffixes | used by (docs/data.md) |
//! |---|---|---|
//! | normal | `n`, `nm`, `norm`, `normal`, `nrm`, `local` | Red Eclipse `_n`, UFO:AI `_nm`, 0 A.D. `_norm`, SuperTuxKart `_Normal`, Doom 3 `_local` |
//! | specular | `s`, `spec`, `specular`, `sm`, `sc` | Red Eclipse `_s`, 0 A.D. `_spec`, UFO:AI `_sm`, Cube 2 `_sc` |
//! | gloss | `gloss`, `glossiness`, `glossy` | SuperTuxKart `_gloss` |
//! | roughness | `rough`, `roughness` | PBR sets (ambientCG `_Roughness`) |
//! | height | `h`, `z`, `hm`, `height`, `bump`, `disp`, `displacement`, `depth` | Red Eclipse `_z`, Cube 2 `_hm`, `_bump` |
//! | glow (emissive) | `g`, `gm`, `glow`, `emissive`, `illum` | Red Eclipse `_g`, UFO:AI `_gm` |
//!
//! A companion without a base in its folder is left alone.

use std::collections::BTreeMap;

use super::{Scheme, TextureSet, base_only};
use crate::tree::{file_name, parent};

/// The companion kinds, in the order their suffixes are tried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Normal,
    Specular,
    Gloss,
    Roughness,
    Height,
    Glow,
}

/// Suffixes of each companion kind (module docs).
const COMPANIONS: [(Kind, &[&str]); 6] = [
    (Kind::Normal, &["n", "nm", "norm", "normal", "nrm", "local"]),
    (Kind::Specular, &["s", "spec", "specular", "sm", "sc"]),
    (Kind::Gloss, &["gloss", "glossiness", "glossy"]),
    (Kind::Roughness, &["rough", "roughness"]),
    (
        Kind::Height,
        &[
            "h",
            "z",
            "hm",
            "height",
            "bump",
            "disp",
            "displacement",
            "depth",
        ],
    ),
    (Kind::Glow, &["g", "gm", "glow", "emissive", "illum"]),
];

/// Suffixes a base colour's own name may carry.
const BASE_SUFFIXES: [&str; 10] = [
    "d",
    "c",
    "cc",
    "col",
    "color",
    "colour",
    "diffuse",
    "dif",
    "albedo",
    "basecolor",
];

/// The files of one key: base colours, and companions with their kinds.
#[derive(Default)]
struct Group<'a> {
    bases: Vec<&'a str>,
    companions: Vec<(Kind, &'a str)>,
}

/// The file name of `path` without its extension.
fn stem(path: &str) -> &str {
    let name = file_name(path);
    name.rsplit_once('.').map_or(name, |(stem, _)| stem)
}

/// `stem` without a separator + `suffix` at its end (letter case ignored), if it has one and
/// something is left.
fn strip_suffix<'a>(stem: &'a str, suffix: &str) -> Option<&'a str> {
    let cut = stem.len().checked_sub(suffix.len() + 1)?;
    let (head, tail) = (stem.get(..cut)?, stem.get(cut..)?);
    let (separator, rest) = tail.split_at(1);
    (matches!(separator, "_" | "-") && rest.eq_ignore_ascii_case(suffix) && !head.is_empty())
        .then_some(head)
}

/// What the file name `path` is: a companion kind and its base's key, or a base and its key
/// (the key: folder + lower-case stem without suffix).
fn classify(path: &str) -> (Option<Kind>, String) {
    let s = stem(path);
    let key = |head: &str| format!("{}/{}", parent(path), head.to_lowercase());
    for (kind, suffixes) in COMPANIONS {
        for suffix in suffixes {
            if let Some(head) = strip_suffix(s, suffix) {
                return (Some(kind), key(head));
            }
        }
    }
    for suffix in BASE_SUFFIXES {
        if let Some(head) = strip_suffix(s, suffix) {
            return (None, key(head));
        }
    }
    (None, key(s))
}

/// The texture sets of `paths` (texture files no material file names), one per base colour,
/// by file name (module docs).
pub fn pair(paths: &[&str]) -> Vec<TextureSet> {
    let mut groups: BTreeMap<String, Group> = BTreeMap::new();
    for path in paths {
        let (kind, key) = classify(path);
        let group = groups.entry(key).or_default();
        match kind {
            None => group.bases.push(path),
            Some(kind) => group.companions.push((kind, path)),
        }
    }
    let mut sets = Vec::new();
    for (
        _,
        Group {
            mut bases,
            companions,
        },
    ) in groups
    {
        bases.sort_unstable();
        // Two base colours of one stem (`rock.jpg`, `rock_d.png`): the first by name.
        let Some(base) = bases.first() else { continue };
        let mut set = base_only(base.to_string(), Scheme::Suffix, parent(base));
        let first = |kind: Kind| {
            let mut found: Vec<&str> = companions
                .iter()
                .filter(|(k, _)| *k == kind)
                .map(|(_, p)| *p)
                .collect();
            found.sort_unstable();
            found.first().map(|p| p.to_string())
        };
        set.normal = first(Kind::Normal);
        set.specular = first(Kind::Specular);
        set.gloss = first(Kind::Gloss);
        set.roughness = first(Kind::Roughness);
        set.height = first(Kind::Height);
        set.emissive = first(Kind::Glow).is_some();
        sets.push(set);
    }
    sets
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suffix_pairing_groups_companions_with_their_base_by_folder() {
        let sets = pair(&[
            "a/Rock.jpg",
            "a/rock_NM.png",
            "a/rock_spec.png",
            "a/rock-height.png",
            "a/brick_d.png",
            "a/brick_norm.png",
            "a/brick_gloss.png",
            "a/panel.png",
            "a/panel_g.png",
            "b/rock_n.png",
        ]);
        let by_base: BTreeMap<&str, &TextureSet> =
            sets.iter().map(|s| (s.base.as_str(), s)).collect();
        assert_eq!(by_base.len(), 3, "{sets:#?}");
        let rock = by_base["a/Rock.jpg"];
        assert_eq!(rock.normal.as_deref(), Some("a/rock_NM.png"));
        assert_eq!(rock.specular.as_deref(), Some("a/rock_spec.png"));
        assert_eq!(rock.height.as_deref(), Some("a/rock-height.png"));
        let brick = by_base["a/brick_d.png"];
        assert_eq!(brick.normal.as_deref(), Some("a/brick_norm.png"));
        assert_eq!(brick.gloss.as_deref(), Some("a/brick_gloss.png"));
        assert!(by_base["a/panel.png"].emissive);
        assert!(by_base["a/panel.png"].normal.is_none());
        // `b/rock_n.png` has no base in its folder.
        assert!(!by_base.contains_key("b/rock_n.png"));
    }
}
