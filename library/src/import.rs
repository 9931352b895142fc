//! `photomat library import`: packages of texture sets → a material library (docs/data.md).
//!
//! For each source (an extracted package folder, or a folder or archive of texture sets) the
//! importer identifies the package ([`crate::package`]), finds its texture sets
//! ([`crate::pairing`]), leaves out what is not a surface by its path or its material file
//! ([`crate::filter`]), reads each remaining set's header sizes before decoding it, converts it
//! ([`crate::convert`]) and writes its two material folders ([`crate::material`]). Then the
//! materials of every source are clustered by near-duplicate signature and one per cluster
//! kept, each cluster is assigned its split ([`crate::split`]), and the index and a contact
//! sheet are written. Sets are converted in parallel; the result does not depend on the thread
//! count.
//!
//! The library folder is one result ([`photomat_core::output_folder`]): an existing library is
//! refused unless `overwrite`, and a killed import leaves the previous library whole.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use photomat_core::output_folder::{OutputFolder, ResultKind};
use rayon::prelude::*;

use crate::convert::{ConvertOptions, DecodedSet, Rejection, convert};
use crate::decode::{decode_rgba, dimensions};
use crate::filter::{Signature, clusters, not_surface};
use crate::index::{INDEX_FILE, IndexEntry, LibraryIndex, MATERIALS_DIR, PackageEntry};
use crate::material::{Provenance, SourceFileRecord, write_material};
use crate::package::PackageSource;
use crate::pairing::{TextureSet, find_sets};
use crate::sheet::{SHEET_FILE, write_contact_sheet};
use crate::split::{Split, SplitShares, split_of};
use crate::tree::SourceTree;

/// What a library folder holds.
pub const LIBRARY: ResultKind = ResultKind {
    what: "a material library",
    command: "photomat library import",
    entries: &[INDEX_FILE, MATERIALS_DIR, SHEET_FILE],
    kept: &[],
};

/// How an import runs.
#[derive(Debug, Clone, Default)]
pub struct ImportOptions {
    pub convert: ConvertOptions,
    /// Seed of the splits. Default 0.
    pub seed: u64,
    pub shares: SplitShares,
    /// Replace an existing library.
    pub overwrite: bool,
}

/// What [`import`] reports while it works.
#[derive(Debug, Clone)]
pub enum ImportEvent {
    /// A source was opened: its package and how many texture sets it has.
    Source { package: String, sets: usize },
    /// A texture set was converted or left out.
    Set,
    /// A file could not be read (the set is left out): the message names it.
    Unreadable(String),
}

/// How an import ended.
#[derive(Debug, Clone)]
pub struct ImportReport {
    /// The library folder.
    pub library: PathBuf,
    /// The index as written.
    pub index: LibraryIndex,
    /// Files that could not be read, each message naming one.
    pub unreadable: Vec<String>,
    /// Whether the stop flag ended the import early (nothing was written then).
    pub interrupted: bool,
}

/// A converted material before deduplication.
struct Candidate {
    id: String,
    source: usize,
    set: TextureSet,
    signature: Signature,
    licences: Vec<String>,
    side: usize,
    height_scale: f64,
}

/// Imports `sources` into the library folder `out` (module docs). `stop`, when set, ends the
/// import after the sets under way, leaving `out` as it was.
pub fn import(
    sources: &[PathBuf],
    out: &Path,
    options: &ImportOptions,
    stop: &AtomicBool,
    progress: &(dyn Fn(ImportEvent) + Sync),
) -> anyhow::Result<ImportReport> {
    anyhow::ensure!(
        !sources.is_empty(),
        "give at least one source folder or archive"
    );
    for source in sources {
        photomat_core::output_folder::refuse_input_inside(source, out, "the source")?;
    }
    let folder = OutputFolder::claim(out, LIBRARY, options.overwrite)?;
    let staging = folder.path().to_path_buf();
    let mut packages = Vec::new();
    let mut candidates = Vec::new();
    let mut unreadable = Vec::new();
    for (index, source) in sources.iter().enumerate() {
        let tree = SourceTree::open(source)?;
        let package = PackageSource::identify(source, &tree)?;
        let Some(imported) =
            import_source(&tree, &package, index, &staging, options, stop, progress)
        else {
            return Ok(ImportReport {
                library: out.to_path_buf(),
                index: empty_index(options),
                unreadable,
                interrupted: true,
            });
        };
        let mut entry = PackageEntry {
            package: package.package.clone(),
            source: photomat_core::paths::absolute(source),
            sets: imported.len(),
            materials: BTreeMap::new(),
            rejected: BTreeMap::new(),
            licences: BTreeMap::new(),
        };
        for (result, problem) in imported {
            unreadable.extend(problem);
            match result {
                Ok(candidate) => candidates.push(candidate),
                Err(reason) => *entry.rejected.entry(reason).or_default() += 1,
            }
        }
        packages.push(entry);
    }
    let materials = deduplicate_and_split(candidates, &mut packages, &staging, options)?;
    let index = LibraryIndex {
        materials,
        packages,
        ..empty_index(options)
    };
    index.save(&staging)?;
    if !index.materials.is_empty() {
        write_contact_sheet(&staging, &index)?;
    }
    let library = folder.commit()?;
    Ok(ImportReport {
        library,
        index,
        unreadable,
        interrupted: false,
    })
}

