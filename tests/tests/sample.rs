//! `photomat sample` on tiny untrained model folders: deterministic per seed (byte-identical
//! EXRs), every output folder loads back through the engine loader, the glTF and MaterialX
//! files are structurally valid and reference existing files, the run files (contact sheet,
//! summary) are written, and the tileable / missing-model errors say what is wrong.

use std::collections::BTreeSet;
use std::path::Path;

use candle_core::Device;
use candle_nn::VarMap;
use photomat_core::image_io::png_header;
use photomat_core::lookup;
use photomat_core::map_files::load_maps;
use photomat_estimator::EstimatorModel;
use photomat_generator::{GanModel, GeneratorConfig};
use photomat_tests::cli_fixtures::{tiny_estimator_config, tiny_gan_config};
use serde_json::Value;

/// A tiny untrained model folder (G/M seeded; E saved once and the folder reused, as its
/// initialisation is unseeded).
fn tiny_model(tileable: bool) -> tempfile::TempDir {
    let temp = tempfile::tempdir().unwrap();
    let dir = temp.path();
    let config = GeneratorConfig {
        tileable,
        ..tiny_gan_config(32)
    };
    GanModel::new(&config, 3, &Device::Cpu)
        .unwrap()
        .save(dir, Value::Null)
        .unwrap();
    let brdf = lookup("height(ggx)").unwrap();
    let e_config = tiny_estimator_config(brdf.channels());
    EstimatorModel::new(brdf, e_config, VarMap::new(), &Device::Cpu)
        .unwrap()
        .save(dir, Value::Null)
        .unwrap();
    temp
}

fn sample(args: &[&str]) -> anyhow::Result<String> {
    let mut out = Vec::new();
    let mut argv = vec!["photomat", "sample"];
    argv.extend_from_slice(args);
    photomat_cli::run_with_output(argv, &mut out)?;
    Ok(String::from_utf8(out).unwrap())
}

fn exr_bytes(material: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<_> = std::fs::read_dir(material)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "exr"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 4, "diffuse, specular, roughness, height");
    files
        .into_iter()
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect()
}

