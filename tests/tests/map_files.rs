//! The material-map folder (`photomat_core::map_files`): save → load round trips (EXR exact,
//! PNG within quantisation), the manifest's contents, and one test per kind of bad input,
//! each checking that the error names the offending file.

use photomat_tests as _;

use std::fs;
use std::path::{Path, PathBuf};

use candle_core::{DType, Device, Tensor};
use photomat_core::image_io::{PlanarImage, read_png, write_exr};
use photomat_core::map_files::{
    FORMAT_TAG, FORMAT_VERSION, MANIFEST_FILE, PngBits, RANGE_TOLERANCE, SaveOptions, load_maps,
    save_maps,
};
use photomat_core::testing::{check_exr_round_trip, check_png_round_trip};
use photomat_core::{Brdf, Error, MaterialMaps, registered_names};
use photomat_tests::{expected_builtins, model, random_maps, rng, values};

const SIZE: usize = 16;

/// Random in-range maps for `brdf` with unit normals (a PNG stores directions only).
fn unit_maps(brdf: &Brdf, seed: u64) -> MaterialMaps {
    let mut maps = random_maps(brdf, &mut rng(seed), SIZE, 0.05, DType::F32);
    if let Ok(normal) = maps.get("normal").cloned() {
        maps.insert(
            "normal",
            photomat_core::vecops::normalize3(&normal).unwrap(),
        );
    }
    maps
}

/// Save `spec`'s random maps into a fresh folder.
fn saved(spec: &str, options: &SaveOptions) -> (tempfile::TempDir, Brdf, MaterialMaps) {
    let brdf = model(spec);
    let maps = unit_maps(&brdf, 7);
    let dir = tempfile::tempdir().unwrap();
    save_maps(dir.path(), brdf.as_ref(), &maps, options).unwrap();
    (dir, brdf, maps)
}

fn manifest_json(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(dir.join(MANIFEST_FILE)).unwrap()).unwrap()
}

fn write_manifest_json(dir: &Path, value: &serde_json::Value) {
    fs::write(
        dir.join(MANIFEST_FILE),
        serde_json::to_string_pretty(value).unwrap(),
    )
    .unwrap();
}

/// Remove every map's "exr" entry, so that loading falls back to the PNGs.
fn drop_exr_entries(dir: &Path) {
    let mut manifest = manifest_json(dir);
    for entry in manifest["maps"].as_array_mut().unwrap() {
        entry.as_object_mut().unwrap().remove("exr");
    }
    write_manifest_json(dir, &manifest);
}

/// The error of loading `dir`, which must be a file error: (path, reason).
fn load_error(dir: &Path) -> (PathBuf, String) {
    match load_maps(dir, None) {
        Ok(_) => panic!("loading {} should fail", dir.display()),
        Err(Error::File { path, reason }) => (path, reason),
        Err(other) => panic!("expected a file error, got: {other}"),
    }
}

#[test]
fn map_files_registry_has_the_builtins() {
    assert_eq!(registered_names().unwrap(), expected_builtins());
}

#[test]
fn map_files_exr_round_trip_is_exact() {
    // The conformance kit's check: model name, map names, shapes, dtype and values restored.
    for spec in [
        "lambert",
        "ggx",
        "coated",
        "height(ggx)",
        "height(ggx, scale=0.05)",
    ] {
        check_exr_round_trip(spec).unwrap();
    }
}

#[test]
fn map_files_f64_maps_round_trip_as_their_f32_values() {
    let brdf = model("ggx");
    let maps = unit_maps(&brdf, 3)
        .map_tensors(|t| Ok(t.to_dtype(DType::F64)?))
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    save_maps(dir.path(), brdf.as_ref(), &maps, &SaveOptions::default()).unwrap();
    let loaded = load_maps(dir.path(), None).unwrap();
    for (name, original) in maps.iter() {
        let expected = original.to_dtype(DType::F32).unwrap();
        assert_eq!(values(loaded.maps.get(name).unwrap()), values(&expected));
    }
}

#[test]
fn map_files_png_round_trip_is_within_quantisation() {
    // The conformance kit's check: half a quantisation step times the colour space's slope.
    for bits in [PngBits::Sixteen, PngBits::Eight] {
        for spec in ["ggx", "coated", "height(ggx)"] {
            check_png_round_trip(spec, bits).unwrap();
        }
    }
}

