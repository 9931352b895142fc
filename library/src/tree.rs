//! A package's files as one tree: a folder on disk (an extracted Debian package) or a single
//! archive, with every zip archive inside it (`.zip`, `.pk3`: Quake-style game data, 0 A.D.'s
//! `public.zip`) opened as a folder of its own, so that material files and the textures they
//! name are found by one path syntax whatever holds them (docs/data.md, "Importing").
//!
//! Paths are relative to the tree's root, `/`-separated; a file inside an archive is named by
//! the archive's path followed by its path in the archive
//! (`usr/share/games/0ad/mods/public/public.zip/art/textures/terrain/types/x.png.cached.dds`).
//! Archives inside archives are not opened (no package this importer knows nests them).
//!
//! Reading checks each file's size before it allocates ([`MAX_FILE_BYTES`]); a damaged archive
//! is an error naming it.

use std::collections::HashMap;
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use photomat_core::{Error, Result};

/// Largest file the importer reads: 256 MB, well above a 4096² RGBA texture (64 MB raw), so
/// that a corrupt size field cannot make it allocate gigabytes.
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// Extensions of the zip archives opened as folders (compared in lower case).
const ARCHIVE_EXTENSIONS: [&str; 2] = ["zip", "pk3"];

/// One file of a [`SourceTree`].
#[derive(Debug, Clone)]
pub struct SourceFile {
    /// Path in the tree (module docs).
    pub path: String,
    /// Size in bytes (uncompressed, for a file inside an archive).
    pub size: u64,
    location: Location,
}

#[derive(Debug, Clone)]
enum Location {
    Disk(PathBuf),
    /// Entry `index` of archive `archive` of the tree.
    Archive {
        archive: usize,
        index: usize,
    },
}

/// An opened zip archive; entries are read one at a time (the reader needs `&mut`).
struct Archive {
    path: PathBuf,
    zip: Mutex<zip::ZipArchive<File>>,
}

/// The files of a folder or archive, archives inside opened (module docs).
pub struct SourceTree {
    root: PathBuf,
    files: Vec<SourceFile>,
    by_path: HashMap<String, usize>,
    by_lower_path: HashMap<String, usize>,
    archives: Vec<Archive>,
}

impl SourceTree {
    /// Lists `root` (a folder, walked recursively, or one archive file) and the archives in
    /// it. Errors name the folder or archive that cannot be read.
    pub fn open(root: &Path) -> Result<Self> {
        let mut tree = Self {
            root: root.to_path_buf(),
            files: Vec::new(),
            by_path: HashMap::new(),
            by_lower_path: HashMap::new(),
            archives: Vec::new(),
        };
        let meta = std::fs::metadata(root)
            .map_err(|e| Error::file(root, format!("cannot read the source: {e}")))?;
        if meta.is_dir() {
            tree.walk(root, "")?;
        } else if is_archive(&root.to_string_lossy()) {
            tree.add_archive(root, "")?;
        } else {
            return Err(Error::file(
                root,
                "is neither a folder nor a zip/pk3 archive (give an extracted package folder or \
                 an archive)",
            ));
        }
        tree.files.sort_by(|a, b| a.path.cmp(&b.path));
        for (i, file) in tree.files.iter().enumerate() {
            tree.by_path.insert(file.path.clone(), i);
            tree.by_lower_path.insert(file.path.to_lowercase(), i);
        }
        Ok(tree)
    }

    /// The folder or archive the tree was opened from.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Every file, sorted by path.
    pub fn files(&self) -> &[SourceFile] {
        &self.files
    }

    /// The file at `path`, or at a path that differs from it only in letter case (game data
    /// made on Windows names its textures inconsistently).
    pub fn find(&self, path: &str) -> Option<&SourceFile> {
        let index = self
            .by_path
            .get(path)
            .or_else(|| self.by_lower_path.get(&path.to_lowercase()))?;
        Some(&self.files[*index])
    }

    /// A readable name of `file` for errors: its place on disk, inside its archive if it is in
    /// one.
    pub fn display(&self, file: &SourceFile) -> String {
        match &file.location {
            Location::Disk(path) => path.display().to_string(),
            Location::Archive { archive, .. } => {
                let archive = &self.archives[*archive].path;
                let inner = file
                    .path
                    .rsplit_once(".zip/")
                    .or(file.path.rsplit_once(".pk3/"));
                format!(
                    "{} (in {})",
                    inner.map_or(file.path.as_str(), |(_, p)| p),
                    archive.display()
                )
            }
        }
    }

    /// [`Self::display`] of the file at tree path `path`, or the path itself when the tree has
    /// no such file.
    pub fn display_path(&self, path: &str) -> String {
        self.find(path)
            .map_or_else(|| path.to_string(), |f| self.display(f))
    }

