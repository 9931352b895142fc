//! Texture slots of the Cube 2 engine's `.cfg` files (Red Eclipse, Sauerbraten's `cube2-data`):
//!
//! ```text
//! setshader bumpspecmapparallaxworld
//! setshaderparam "specscale" 0.25 0.25 0.25
//! texture c trak/trak5/comp1a.jpg 0 0 0 0.5     // a slot starts: base colour (also `0`)
//! texture n trak/trak5/comp1_n.png              // its normal map
//! texture s trak/trak5/comp1_s.jpg              // specular intensity
//! texture z trak/trak5/comp1_z.png              // height (parallax depth)
//! texture g trak/trak5/comp1a_g.jpg             // glow: the surface lights itself
//! ```
//!
//! A slot is a `c` (or `0`) line and the companion lines after it; any other first word after
//! `texture` (`water`, `lava`, `sky`, …) ends the slot. Paths may be quoted and carry loader
//! prefixes such as `<dds>` or `<mad:…>`, which are dropped; they resolve against the file's
//! folder or an ancestor of it (the engine's data root, [`super::resolve`]). `//` starts a
//! comment.

use super::{Scheme, TextureSet, base_only, resolve};
use crate::tree::SourceTree;

/// Every texture slot with a base colour that exists, over every `.cfg` file of `tree`.
pub fn sets(tree: &SourceTree) -> Vec<TextureSet> {
    let mut sets = Vec::new();
    for file in tree.files() {
        if !file.path.to_lowercase().ends_with(".cfg") {
            continue;
        }
        // A cfg the tree cannot read is a missing source of pairs, not a reason to stop.
        let Ok(bytes) = tree.read(file) else {
            continue;
        };
        sets.extend(parse(tree, &file.path, &String::from_utf8_lossy(&bytes)));
    }
    sets
}

/// The slots of the cfg `text` at tree path `from`.
pub fn parse(tree: &SourceTree, from: &str, text: &str) -> Vec<TextureSet> {
    let mut sets: Vec<TextureSet> = Vec::new();
    let mut open = false;
    // Slots of a glow shader light themselves (through a `g` map or the base's alpha).
    let mut glow_shader = false;
    for line in text.lines() {
        let line = line.split("//").next().unwrap_or("").trim();
        let words = split_words(line);
        match words.as_slice() {
            [texture, kind, path, ..] if texture == "texture" => {
                let path = strip_loader_prefixes(path);
                match kind.as_str() {
                    "c" | "0" => {
                        open = false;
                        if let Some(base) = resolve(tree, from, &path) {
                            sets.push(TextureSet {
                                emissive: glow_shader,
                                ..base_only(base, Scheme::CubeCfg, from)
                            });
                            open = true;
                        }
                    }
                    "n" | "s" | "z" | "g" if open => {
                        let Some(set) = sets.last_mut() else { continue };
                        let found = resolve(tree, from, &path);
                        if found.is_none() && *kind != "g" {
                            set.missing.push(format!("{kind} {path}"));
                        }
                        match kind.as_str() {
                            "n" => set.normal = set.normal.take().or(found),
                            "s" => set.specular = set.specular.take().or(found),
                            "z" => set.height = set.height.take().or(found),
                            // A glow map lights the surface whether or not its file exists.
                            _ => set.emissive = true,
                        }
                    }
                    // Blend layers (`1`) and engine slots (`e`, `u`) keep the slot open.
                    "1" | "e" | "u" => {}
                    _ => open = false,
                }
            }
            [set_shader, shader, ..] if set_shader == "setshader" => {
                open = false;
                glow_shader = shader.contains("glow");
            }
            _ => {}
        }
    }
    sets
}

/// The words of a cfg line: whitespace-separated, `"…"` quoting a word with spaces.
fn split_words(line: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut quoted = false;
    for ch in line.chars() {
        match ch {
            '"' => quoted = !quoted,
            c if c.is_whitespace() && !quoted => {
                if !word.is_empty() {
                    words.push(std::mem::take(&mut word));
                }
            }
            c => word.push(c),
        }
    }
    if !word.is_empty() {
        words.push(word);
    }
    words
}

/// A cfg path without the loader's `<…>` prefixes (`<dds><grey>trak/x.png` → `trak/x.png`).
fn strip_loader_prefixes(path: &str) -> String {
    let mut rest = path;
    while let Some(after) = rest.strip_prefix('<') {
        match after.find('>') {
            Some(end) => rest = &after[end + 1..],
            None => break,
        }
    }
    rest.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_and_prefixes_are_read_as_the_engine_reads_them() {
        assert_eq!(
            split_words(r#"texture c "my dir/rock.jpg" 0 0"#),
            ["texture", "c", "my dir/rock.jpg", "0", "0"]
        );
        assert_eq!(strip_loader_prefixes("<dds><mad:0.5>a/b.png"), "a/b.png");
        assert_eq!(strip_loader_prefixes("a/b.png"), "a/b.png");
    }
}