#[test]
fn map_files_png_layout_follows_channels_and_bits() {
    for bits in [PngBits::Sixteen, PngBits::Eight] {
        let (dir, brdf, maps) = saved(
            "ggx",
            &SaveOptions {
                png_bits: bits,
                ..SaveOptions::default()
            },
        );
        for p in brdf.params() {
            let (image, file_bits) = read_png(&dir.path().join(format!("{}.png", p.name))).unwrap();
            assert_eq!(file_bits, bits);
            assert_eq!(
                (image.channels, image.height, image.width),
                (p.channels, SIZE, SIZE)
            );
        }
        // Albedos are stored gamma-encoded, roughness linearly, normals as 0.5·n + 0.5.
        let stored = |name: &str| read_png(&dir.path().join(format!("{name}.png"))).unwrap().0;
        let step = 1.0 / bits.max_value() as f64;
        let check = |name: &str, encode: &dyn Fn(f64) -> f64| {
            let original = values(maps.get(name).unwrap());
            for (s, v) in stored(name).data.iter().zip(original) {
                assert!(
                    (*s as f64 - encode(v)).abs() <= 0.5 * step + 1e-6,
                    "{name}: {s} vs {v}"
                );
            }
        };
        check("diffuse", &|v| v.powf(1.0 / 2.2));
        check("roughness", &|v| v);
        check("normal", &|v| 0.5 * v + 0.5);
    }
}

#[test]
fn map_files_manifest_records_the_model_and_maps() {
    let (dir, brdf, _) = saved("height(ggx, scale=0.05)", &SaveOptions::default());
    let m = manifest_json(dir.path());
    assert_eq!(m["format"], FORMAT_TAG);
    assert_eq!(m["version"], FORMAT_VERSION);
    assert_eq!(m["brdf"], "height(ggx, scale=0.05)");
    assert_eq!(m["args"]["scale"], 0.05);
    assert_eq!(m["resolution"], SIZE);
    let entries = m["maps"].as_array().unwrap();
    let names: Vec<&str> = entries
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["diffuse", "specular", "roughness", "height"]);
    for (entry, spec) in entries.iter().zip(brdf.params()) {
        assert_eq!(entry["channels"], spec.channels);
        assert_eq!(entry["png"], format!("{}.png", spec.name));
        assert_eq!(entry["exr"], format!("{}.exr", spec.name));
        assert_eq!(entry["png_bits"], 16);
        assert_eq!(
            entry["range"],
            serde_json::json!([spec.range.0, spec.range.1])
        );
        assert_eq!(
            entry["color_space"],
            serde_json::to_value(spec.color_space).unwrap()
        );
    }
    assert_eq!(entries[0]["color_space"], "gamma22");
    assert_eq!(entries[3]["color_space"], "linear");
}

#[test]
fn map_files_folder_holds_only_the_listed_files() {
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    // Saving twice replaces the files in place and leaves no temporary files behind.
    let brdf = model("ggx");
    save_maps(
        dir.path(),
        brdf.as_ref(),
        &unit_maps(&brdf, 9),
        &SaveOptions::default(),
    )
    .unwrap();
    let mut files: Vec<String> = fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    let mut expected = vec![MANIFEST_FILE.to_string()];
    for name in ["diffuse", "specular", "roughness", "normal"] {
        expected.push(format!("{name}.png"));
        expected.push(format!("{name}.exr"));
    }
    expected.sort();
    assert_eq!(files, expected);
}

#[test]
fn map_files_override_loads_the_maps_it_takes() {
    let (dir, _, maps) = saved("ggx", &SaveOptions::default());
    let loaded = load_maps(dir.path(), Some(model("lambert"))).unwrap();
    assert_eq!(loaded.brdf.name(), "lambert");
    assert_eq!(loaded.maps.names(), ["diffuse", "normal"]);
    assert_eq!(
        values(loaded.maps.get("diffuse").unwrap()),
        values(maps.get("diffuse").unwrap())
    );
    assert_eq!(loaded.manifest.brdf, "ggx");

    let err = load_maps(dir.path(), Some(model("height(ggx)")))
        .err()
        .unwrap();
    let Error::File { path, reason } = err else {
        panic!("{err}")
    };
    assert_eq!(path, dir.path().join(MANIFEST_FILE));
    assert!(reason.contains("'height'"), "{reason}");
}

#[test]
fn map_files_missing_manifest_names_the_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, dir.path().join(MANIFEST_FILE));
    assert!(reason.contains("cannot read"), "{reason}");
    let full = load_maps(dir.path(), None).err().unwrap().to_string();
    assert!(full.contains("material.json"), "{full}");
}

