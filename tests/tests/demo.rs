//! `photomat demo`: the README's first command writes a material folder that loads back
//! through the engine loader, and pictures of the expected sizes, deterministically per seed.

use photomat_core::image_io::read_png;
use photomat_core::map_files::load_maps;
use photomat_tests as _;

fn demo(dir: &std::path::Path, seed: &str) {
    let out = dir.to_str().unwrap();
    photomat_cli::run_with_output(
        [
            "photomat", "demo", "--out", out, "--size", "32", "--seed", seed, "--orbit", "4",
        ],
        &mut Vec::new(),
    )
    .unwrap();
}

#[test]
fn demo_writes_a_loadable_material_and_its_pictures() {
    let dir = tempfile::tempdir().unwrap();
    demo(dir.path(), "3");
    let material = load_maps(&dir.path().join("material"), None).unwrap();
    assert_eq!(material.brdf.channels(), 8);
    assert_eq!(material.maps.batch_and_size().unwrap(), (1, 32, 32));
    let size = |name: &str| {
        let (img, _) = read_png(&dir.path().join(name)).unwrap();
        (img.channels, img.height, img.width)
    };
    assert_eq!(size("render.png"), (3, 32, 32));
    // 4 renders on a 2×2 sheet with a 4-pixel gap; 5 map previews on a 3×2 sheet.
    assert_eq!(size("orbit.png"), (3, 68, 68));
    assert_eq!(size("maps.png"), (3, 68, 104));
}

#[test]
fn demo_is_deterministic_per_seed() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    demo(a.path(), "5");
    demo(b.path(), "5");
    demo(c.path(), "6");
    let bytes =
        |d: &tempfile::TempDir| std::fs::read(d.path().join("material/diffuse.exr")).unwrap();
    assert_eq!(bytes(&a), bytes(&b));
    assert_ne!(bytes(&a), bytes(&c));
}

#[test]
fn demo_family_picks_the_model_and_unknown_families_are_listed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    photomat_cli::run_with_output(
        [
            "photomat",
            "demo",
            "--out",
            out,
            "--size",
            "32",
            "--family",
            "car_paint",
        ],
        &mut Vec::new(),
    )
    .unwrap();
    let material = load_maps(&dir.path().join("material"), None).unwrap();
    assert_eq!(material.brdf.name(), "coated");
    let err = photomat_cli::run_with_output(
        ["photomat", "demo", "--out", out, "--family", "marble"],
        &mut Vec::new(),
    )
    .expect_err("unknown family must fail")
    .to_string();
    assert!(
        err.contains("'marble'") && err.contains("car_paint, fabric"),
        "{err}"
    );
}