/// Every index the glTF uses exists, every URI names a file, asset.version is "2.0".
fn check_gltf(path: &Path) {
    let dir = path.parent().unwrap();
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(doc["asset"]["version"], "2.0");
    let len = |key: &str| doc[key].as_array().map_or(0, Vec::len);
    let idx = |v: &Value| v.as_u64().expect("index") as usize;
    assert!(idx(&doc["scene"]) < len("scenes"));
    for n in doc["scenes"][0]["nodes"].as_array().unwrap() {
        assert!(idx(n) < len("nodes"));
        assert!(idx(&doc["nodes"][idx(n)]["mesh"]) < len("meshes"));
    }
    for p in doc["meshes"][0]["primitives"].as_array().unwrap() {
        for (_, a) in p["attributes"].as_object().unwrap() {
            assert!(idx(a) < len("accessors"));
        }
        assert!(idx(&p["indices"]) < len("accessors"));
        assert!(idx(&p["material"]) < len("materials"));
    }
    for a in doc["accessors"].as_array().unwrap() {
        assert!(idx(&a["bufferView"]) < len("bufferViews"));
    }
    for v in doc["bufferViews"].as_array().unwrap() {
        assert!(idx(&v["buffer"]) < len("buffers"));
    }
    for b in doc["buffers"].as_array().unwrap() {
        let file = dir.join(b["uri"].as_str().unwrap());
        assert_eq!(
            std::fs::metadata(&file).unwrap().len() as usize,
            idx(&b["byteLength"])
        );
    }
    for t in doc["textures"].as_array().unwrap() {
        assert!(idx(&t["sampler"]) < len("samplers"));
        assert!(idx(&t["source"]) < len("images"));
    }
    for i in doc["images"].as_array().unwrap() {
        assert!(dir.join(i["uri"].as_str().unwrap()).is_file());
    }
    let material = &doc["materials"][0];
    let mut texture_indices = vec![
        &material["pbrMetallicRoughness"]["baseColorTexture"]["index"],
        &material["pbrMetallicRoughness"]["metallicRoughnessTexture"]["index"],
        &material["normalTexture"]["index"],
        &material["extensions"]["KHR_materials_specular"]["specularColorTexture"]["index"],
    ];
    texture_indices.retain(|v| !v.is_null());
    assert_eq!(texture_indices.len(), 4, "height(ggx) maps to all four");
    for i in texture_indices {
        assert!(idx(i) < len("textures"));
    }
    let used: Vec<&str> = doc["extensionsUsed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(used.contains(&"KHR_materials_specular"));
}

/// The MaterialX parses, is version 1.38 and its file inputs name existing files.
fn check_materialx(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap();
    let doc = roxmltree::Document::parse(&text).unwrap();
    assert_eq!(doc.root_element().tag_name().name(), "materialx");
    assert_eq!(doc.root_element().attribute("version"), Some("1.38"));
    let files: Vec<&str> = doc
        .descendants()
        .filter(|n| n.has_tag_name("input") && n.attribute("type") == Some("filename"))
        .map(|n| n.attribute("value").unwrap())
        .collect();
    assert_eq!(files.len(), 4);
    for f in files {
        assert!(path.parent().unwrap().join(f).is_file(), "{f}");
    }
    assert!(doc.descendants().any(|n| n.has_tag_name("surfacematerial")));
}

#[test]
fn sample_is_deterministic_per_seed_and_writes_loadable_outputs() {
    let out = tempfile::tempdir().unwrap();
    let (a, b) = (out.path().join("a"), out.path().join("b"));
    let model_dir = tiny_model(false);
    let model = model_dir.path().to_str().unwrap();
    let text = sample(&[
        "--model",
        model,
        "--count",
        "2",
        "--seed",
        "7",
        "--out",
        a.to_str().unwrap(),
        "--hextile",
        "--gltf",
        "--mtlx",
    ])
    .unwrap();
    assert!(text.contains("summary.json"), "{text}");
    sample(&[
        "--model",
        model,
        "--count",
        "1",
        "--seed",
        "8",
        "--out",
        b.to_str().unwrap(),
    ])
    .unwrap();
    // Same seed, same bytes, whatever else the run did; another seed, another material.
    let a8 = exr_bytes(&a.join("seed-0008/material"));
    assert_eq!(a8, exr_bytes(&b.join("seed-0008/material")));
    assert_ne!(a8, exr_bytes(&a.join("seed-0007/material")));

    for seed in ["seed-0007", "seed-0008"] {
        let folder = a.join(seed);
        let material = load_maps(&folder.join("material"), None).unwrap();
        assert_eq!(material.brdf.name(), "height(ggx, scale=0.02)");
        assert_eq!(material.manifest.resolution, 32);
        // The 2×2 hex-tiling is a material of the innermost model, with the derived normal.
        let hex = load_maps(&folder.join("material_hextile_2x2"), None).unwrap();
        assert_eq!(hex.brdf.name(), "ggx");
        assert_eq!(hex.manifest.resolution, 64);
        // 5 lights side by side, 32 px each, 4 px gaps.
        for render in ["neural.png", "analytic.png"] {
            assert_eq!(
                png_header(&folder.join(render)).unwrap(),
                (3, 32, 5 * 32 + 4 * 4)
            );
        }
        assert_eq!(
            png_header(&folder.join("hextile_2x2.png")).unwrap(),
            (3, 64, 64)
        );
        assert!(!folder.join("tiled_2x2.png").exists());
        check_gltf(&folder.join("export/material.gltf"));
        check_materialx(&folder.join("export/material.mtlx"));
    }
    // One row per material: 5 previews (diffuse, specular, roughness, normal, height) and
    // 2 × 5 renders.
    let (_, h, w) = png_header(&a.join("contact_sheet.png")).unwrap();
    assert_eq!((h, w), (2 * 32 + 4, 15 * 32 + 14 * 4));
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["seeds"], serde_json::json!([7, 8]));
    assert_eq!(summary["lights"].as_array().unwrap().len(), 5);
    for m in summary["materials"].as_array().unwrap() {
        let l1 = m["l1_per_light"].as_array().unwrap();
        assert_eq!(l1.len(), 5);
        // A fixed-size model's unit-square material lies whole within a photo's reach of
        // each of the five flashes: both figures are over the same texels.
        // (Summed in another order: equal to f32 rounding.)
        let in_reach = m["l1_within_photo_reach_per_light"].as_array().unwrap();
        assert_eq!(in_reach.len(), l1.len());
        for (near, all) in in_reach.iter().zip(l1) {
            assert!((near.as_f64().unwrap() - all.as_f64().unwrap()).abs() < 1e-6);
        }
        assert!(
            l1.iter()
                .all(|v| (0.0..=1.0).contains(&v.as_f64().unwrap()))
        );
    }
    let timings: BTreeSet<&str> = summary["timings_s"]
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    assert!(timings.contains("generate") && timings.contains("total"));

    // A second run into the same folder would mix with the first: refused, unless
    // --overwrite, which replaces the result whole (only the new run's seed folders remain).
    // A file sample does not write makes the folder someone else's: refused even then.
    let again = ["--model", model, "--count", "1", "--seed", "9", "--out"];
    let err = sample(&[&again[..], &[a.to_str().unwrap()]].concat()).unwrap_err();
    let err = format!("{err:#}");
    assert!(
        err.contains(&a.display().to_string())
            && err.contains("seed-0007")
            && err.contains("--overwrite"),
        "{err}"
    );
    assert!(a.join("seed-0007").exists());
    std::fs::write(a.join("notes.txt"), b"mine").unwrap();
    let err = sample(&[&again[..], &[a.to_str().unwrap(), "--overwrite"]].concat()).unwrap_err();
    let err = format!("{err:#}");
    assert!(
        err.contains("notes.txt") && err.contains("does not write"),
        "{err}"
    );
    assert!(a.join("notes.txt").exists() && a.join("seed-0007").exists());
    std::fs::remove_file(a.join("notes.txt")).unwrap();
    sample(&[&again[..], &[a.to_str().unwrap(), "--overwrite"]].concat()).unwrap();
    let seeds: Vec<String> = std::fs::read_dir(&a)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("seed-"))
        .collect();
    assert_eq!(seeds, ["seed-0009"]);

    // While another process (here: a lock this test holds) writes the folder, sample fails
    // at once naming the holder.
    let _held = photomat_core::FolderLock::acquire(&b, "photomat sample").unwrap();
    let err = sample(&[&again[..], &[b.to_str().unwrap(), "--overwrite"]].concat()).unwrap_err();
    let err = format!("{err:#}");
    assert!(
        err.contains("is in use by process") && err.contains(&std::process::id().to_string()),
        "{err}"
    );
}