#[test]
fn map_files_corrupt_manifest_names_the_manifest() {
    let (dir, _, _) = saved("lambert", &SaveOptions::default());
    let manifest = dir.path().join(MANIFEST_FILE);
    let text = fs::read_to_string(&manifest).unwrap();
    fs::write(&manifest, &text[..text.len() / 2]).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, manifest);
    assert!(
        reason.contains("corrupt") && reason.contains("JSON"),
        "{reason}"
    );

    // Valid JSON of the wrong shape (resolution as a string) is corrupt too.
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    m["resolution"] = "big".into();
    write_manifest_json(dir.path(), &m);
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, manifest);
    assert!(
        reason.contains("corrupt") && reason.contains("line"),
        "{reason}"
    );

    // Another program's JSON.
    fs::write(&manifest, r#"{"format": "gltf"}"#).unwrap();
    let (_, reason) = load_error(dir.path());
    assert!(
        reason.contains("not a photomat material manifest"),
        "{reason}"
    );
}

#[test]
fn map_files_newer_version_is_refused() {
    let (dir, _, _) = saved("lambert", &SaveOptions::default());
    let mut m = manifest_json(dir.path());
    m["version"] = (FORMAT_VERSION + 1).into();
    write_manifest_json(dir.path(), &m);
    let (_, reason) = load_error(dir.path());
    assert!(reason.contains("newer photomat"), "{reason}");
}

#[test]
fn map_files_unknown_brdf_lists_known_names() {
    let (dir, _, _) = saved("lambert", &SaveOptions::default());
    let mut m = manifest_json(dir.path());
    m["brdf"] = "phong".into();
    write_manifest_json(dir.path(), &m);
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, dir.path().join(MANIFEST_FILE));
    assert!(reason.contains("'phong'"), "{reason}");
    assert!(reason.contains(&expected_builtins().join(", ")), "{reason}");
}

#[test]
fn map_files_wrong_channel_count_names_the_file() {
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let exr = dir.path().join("diffuse.exr");
    write_exr(&exr, &PlanarImage::filled(1, SIZE, SIZE, 0.5)).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, exr);
    assert!(
        reason.contains("1 channel") && reason.contains("needs 3"),
        "{reason}"
    );

    // The manifest itself disagreeing with the model is the manifest's fault.
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let mut m = manifest_json(dir.path());
    m["maps"][2]["channels"] = 3.into();
    write_manifest_json(dir.path(), &m);
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, dir.path().join(MANIFEST_FILE));
    assert!(
        reason.contains("'roughness'") && reason.contains("needs 1"),
        "{reason}"
    );
}

#[test]
fn map_files_mismatched_map_sizes_name_the_file() {
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let exr = dir.path().join("roughness.exr");
    write_exr(&exr, &PlanarImage::filled(1, SIZE / 2, SIZE / 2, 0.5)).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, exr);
    assert!(
        reason.contains(&format!("{0}×{0}", SIZE / 2)) && reason.contains("resolution"),
        "{reason}"
    );

    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let exr = dir.path().join("specular.exr");
    write_exr(&exr, &PlanarImage::filled(3, SIZE, SIZE + 1, 0.5)).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, exr);
    assert!(reason.contains("square"), "{reason}");
}

#[test]
fn map_files_nan_in_exr_names_the_file() {
    for bad in [f32::NAN, f32::INFINITY] {
        let (dir, _, _) = saved("ggx", &SaveOptions::default());
        let exr = dir.path().join("diffuse.exr");
        let mut image = PlanarImage::filled(3, SIZE, SIZE, 0.5);
        image.data[2 * SIZE * SIZE + 3 * SIZE + 5] = bad;
        write_exr(&exr, &image).unwrap();
        let (path, reason) = load_error(dir.path());
        assert_eq!(path, exr);
        assert!(
            reason.contains("non-finite") && reason.contains("row 3, column 5, channel B"),
            "{reason}"
        );
    }
}

#[test]
fn map_files_out_of_range_value_names_the_file() {
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let exr = dir.path().join("roughness.exr");
    let mut image = PlanarImage::filled(1, SIZE, SIZE, 0.5);
    image.data[7] = 1.0 + 10.0 * RANGE_TOLERANCE;
    write_exr(&exr, &image).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, exr);
    assert!(
        reason.contains("outside its range [0, 1]") && reason.contains("column 7"),
        "{reason}"
    );

    // Within the documented tolerance: accepted and kept as written.
    image.data[7] = 1.0 + 0.5 * RANGE_TOLERANCE;
    write_exr(&exr, &image).unwrap();
    let loaded = load_maps(dir.path(), None).unwrap();
    assert_eq!(
        values(loaded.maps.get("roughness").unwrap())[7],
        image.data[7] as f64
    );
}

#[test]
fn map_files_corrupt_png_names_the_file() {
    // PNG-only folder: the PNG is decoded.
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    drop_exr_entries(dir.path());
    let png = dir.path().join("specular.png");
    let bytes = fs::read(&png).unwrap();
    fs::write(&png, &bytes[..bytes.len() / 2]).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, png);
    assert!(reason.contains("PNG"), "{reason}");

    // Beside an EXR the PNG's header is still checked.
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let png = dir.path().join("normal.png");
    fs::write(&png, b"not a png at all").unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, png);
    assert!(reason.contains("PNG"), "{reason}");
}