/// One set's outcome: the candidate or why not, and the message of an unreadable file.
type SetOutcome = (Result<Candidate, Rejection>, Option<String>);

/// Every texture set of source `index` converted into `staging` in parallel; `None` when the
/// stop flag was set meanwhile.
fn import_source(
    tree: &SourceTree,
    package: &PackageSource,
    index: usize,
    staging: &Path,
    options: &ImportOptions,
    stop: &AtomicBool,
    progress: &(dyn Fn(ImportEvent) + Sync),
) -> Option<Vec<SetOutcome>> {
    let sets = find_sets(tree);
    progress(ImportEvent::Source {
        package: package.package.name.clone(),
        sets: sets.len(),
    });
    let results: Vec<SetOutcome> = sets
        .into_par_iter()
        .map(|set| {
            if stop.load(Ordering::SeqCst) {
                return (Err(Rejection::Unreadable), None);
            }
            let outcome = import_set(tree, package, &set, index, staging, options);
            progress(ImportEvent::Set);
            match outcome {
                Ok(candidate) => (Ok(candidate), None),
                Err(SetFailure::Rejected(r)) => (Err(r), None),
                Err(SetFailure::Unreadable(message)) => {
                    progress(ImportEvent::Unreadable(message.clone()));
                    (Err(Rejection::Unreadable), Some(message))
                }
            }
        })
        .collect();
    (!stop.load(Ordering::SeqCst)).then_some(results)
}

/// The index entries of `candidates` (sorted by id): the first of each near-duplicate cluster
/// kept and given its split, the others removed from `staging` and counted as duplicates in
/// their package's entry.
fn deduplicate_and_split(
    mut candidates: Vec<Candidate>,
    packages: &mut [PackageEntry],
    staging: &Path,
    options: &ImportOptions,
) -> anyhow::Result<Vec<IndexEntry>> {
    candidates.sort_by(|a, b| a.id.cmp(&b.id));
    let signatures: Vec<Signature> = candidates.iter().map(|c| c.signature.clone()).collect();
    let cluster_of = clusters(&signatures);
    let mut seen_clusters = std::collections::BTreeSet::new();
    let mut materials = Vec::new();
    for (candidate, cluster) in candidates.into_iter().zip(cluster_of) {
        let package = &mut packages[candidate.source];
        if !seen_clusters.insert(cluster) {
            let dir = staging.join(MATERIALS_DIR).join(&candidate.id);
            std::fs::remove_dir_all(&dir)
                .with_context(|| format!("cannot remove the duplicate {}", dir.display()))?;
            *package.rejected.entry(Rejection::Duplicate).or_default() += 1;
            continue;
        }
        let split = split_of(&candidate.id, options.seed, options.shares);
        *package.materials.entry(split).or_default() += 1;
        for licence in &candidate.licences {
            *package.licences.entry(licence.clone()).or_default() += 1;
        }
        materials.push(IndexEntry {
            // The kept material is its cluster's first, and names it.
            cluster: candidate.id.clone(),
            id: candidate.id,
            split,
            package: package.package.name.clone(),
            base: candidate.set.base,
            licences: candidate.licences,
            side: candidate.side,
            height_scale: candidate.height_scale,
        });
    }
    Ok(materials)
}

fn empty_index(options: &ImportOptions) -> LibraryIndex {
    LibraryIndex {
        format: crate::index::FORMAT_TAG.into(),
        version: crate::index::FORMAT_VERSION,
        seed: options.seed,
        shares: options.shares,
        packages: Vec::new(),
        materials: Vec::new(),
    }
}

/// Why one set was not imported.
enum SetFailure {
    Rejected(Rejection),
    /// A file cannot be read or decoded: the message names it.
    Unreadable(String),
}

impl From<Rejection> for SetFailure {
    fn from(r: Rejection) -> Self {
        SetFailure::Rejected(r)
    }
}

/// The material id of a set: `<package>/<slug of the base's path>` (module docs of
/// [`crate::index`]).
pub fn material_id(package: &str, base: &str) -> String {
    // Debian installs game data under usr/share/games/<game>/: the rest names the texture.
    let rest = base
        .strip_prefix("usr/share/games/")
        .and_then(|r| r.split_once('/').map(|(_, r)| r))
        .unwrap_or(base);
    let file_start = rest.rfind('/').map_or(0, |i| i + 1);
    // Every extension goes (`cliff_01.png.cached.dds` → `cliff_01`).
    let stem_end = rest[file_start..]
        .find('.')
        .map_or(rest.len(), |i| file_start + i);
    let slug: String = rest[..stem_end]
        .chars()
        .map(|c| match c {
            '/' => '-',
            c if c.is_ascii_alphanumeric() || c == '_' || c == '-' => c,
            _ => '_',
        })
        .collect();
    format!("{package}/{slug}")
}

