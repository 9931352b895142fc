//! Declares every plugin file of `src/` as a module, so that a new built-in BRDF is one new
//! file and nothing else (docs/plugins.md, "Layout and naming"): `src/lib.rs` includes the
//! generated list, and the crate's guard test checks that each file registers its stem.

use std::fs;
use std::path::Path;

fn main() {
    let src = Path::new(&std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets it")).join("src");
    // A file added or removed changes the directory's listing; rerun then.
    println!("cargo:rerun-if-changed={}", src.display());
    let mut stems: Vec<String> = fs::read_dir(&src)
        .expect("brdf-plugins/src is readable")
        .map(|e| e.expect("a directory entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .filter_map(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .filter(|stem| stem != "lib")
        .collect();
    stems.sort();
    let mut modules = String::new();
    for stem in &stems {
        let path = src.join(format!("{stem}.rs"));
        modules.push_str(&format!(
            "#[path = {:?}]\npub mod {stem};\n",
            path.display().to_string()
        ));
    }
    let out = Path::new(&std::env::var("OUT_DIR").expect("cargo sets it")).join("plugins.rs");
    fs::write(&out, modules).expect("OUT_DIR is writable");
}