#[test]
fn map_files_missing_map_file_names_the_file() {
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let exr = dir.path().join("normal.exr");
    fs::remove_file(&exr).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, exr);
    assert!(
        reason.contains("missing") && reason.contains("'normal'"),
        "{reason}"
    );
}

#[test]
fn map_files_a_folder_in_place_of_a_map_file_is_not_called_missing() {
    let (dir, _, _) = saved("ggx", &SaveOptions::default());
    let exr = dir.path().join("diffuse.exr");
    fs::remove_file(&exr).unwrap();
    fs::create_dir(&exr).unwrap();
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, exr);
    assert!(
        reason.contains("is not a file") && !reason.contains("missing"),
        "{reason}"
    );
}

#[test]
fn map_files_an_unknown_model_with_args_names_the_model() {
    let (dir, _, _) = saved("height(ggx, scale=0.05)", &SaveOptions::default());
    let mut m = manifest_json(dir.path());
    // The args no longer match the spelling either; the unknown name is what to fix first.
    m["brdf"] = "hieght(ggx)".into();
    write_manifest_json(dir.path(), &m);
    let (path, reason) = load_error(dir.path());
    assert_eq!(path, dir.path().join(MANIFEST_FILE));
    assert!(
        reason.contains("unknown BRDF model 'hieght'") && !reason.contains("disagrees"),
        "{reason}"
    );
}

#[test]
fn map_files_png_normals_are_renormalised() {
    let (dir, _, maps) = saved("lambert", &SaveOptions::default());
    drop_exr_entries(dir.path());
    let loaded = load_maps(dir.path(), None).unwrap();
    let n = loaded.maps.get("normal").unwrap();
    let len2 = values(&n.sqr().unwrap().sum_keepdim(1).unwrap());
    assert!(len2.iter().all(|l| (l - 1.0).abs() < 1e-6), "{len2:?}");
    assert!(
        photomat_kernels::testing::max_abs_diff(n, maps.get("normal").unwrap()).unwrap() < 1e-4
    );
}

#[test]
fn map_files_save_rejects_what_would_not_load() {
    let brdf = model("ggx");
    let dir = tempfile::tempdir().unwrap();
    let options = SaveOptions::default();

    let batch = random_maps(&brdf, &mut rng(1), 8, 0.1, DType::F32)
        .map_tensors(|t| Ok(Tensor::cat(&[t, t], 0)?))
        .unwrap();
    let err = save_maps(dir.path(), brdf.as_ref(), &batch, &options)
        .unwrap_err()
        .to_string();
    assert!(err.contains("batch of 2"), "{err}");

    let mut maps = unit_maps(&brdf, 2);
    maps.insert(
        "roughness",
        Tensor::full(1.5f32, (1, 1, SIZE, SIZE), &Device::Cpu).unwrap(),
    );
    let err = save_maps(dir.path(), brdf.as_ref(), &maps, &options)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("'roughness'") && err.contains("outside"),
        "{err}"
    );

    let lambert_maps = unit_maps(&model("lambert"), 2);
    let err = save_maps(dir.path(), brdf.as_ref(), &lambert_maps, &options)
        .unwrap_err()
        .to_string();
    assert!(err.contains("missing map 'specular'"), "{err}");

    // Nothing was written by the failed saves.
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn map_folder_keeps_the_texel_size_of_a_spatial_models_maps() {
    let brdf = model("height(ggx)");
    let maps = unit_maps(&brdf, 3).with_texel_size(Some(1.0 / 128.0));
    let dir = tempfile::tempdir().unwrap();
    save_maps(dir.path(), brdf.as_ref(), &maps, &SaveOptions::default()).unwrap();
    assert_eq!(manifest_json(dir.path())["texel_size"], 1.0 / 128.0);
    let loaded = load_maps(dir.path(), None).unwrap();
    assert_eq!(loaded.maps.texel_size(), Some(1.0 / 128.0));

    // Unit-square maps write no texel size (older readers and manifests stay as they were).
    let (plain, _, _) = saved("height(ggx)", &SaveOptions::default());
    assert!(manifest_json(plain.path()).get("texel_size").is_none());
    assert_eq!(
        load_maps(plain.path(), None).unwrap().maps.texel_size(),
        None
    );

    let mut manifest = manifest_json(dir.path());
    manifest["texel_size"] = serde_json::json!(-0.5);
    write_manifest_json(dir.path(), &manifest);
    let err = load_maps(dir.path(), None).err().unwrap().to_string();
    assert!(
        err.contains("texel_size") && err.contains("material.json"),
        "{err}"
    );
}