    /// The bytes of `file`; errors name it.
    pub fn read(&self, file: &SourceFile) -> Result<Vec<u8>> {
        if file.size > MAX_FILE_BYTES {
            return Err(Error::file(
                self.display(file),
                format!(
                    "is {} bytes, over the importer's limit of {MAX_FILE_BYTES} \
                     (photomat_library::tree::MAX_FILE_BYTES)",
                    file.size
                ),
            ));
        }
        match &file.location {
            Location::Disk(path) => {
                std::fs::read(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))
            }
            Location::Archive { archive, index } => {
                let archive = &self.archives[*archive];
                let mut zip = archive.zip.lock().map_err(|_| {
                    Error::file(&archive.path, "an earlier read of the archive panicked")
                })?;
                let mut entry = zip.by_index(*index).map_err(|e| {
                    Error::file(self.display(file), format!("cannot read the entry: {e}"))
                })?;
                let mut bytes = Vec::with_capacity(file.size as usize);
                entry
                    .by_ref()
                    .take(MAX_FILE_BYTES + 1)
                    .read_to_end(&mut bytes)
                    .map_err(|e| {
                        Error::file(self.display(file), format!("cannot decompress: {e}"))
                    })?;
                Ok(bytes)
            }
        }
    }

    /// Adds the files under `dir`, whose tree path is `prefix`, opening archives.
    fn walk(&mut self, dir: &Path, prefix: &str) -> Result<()> {
        let mut entries: Vec<_> = std::fs::read_dir(dir)
            .map_err(|e| Error::file(dir, format!("cannot list the folder: {e}")))?
            .collect::<std::io::Result<_>>()
            .map_err(|e| Error::file(dir, format!("cannot list the folder: {e}")))?;
        entries.sort_by_key(|e| e.file_name());
        for entry in entries {
            let name = entry.file_name().to_string_lossy().into_owned();
            let path = entry.path();
            let tree_path = join(prefix, &name);
            // Symbolic links are skipped: Debian packages link their data into compatibility
            // paths (`usr/lib/games/redeclipse/data`), which would list it twice.
            let meta = std::fs::symlink_metadata(&path)
                .map_err(|e| Error::file(&path, format!("cannot read: {e}")))?;
            if meta.is_dir() {
                self.walk(&path, &tree_path)?;
            } else if meta.is_file() {
                if is_archive(&name) {
                    self.add_archive(&path, &tree_path)?;
                }
                self.files.push(SourceFile {
                    path: tree_path,
                    size: meta.len(),
                    location: Location::Disk(path),
                });
            }
        }
        Ok(())
    }

    /// Opens the archive at `path` and adds its files under `prefix`.
    fn add_archive(&mut self, path: &Path, prefix: &str) -> Result<()> {
        let file = File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))?;
        let mut zip = zip::ZipArchive::new(file)
            .map_err(|e| Error::file(path, format!("is not a readable zip archive: {e}")))?;
        let archive = self.archives.len();
        for index in 0..zip.len() {
            let entry = zip
                .by_index_raw(index)
                .map_err(|e| Error::file(path, format!("damaged entry {index}: {e}")))?;
            if entry.is_dir() {
                continue;
            }
            let Some(inner) = entry.enclosed_name() else {
                // An entry escaping its folder (`../`) names nothing this importer reads.
                continue;
            };
            let inner = inner.to_string_lossy().replace('\\', "/");
            self.files.push(SourceFile {
                path: join(prefix, &inner),
                size: entry.size(),
                location: Location::Archive { archive, index },
            });
        }
        self.archives.push(Archive {
            path: path.to_path_buf(),
            zip: Mutex::new(zip),
        });
        Ok(())
    }
}

/// `prefix/name`, or `name` at the root.
fn join(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_string()
    } else {
        format!("{prefix}/{name}")
    }
}

/// Whether a file name is a zip archive the tree opens.
fn is_archive(name: &str) -> bool {
    let lower = name.to_lowercase();
    ARCHIVE_EXTENSIONS
        .iter()
        .any(|ext| lower.ends_with(&format!(".{ext}")))
}

/// The folder of a tree path (`""` at the root).
pub fn parent(path: &str) -> &str {
    path.rsplit_once('/').map_or("", |(dir, _)| dir)
}

/// The file name of a tree path.
pub fn file_name(path: &str) -> &str {
    path.rsplit_once('/').map_or(path, |(_, name)| name)
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use super::*;

    #[test]
    fn archives_open_as_folders_and_lookups_ignore_case() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("data/wood")).unwrap();
        std::fs::write(dir.path().join("data/wood/plank.png"), b"png").unwrap();
        let zip_path = dir.path().join("data/pak0.pk3");
        let mut zip = zip::ZipWriter::new(File::create(&zip_path).unwrap());
        zip.start_file(
            "textures/Rock_N.jpg",
            zip::write::SimpleFileOptions::default(),
        )
        .unwrap();
        zip.write_all(b"jpeg bytes").unwrap();
        zip.finish().unwrap();
        let tree = SourceTree::open(dir.path()).unwrap();
        let paths: Vec<&str> = tree.files().iter().map(|f| f.path.as_str()).collect();
        assert_eq!(
            paths,
            [
                "data/pak0.pk3",
                "data/pak0.pk3/textures/Rock_N.jpg",
                "data/wood/plank.png"
            ]
        );
        let inner = tree.find("data/pak0.pk3/textures/rock_n.JPG").unwrap();
        assert_eq!(tree.read(inner).unwrap(), b"jpeg bytes");
        assert!(tree.display(inner).contains("textures/Rock_N.jpg (in "));
        assert_eq!(
            tree.read(tree.find("data/wood/plank.png").unwrap())
                .unwrap(),
            b"png"
        );
    }

    #[test]
    fn a_damaged_archive_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("broken.pk3"), b"not a zip at all").unwrap();
        let err = SourceTree::open(dir.path()).err().unwrap().to_string();
        assert!(
            err.contains("broken.pk3") && err.contains("not a readable zip archive"),
            "{err}"
        );
    }
}
