//! The library's index, `library.json` ([`INDEX_FILE`]): every material with its split,
//! cluster, package, licences and folders, the packages imported with their versions and
//! counts, and what was left out and why (docs/data.md, "The index").

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use photomat_core::image_io::write_atomic;
use photomat_core::{Error, Result};
use serde::{Deserialize, Serialize};

use crate::convert::Rejection;
use crate::material::MaterialFolders;
use crate::package::Package;
use crate::split::{Split, SplitShares};

/// The index file at the library's root.
pub const INDEX_FILE: &str = "library.json";
/// Value of the index's `format` field.
pub const FORMAT_TAG: &str = "photomat-library";
/// Index version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;
/// The folder of the materials, one sub-folder per package.
pub const MATERIALS_DIR: &str = "materials";

/// One material of the index.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IndexEntry {
    /// `<package>/<slug>`: also its folder under [`MATERIALS_DIR`].
    pub id: String,
    pub split: Split,
    /// The cluster of near-duplicates it stands for: the id of the cluster's first member.
    pub cluster: String,
    pub package: String,
    /// The base colour's path in the package.
    pub base: String,
    /// The licences of its files.
    pub licences: Vec<String>,
    /// Side of its square maps.
    pub side: usize,
    /// The relief's range in world units (the height model's scale).
    pub height_scale: f64,
}

/// One imported package.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PackageEntry {
    #[serde(flatten)]
    pub package: Package,
    /// The folder or archive it was read from.
    pub source: PathBuf,
    /// Texture sets its material files and names gave.
    pub sets: usize,
    /// Materials imported, per split.
    pub materials: BTreeMap<Split, usize>,
    /// Sets left out, per reason.
    pub rejected: BTreeMap<Rejection, usize>,
    /// Materials per licence.
    pub licences: BTreeMap<String, usize>,
}

/// The contents of `library.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LibraryIndex {
    pub format: String,
    pub version: u32,
    /// The seed of the splits.
    pub seed: u64,
    pub shares: SplitShares,
    pub packages: Vec<PackageEntry>,
    pub materials: Vec<IndexEntry>,
}

impl LibraryIndex {
    /// Writes `dir/library.json` atomically.
    pub fn save(&self, dir: &Path) -> Result<()> {
        let json = serde_json::to_vec_pretty(self)
            .map_err(|e| Error::Invalid(format!("library index: {e}")))?;
        write_atomic(&dir.join(INDEX_FILE), &json)
    }

    /// Reads `dir/library.json`; errors name the file.
    pub fn load(dir: &Path) -> Result<Self> {
        let path = dir.join(INDEX_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            Error::file(
                &path,
                format!("cannot read the library index ({e}); is this a `photomat library import` output?"),
            )
        })?;
        let index: Self = serde_json::from_str(&text)
            .map_err(|e| Error::file(&path, format!("is not a library index: {e}")))?;
        if index.format != FORMAT_TAG || index.version != FORMAT_VERSION {
            return Err(Error::file(
                &path,
                format!(
                    "is format {} version {}; this build reads {FORMAT_TAG} version {FORMAT_VERSION}",
                    index.format, index.version
                ),
            ));
        }
        Ok(index)
    }

    /// The materials of `split`, in index order.
    pub fn split(&self, split: Split) -> Vec<&IndexEntry> {
        self.materials.iter().filter(|m| m.split == split).collect()
    }
}

/// The folders of the material `entry` of the library at `dir`.
pub fn folders(dir: &Path, entry: &IndexEntry) -> MaterialFolders {
    MaterialFolders::of(&dir.join(MATERIALS_DIR).join(&entry.id))
}