#[test]
fn sample_tileable_on_a_non_tileable_model_says_so() {
    let out = tempfile::tempdir().unwrap();
    let model = tiny_model(false);
    let err = sample(&[
        "--model",
        model.path().to_str().unwrap(),
        "--count",
        "1",
        "--out",
        out.path().to_str().unwrap(),
        "--tileable",
    ])
    .unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains("not tileable"), "{text}");
    assert!(text.contains("train-gan --tileable"), "{text}");
    assert!(!out.path().join("seed-0000").exists());
}

#[test]
fn sample_tileable_model_writes_the_tiled_render() {
    let model = tiny_model(true);
    let out = tempfile::tempdir().unwrap();
    sample(&[
        "--model",
        model.path().to_str().unwrap(),
        "--count",
        "1",
        "--seed",
        "3",
        "--out",
        out.path().to_str().unwrap(),
        "--tileable",
        "--size-render",
        "16",
    ])
    .unwrap();
    let folder = out.path().join("seed-0003");
    assert_eq!(
        png_header(&folder.join("tiled_2x2.png")).unwrap(),
        (3, 32, 32)
    );
    assert_eq!(
        png_header(&folder.join("analytic.png")).unwrap(),
        (3, 16, 5 * 16 + 4 * 4)
    );
}

#[test]
fn sample_without_a_model_names_the_path_and_how_to_train() {
    let out = tempfile::tempdir().unwrap();
    let missing = out.path().join("no-model");
    let err = sample(&[
        "--model",
        missing.to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
    ])
    .unwrap_err();
    let text = format!("{err:#}");
    assert!(text.contains(missing.to_str().unwrap()), "{text}");
    assert!(
        text.contains("train-gan") && text.contains("train-estimator"),
        "{text}"
    );
}

/// Every file under `dir` but `summary.json`, by relative path, with its bytes.
fn tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().unwrap() != "summary.json" {
                let rel = path
                    .strip_prefix(dir)
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                files.push((rel, std::fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

#[test]
fn sampler_library_writes_what_the_command_writes() {
    use photomat_estimator::sample::{SampleEvent, SampleOptions, Sampler};
    let model = tiny_model(true);
    let out = tempfile::tempdir().unwrap();
    let (by_cli, by_lib) = (out.path().join("cli"), out.path().join("lib"));
    let printed = sample(&[
        "--model",
        model.path().to_str().unwrap(),
        "--out",
        by_cli.to_str().unwrap(),
        "--count",
        "2",
        "--seed",
        "5",
        "--tileable",
        "--hextile",
        "--gltf",
        "--size-render",
        "16",
    ])
    .unwrap();

    let sampler = Sampler::open(model.path(), &Device::Cpu).unwrap();
    let options = SampleOptions {
        count: 2,
        seed: 5,
        tileable: true,
        hextile: true,
        gltf: true,
        render_size: Some(16),
        ..SampleOptions::default()
    };
    let mut events = Vec::new();
    let summary = sampler
        .run(&options, &by_lib, &mut |e| {
            events.push(e);
            Ok(())
        })
        .unwrap();

    let (a, b) = (tree(&by_cli), tree(&by_lib));
    assert!(a.len() > 20, "{} files", a.len());
    assert_eq!(
        a.iter().map(|(p, _)| p).collect::<Vec<_>>(),
        b.iter().map(|(p, _)| p).collect::<Vec<_>>()
    );
    for ((path, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{path} differs between the command and the library");
    }
    assert_eq!(summary.seeds, vec![5, 6]);
    let saved: Value =
        serde_json::from_str(&std::fs::read_to_string(by_cli.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(
        saved["l1_per_light"],
        serde_json::json!(summary.l1_per_light)
    );
    // The notes the command printed are the library's Note events, then one tick per material.
    let notes: Vec<&String> = events
        .iter()
        .filter_map(|e| match e {
            SampleEvent::Note(line) => Some(line),
            SampleEvent::Material { .. } => None,
        })
        .collect();
    assert!(
        !notes.is_empty(),
        "the glTF mapping of height(ggx) has notes"
    );
    for note in &notes {
        assert!(printed.contains(note.as_str()), "{note}");
    }
    let ticks: Vec<_> = events
        .iter()
        .filter(|e| matches!(e, SampleEvent::Material { .. }))
        .collect();
    assert_eq!(
        ticks,
        [
            &SampleEvent::Material { done: 1, total: 2 },
            &SampleEvent::Material { done: 2, total: 2 }
        ]
    );
}
