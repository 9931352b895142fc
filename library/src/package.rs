//! What a source folder is: the Debian package it was extracted from (name, version), its
//! copyright file, and the packages the library refuses (docs/data.md, "Sources").
//!
//! `data/sources/debian.sh PACKAGE DIR` fetches a package with `apt-get download`, extracts it
//! with `dpkg -x` and writes [`SOURCE_FILE`] beside the extracted tree: the package's name,
//! version and the `.deb`'s SHA-256. A folder without it is read as an extracted package when
//! it holds `usr/share/doc/<name>/copyright` (the version then from the first line of
//! `changelog.Debian.gz`), and as an anonymous source (a folder or archive of texture sets,
//! named after itself, licence unknown) otherwise.

use std::io::Read;
use std::path::Path;

use photomat_core::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::licence::CopyrightFile;
use crate::tree::SourceTree;

/// The file `data/sources/debian.sh` writes beside an extracted package.
pub const SOURCE_FILE: &str = "photomat-source.json";

/// Packages kept out of every library: `nexuiz-textures` is held back for independent checks
/// of what photomat learns (and `nexuiz-data` ships the same textures).
pub const HELD_BACK: [&str; 2] = ["nexuiz-textures", "nexuiz-data"];

/// A source's identity.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Package {
    /// The Debian package name, or the source folder's name.
    pub name: String,
    /// The package version (`1.6.0-1`), `unknown` when nothing says.
    pub version: String,
    /// SHA-256 of the `.deb`, when `data/sources/debian.sh` recorded it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deb_sha256: Option<String>,
}

/// A source with its copyright file.
pub struct PackageSource {
    pub package: Package,
    /// The DEP-5 copyright file, empty when the source has none.
    pub copyright: CopyrightFile,
}

impl PackageSource {
    /// Identifies the source at `root` (a folder or an archive), already opened as `tree`;
    /// refuses a [`HELD_BACK`] package naming it.
    pub fn identify(root: &Path, tree: &SourceTree) -> Result<Self> {
        let recorded = read_source_file(root)?;
        let doc = tree
            .files()
            .iter()
            .filter_map(|f| {
                let rest = f.path.strip_prefix("usr/share/doc/")?;
                let (name, file) = rest.split_once('/')?;
                (file == "copyright").then(|| (name.to_string(), f))
            })
            .next();
        let folder_name = root.file_name().map_or_else(
            || "source".to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        let name = recorded
            .as_ref()
            .map(|p| p.name.clone())
            .or_else(|| doc.as_ref().map(|(n, _)| n.clone()))
            .unwrap_or(folder_name);
        if HELD_BACK.contains(&name.as_str()) {
            return Err(Error::file(
                root,
                format!(
                    "is the package {name}, which is held back for independent checks of what \
                     photomat learns: it must not enter a material library (docs/data.md)"
                ),
            ));
        }
        let copyright = match &doc {
            Some((_, file)) => CopyrightFile::parse(&String::from_utf8_lossy(&tree.read(file)?)),
            None => CopyrightFile::default(),
        };
        let version = recorded
            .as_ref()
            .map(|p| p.version.clone())
            .or_else(|| changelog_version(tree, &name))
            .unwrap_or_else(|| "unknown".into());
        Ok(Self {
            package: Package {
                name,
                version,
                deb_sha256: recorded.and_then(|p| p.deb_sha256),
            },
            copyright,
        })
    }
}

/// [`SOURCE_FILE`] in the folder `root`, when there is one.
fn read_source_file(root: &Path) -> Result<Option<Package>> {
    let path = root.join(SOURCE_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path)
        .map_err(|e| Error::file(&path, format!("cannot read: {e}")))?;
    serde_json::from_str(&text)
        .map(Some)
        .map_err(|e| Error::file(&path, format!("is not a source record: {e}")))
}

/// The version on the first line of `usr/share/doc/<name>/changelog.Debian.gz`
/// (`name (1.6.0-1) unstable; urgency=medium`).
fn changelog_version(tree: &SourceTree, name: &str) -> Option<String> {
    let file = tree.find(&format!("usr/share/doc/{name}/changelog.Debian.gz"))?;
    let bytes = tree.read(file).ok()?;
    let mut text = String::new();
    flate2::read::GzDecoder::new(bytes.as_slice())
        .take(4096)
        .read_to_string(&mut text)
        .ok()?;
    let first = text.lines().next()?;
    let open = first.find('(')?;
    let close = first[open..].find(')')?;
    Some(first[open + 1..open + close].to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_extracted_package_is_named_by_its_doc_folder_and_dated_by_its_changelog() {
        let dir = tempfile::tempdir().unwrap();
        let doc = dir.path().join("usr/share/doc/redeclipse-data");
        std::fs::create_dir_all(&doc).unwrap();
        std::fs::write(
            doc.join("copyright"),
            "Files: *\nCopyright: Team\nLicense: CC0-1.0\n",
        )
        .unwrap();
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(
            &mut gz,
            b"redeclipse-data (1.6.0-1) unstable; urgency=medium\n",
        )
        .unwrap();
        std::fs::write(doc.join("changelog.Debian.gz"), gz.finish().unwrap()).unwrap();
        let tree = SourceTree::open(dir.path()).unwrap();
        let source = PackageSource::identify(dir.path(), &tree).unwrap();
        assert_eq!(source.package.name, "redeclipse-data");
        assert_eq!(source.package.version, "1.6.0-1");
        let licence = source
            .copyright
            .licence_of("usr/share/games/x.png")
            .unwrap();
        assert_eq!(licence.name, "CC0-1.0");
    }

    #[test]
    fn the_held_back_package_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let doc = dir.path().join("usr/share/doc/nexuiz-textures");
        std::fs::create_dir_all(&doc).unwrap();
        std::fs::write(doc.join("copyright"), "").unwrap();
        let tree = SourceTree::open(dir.path()).unwrap();
        let err = PackageSource::identify(dir.path(), &tree)
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("held back for independent checks"), "{err}");
    }
}