/// Reads, converts and writes one set (module docs).
fn import_set(
    tree: &SourceTree,
    package: &PackageSource,
    set: &TextureSet,
    source: usize,
    staging: &Path,
    options: &ImportOptions,
) -> Result<Candidate, SetFailure> {
    if set.emissive {
        return Err(Rejection::Emissive.into());
    }
    if not_surface(&set.base) {
        return Err(Rejection::NotSurface.into());
    }
    if set.borrowed_normal {
        return Err(Rejection::BorrowedNormal.into());
    }
    if let Some(missing) = set.missing.first() {
        return Err(SetFailure::Unreadable(format!(
            "{} names `{missing}` for the base colour {}, and the package has no such file",
            tree.display_path(&set.defined_in),
            set.base
        )));
    }
    let normal_path = set.normal.as_ref().ok_or(Rejection::NoNormal)?;
    let read = |path: &str| -> Result<Vec<u8>, SetFailure> {
        let file = tree
            .find(path)
            .ok_or_else(|| SetFailure::Unreadable(format!("{path}: listed but not found")))?;
        tree.read(file)
            .map_err(|e| SetFailure::Unreadable(e.to_string()))
    };
    let base_bytes = read(&set.base)?;
    // The sizes in the header first: a texture too small is left out before it is decoded.
    let (w, h) =
        dimensions(&base_bytes, &set.base).map_err(|e| SetFailure::Unreadable(e.to_string()))?;
    if w.min(h) < options.convert.min_side {
        return Err(Rejection::TooSmall.into());
    }
    let decode = |path: &str, bytes: &[u8]| {
        decode_rgba(bytes, path).map_err(|e| SetFailure::Unreadable(e.to_string()))
    };
    let optional = |path: &Option<String>| -> Result<_, SetFailure> {
        path.as_deref().map(|p| decode(p, &read(p)?)).transpose()
    };
    let decoded = DecodedSet {
        base: decode(&set.base, &base_bytes)?,
        normal: Some(decode(normal_path, &read(normal_path)?)?),
        specular: optional(&set.specular)?,
        gloss: optional(&set.gloss)?,
        roughness: optional(&set.roughness)?,
        height: optional(&set.height)?,
        normal_strength: set.normal_strength,
        specular_power: set.specular_power,
    };
    let images = convert(&decoded, &options.convert)?;
    let licence_of = |path: &str| {
        let licence = package.copyright.licence_of(path);
        SourceFileRecord {
            path: path.to_string(),
            licence: licence.map_or_else(|| "unknown".to_string(), |l| l.name.clone()),
            holders: licence.map(|l| l.holders.clone()).unwrap_or_default(),
        }
    };
    let provenance = Provenance::new(&package.package, set, &images, &licence_of);
    let id = material_id(&package.package.name, &set.base);
    let dir = staging.join(MATERIALS_DIR).join(&id);
    write_material(&dir, &images, &provenance)
        .map_err(|e| SetFailure::Unreadable(format!("cannot write {}: {e}", dir.display())))?;
    let base_rgb = crate::resample::resize(&images.diffuse, 64, 64);
    Ok(Candidate {
        id,
        source,
        set: set.clone(),
        signature: Signature::new(&base_rgb, &images.normal),
        licences: provenance.licences,
        side: images.side(),
        height_scale: images.height.scale,
    })
}

/// The materials of the library at `dir` in `split`: their ids and folders.
pub fn split_folders(dir: &Path, split: Split) -> anyhow::Result<Vec<(String, PathBuf)>> {
    let index = LibraryIndex::load(dir)?;
    Ok(index
        .split(split)
        .into_iter()
        .map(|m| (m.id.clone(), dir.join(MATERIALS_DIR).join(&m.id)))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn material_ids_name_the_package_and_the_texture_path() {
        assert_eq!(
            material_id(
                "redeclipse-data",
                "usr/share/games/redeclipse/data/trak/trak5/wall4a.jpg"
            ),
            "redeclipse-data/data-trak-trak5-wall4a"
        );
        assert_eq!(
            material_id(
                "0ad-data",
                "usr/share/games/0ad/mods/public/public.zip/art/textures/terrain/types/india/paving_01.png.cached.dds"
            ),
            "0ad-data/mods-public-public_zip-art-textures-terrain-types-india-paving_01"
        );
        assert_eq!(material_id("mine", "rock one.png"), "mine/rock_one");
    }
}
