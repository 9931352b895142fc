//! Licences of a package's files, from its machine-readable Debian copyright file (DEP-5,
//! <https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/>): paragraphs of
//! `Files:` glob patterns with their `Copyright:` and `License:`, the last matching paragraph
//! deciding.
//!
//! Patterns name paths of the upstream source (`data/trak/trak4/*`), which a package installs
//! under its own prefix (`usr/share/games/redeclipse/data/trak/trak4/…`), and a file inside an
//! archive is named by its path in the archive: a pattern matches a file when it matches its
//! tree path with some leading folders dropped ([`CopyrightFile::licence_of`]). In patterns
//! `*` matches any characters, `/` included, and `?` one character.

use serde::{Deserialize, Serialize};

/// The licence of one file: its `License:` short name and `Copyright:` holders.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Licence {
    /// The `License:` line's short name, e.g. `CC-BY-SA-3.0+` or `GPL-2+ or Expat`.
    pub name: String,
    /// The `Copyright:` holders, one per line.
    pub holders: Vec<String>,
}

/// One `Files:` paragraph.
#[derive(Debug, Clone, PartialEq)]
struct Paragraph {
    patterns: Vec<String>,
    licence: Licence,
}

/// A parsed DEP-5 copyright file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CopyrightFile {
    paragraphs: Vec<Paragraph>,
}

impl CopyrightFile {
    /// Parses the text of a copyright file; paragraphs without `Files:` (the header, stand-alone
    /// licence texts) are skipped. A file that is not DEP-5 yields no paragraphs.
    pub fn parse(text: &str) -> Self {
        let mut paragraphs = Vec::new();
        for block in text.split("\n\n").flat_map(|b| b.split("\r\n\r\n")) {
            let fields = fields(block);
            let get = |name: &str| {
                fields
                    .iter()
                    .find(|(field, _)| field.eq_ignore_ascii_case(name))
                    .map(|(_, value)| value.clone())
            };
            let (Some(files), Some(licence)) = (get("Files"), get("License")) else {
                continue;
            };
            let patterns = files.split_whitespace().map(str::to_string).collect();
            // The short name is the first line; the rest is the licence text.
            let name = licence.lines().next().unwrap_or("").trim().to_string();
            let holders = get("Copyright")
                .map(|c| {
                    c.lines()
                        .map(str::trim)
                        .filter(|l| !l.is_empty())
                        .map(str::to_string)
                        .collect()
                })
                .unwrap_or_default();
            paragraphs.push(Paragraph {
                patterns,
                licence: Licence { name, holders },
            });
        }
        Self { paragraphs }
    }

    /// The licence of the file at `path` (a tree path, module docs), if a paragraph matches.
    pub fn licence_of(&self, path: &str) -> Option<&Licence> {
        let suffixes: Vec<&str> = std::iter::once(path)
            .chain(path.match_indices('/').map(|(i, _)| &path[i + 1..]))
            .collect();
        self.paragraphs
            .iter()
            .rev()
            .find(|p| {
                p.patterns
                    .iter()
                    .any(|pattern| suffixes.iter().any(|s| glob(pattern, s)))
            })
            .map(|p| &p.licence)
    }
}

/// The fields of one paragraph: `Name: value` lines, continuation lines (starting with white
/// space) appended with a newline; a continuation line of a lone `.` is an empty line.
fn fields(block: &str) -> Vec<(String, String)> {
    let mut fields: Vec<(String, String)> = Vec::new();
    for line in block.lines() {
        if line.starts_with([' ', '\t']) {
            if let Some((_, value)) = fields.last_mut() {
                let text = line.trim();
                value.push('\n');
                value.push_str(if text == "." { "" } else { text });
            }
        } else if let Some((name, value)) = line.split_once(':') {
            fields.push((name.trim().to_string(), value.trim().to_string()));
        }
    }
    fields
}

/// Whether `text` matches the DEP-5 glob `pattern` (module docs).
fn glob(pattern: &str, text: &str) -> bool {
    let (p, t): (Vec<char>, Vec<char>) = (pattern.chars().collect(), text.chars().collect());
    // Iterative matching with one backtrack point per `*` (linear in practice).
    let (mut pi, mut ti) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while ti < t.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == t[ti]) {
            pi += 1;
            ti += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some((pi, ti));
            pi += 1;
        } else if let Some((sp, st)) = star {
            pi = sp + 1;
            ti = st + 1;
            star = Some((sp, st + 1));
        } else {
            return false;
        }
    }
    p[pi..].iter().all(|&c| c == '*')
}

#[cfg(test)]
mod tests {
    use super::*;

    const COPYRIGHT: &str =
        "Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/
Upstream-Name: Example

Files: *
Copyright: 2009-2017, Red Eclipse Team
License: CC-BY-SA-3.0+

Files: data/trak/trak4/* data/trak/trak6/*
Copyright: Georges 'TRaK' Grondin
License: CC-BY-3.0

Files: data/trak/trak5/*
Copyright: 2009, Georges 'TRaK' Grondin
           2010, Someone Else
License: Expat
 Permission is hereby granted, free of charge,
 .
 to any person

License: CC-BY-3.0
 The licence text.
";

    #[test]
    fn the_last_matching_paragraph_decides_under_any_install_prefix() {
        let file = CopyrightFile::parse(COPYRIGHT);
        let of = |p: &str| file.licence_of(p).map(|l| l.name.clone());
        assert_eq!(
            of("usr/share/games/redeclipse/data/trak/trak4/brick1.jpg").as_deref(),
            Some("CC-BY-3.0")
        );
        let trak5 = file
            .licence_of("usr/share/games/redeclipse/data/trak/trak5/wall4a.jpg")
            .unwrap();
        assert_eq!(trak5.name, "Expat");
        assert_eq!(
            trak5.holders,
            ["2009, Georges 'TRaK' Grondin", "2010, Someone Else"]
        );
        assert_eq!(
            of("usr/share/games/redeclipse/data/wicked/rock.jpg").as_deref(),
            Some("CC-BY-SA-3.0+")
        );
    }

    #[test]
    fn globs_match_across_folders_and_single_characters() {
        assert!(glob("data/maps/ares*", "data/maps/ares/x.cfg"));
        assert!(glob("a?c", "abc") && !glob("a?c", "abbc"));
        assert!(glob("*", "") && !glob("data/*.png", "data/x.jpg"));
    }
}
