//! Renderer exports of every built-in model: the texture set holds the maps in the renderers'
//! conventions, the glTF document is structurally valid (every index it uses exists, every URI
//! names a file, the buffer holds the quad), the MaterialX document parses and references
//! existing files and nodes.

use std::collections::BTreeSet;
use std::path::Path;

use candle_core::{Device, Tensor};
use photomat_brdfs as _;
use photomat_core::image_io::read_png;
use photomat_core::{Brdf, MaterialMaps, lookup};
use photomat_export::textures::{DIELECTRIC_F0, files, srgb_encode};
use photomat_export::{write_gltf, write_materialx, write_textures};
use serde_json::Value;

const SIZE: usize = 16;

/// A random valid material of `spec`: decoded raw normals from a seeded stream.
fn material(spec: &str, seed: u64) -> (Brdf, MaterialMaps) {
    let brdf = lookup(spec).unwrap();
    let n = brdf.channels();
    let raw: Vec<f32> = photomat_core::rng::SplitMix64(seed)
        .normals(n * SIZE * SIZE)
        .into_iter()
        .map(|v| v as f32)
        .collect();
    let raw = Tensor::from_vec(raw, (1, n, SIZE, SIZE), &Device::Cpu).unwrap();
    let maps = brdf.decode(&raw).unwrap();
    (brdf, maps)
}

fn channel(maps: &MaterialMaps, name: &str, c: usize) -> Vec<f32> {
    maps.get(name)
        .unwrap()
        .narrow(1, c, 1)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap()
}

/// Every `"…Texture": {"index": i}` below `value` has i < `textures`.
fn texture_refs(value: &Value, out: &mut Vec<usize>) {
    match value {
        Value::Object(map) => {
            for (key, v) in map {
                if key.ends_with("Texture") {
                    out.push(v["index"].as_u64().expect("texture index") as usize);
                }
                texture_refs(v, out);
            }
        }
        Value::Array(items) => items.iter().for_each(|v| texture_refs(v, out)),
        _ => {}
    }
}

/// Checks the glTF document's references and data; returns it.
fn check_gltf(path: &Path) -> Value {
    let dir = path.parent().unwrap();
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_eq!(doc["asset"]["version"], "2.0");
    let len = |key: &str| doc[key].as_array().map_or(0, Vec::len);
    let idx = |v: &Value| v.as_u64().expect("an index") as usize;
    assert!(idx(&doc["scene"]) < len("scenes"));
    for scene in doc["scenes"].as_array().unwrap() {
        for n in scene["nodes"].as_array().unwrap() {
            assert!(idx(n) < len("nodes"));
        }
    }
    for node in doc["nodes"].as_array().unwrap() {
        assert!(idx(&node["mesh"]) < len("meshes"));
    }
    for mesh in doc["meshes"].as_array().unwrap() {
        for p in mesh["primitives"].as_array().unwrap() {
            for key in ["POSITION", "NORMAL", "TEXCOORD_0"] {
                assert!(idx(&p["attributes"][key]) < len("accessors"), "{key}");
            }
            // Tangents exactly when a normal texture needs them.
            let material = &doc["materials"][idx(&p["material"])];
            assert_eq!(
                p["attributes"].get("TANGENT").is_some(),
                material.get("normalTexture").is_some()
            );
            assert!(idx(&p["indices"]) < len("accessors"));
            assert!(idx(&p["material"]) < len("materials"));
        }
    }
    let mut refs = Vec::new();
    texture_refs(&doc["materials"], &mut refs);
    assert!(!refs.is_empty());
    assert!(refs.iter().all(|&i| i < len("textures")), "{refs:?}");
    for t in doc["textures"].as_array().unwrap() {
        assert!(idx(&t["sampler"]) < len("samplers"));
        assert!(idx(&t["source"]) < len("images"));
    }
    for image in doc["images"].as_array().unwrap() {
        let uri = image["uri"].as_str().unwrap();
        assert!(dir.join(uri).is_file(), "image {uri} missing");
    }
    // Extensions used by materials are declared.
    let declared: BTreeSet<&str> = doc["extensionsUsed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    for m in doc["materials"].as_array().unwrap() {
        if let Some(ext) = m["extensions"].as_object() {
            for key in ext.keys() {
                assert!(
                    declared.contains(key.as_str()),
                    "{key} not in extensionsUsed"
                );
            }
        }
    }
    // Buffers exist with their length; views inside buffers; accessors inside views.
    let buffers: Vec<Vec<u8>> = doc["buffers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| {
            let bytes = std::fs::read(dir.join(b["uri"].as_str().unwrap())).unwrap();
            assert_eq!(bytes.len(), idx(&b["byteLength"]));
            bytes
        })
        .collect();
    for v in doc["bufferViews"].as_array().unwrap() {
        let b = idx(&v["buffer"]);
        assert!(b < buffers.len());
        assert!(idx(&v["byteOffset"]) + idx(&v["byteLength"]) <= buffers[b].len());
    }
    // Vertex accessors sharing a view need the view's byteStride (glTF 2.0 §3.6.2.4).
    let mut users = vec![0; len("bufferViews")];
    for a in doc["accessors"].as_array().unwrap() {
        users[idx(&a["bufferView"])] += 1;
    }
    for (v, n) in doc["bufferViews"].as_array().unwrap().iter().zip(users) {
        assert!(
            n <= 1 || v.get("byteStride").is_some(),
            "shared view without byteStride"
        );
    }
    for a in doc["accessors"].as_array().unwrap() {
        let view = &doc["bufferViews"][idx(&a["bufferView"])];
        let components = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            other => panic!("accessor type {other}"),
        };
        let size = match idx(&a["componentType"]) {
            5126 => 4,
            5123 => 2,
            other => panic!("component type {other}"),
        };
        assert_eq!(idx(&a["byteOffset"]) % size, 0, "misaligned accessor");
        assert!(
            idx(&a["byteOffset"]) + idx(&a["count"]) * components * size
                <= idx(&view["byteLength"])
        );
    }
    doc
}

/// Floats of accessor `i` (FLOAT accessors of buffer 0).
fn floats(doc: &Value, dir: &Path, i: usize) -> Vec<f32> {
    let a = &doc["accessors"][i];
    let view = &doc["bufferViews"][a["bufferView"].as_u64().unwrap() as usize];
    let bytes = std::fs::read(dir.join(doc["buffers"][0]["uri"].as_str().unwrap())).unwrap();
    let start = (view["byteOffset"].as_u64().unwrap() + a["byteOffset"].as_u64().unwrap()) as usize;
    let n = a["count"].as_u64().unwrap() as usize
        * match a["type"].as_str().unwrap() {
            "VEC2" => 2,
            "VEC3" => 3,
            _ => 4,
        };
    (0..n)
        .map(|k| f32::from_le_bytes(bytes[start + 4 * k..start + 4 * k + 4].try_into().unwrap()))
        .collect()
}

#[test]
fn gltf_references_exist_for_every_builtin_model() {
    for spec in ["height(ggx)", "ggx", "lambert", "coated"] {
        let (brdf, maps) = material(spec, 3);
        let dir = tempfile::tempdir().unwrap();
        let set = write_textures(dir.path(), brdf.as_ref(), &maps).unwrap();
        let path = write_gltf(dir.path(), "material", &set).unwrap();
        let doc = check_gltf(&path);
        let m = &doc["materials"][0];
        assert_eq!(m["pbrMetallicRoughness"]["metallicFactor"], 0.0);
        assert!(
            m["extensions"]["KHR_materials_specular"].is_object(),
            "{spec}"
        );
        assert_eq!(m["extras"]["photomat"]["brdf"], brdf.name());
        match spec {
            "coated" => {
                assert!(m["extensions"]["KHR_materials_clearcoat"].is_object());
                let approx = m["extras"]["photomat"]["approximations"].to_string();
                assert!(approx.contains("specular2"), "{approx}");
                assert!(m.get("normalTexture").is_none());
            }
            "lambert" => {
                assert_eq!(
                    m["extensions"]["KHR_materials_specular"]["specularFactor"],
                    0.0
                );
                assert!(m["normalTexture"].is_object());
            }
            _ => assert!(m["normalTexture"].is_object(), "{spec}"),
        }
        assert!(
            m["extras"]["photomat"]["dropped"]
                .as_array()
                .unwrap()
                .is_empty(),
            "{spec}: built-in maps all map"
        );
    }
}

#[test]
fn gltf_quad_faces_its_normal_with_tangent_along_u() {
    let (brdf, maps) = material("ggx", 1);
    let dir = tempfile::tempdir().unwrap();
    let set = write_textures(dir.path(), brdf.as_ref(), &maps).unwrap();
    let doc = check_gltf(&write_gltf(dir.path(), "q", &set).unwrap());
    let attribute = |name: &str| {
        let i = doc["meshes"][0]["primitives"][0]["attributes"][name]
            .as_u64()
            .unwrap();
        floats(&doc, dir.path(), i as usize)
    };
    let pos = attribute("POSITION");
    let uv = attribute("TEXCOORD_0");
    // u grows with x, v grows with −y (image rows go down, +y is up): tangent +x, bitangent +y.
    for k in 0..4 {
        assert_eq!(uv[2 * k], pos[3 * k] + 0.5);
        assert_eq!(uv[2 * k + 1], 0.5 - pos[3 * k + 1]);
    }
    let tangent = attribute("TANGENT");
    assert_eq!(&tangent[..4], &[1.0, 0.0, 0.0, 1.0]);
}

#[test]
fn textures_hold_the_maps_in_renderer_conventions() {
    let (brdf, maps) = material("ggx", 7);
    let dir = tempfile::tempdir().unwrap();
    let set = write_textures(dir.path(), brdf.as_ref(), &maps).unwrap();
    // Half an 8-bit step, plus the sRGB curve's steepest slope (12.92) near black.
    let q = 0.5 / 255.0 + 1e-6;
    let (base, _) = read_png(&dir.path().join(files::BASE_COLOR)).unwrap();
    let (spec, _) = read_png(&dir.path().join(files::SPECULAR_COLOR)).unwrap();
    let (mr, _) = read_png(&dir.path().join(files::METALLIC_ROUGHNESS)).unwrap();
    let (normal, _) = read_png(&dir.path().join(files::NORMAL)).unwrap();
    let plane = SIZE * SIZE;
    for c in 0..3 {
        let d = channel(&maps, "diffuse", c);
        let f0 = channel(&maps, "specular", c);
        let n = channel(&maps, "normal", c);
        for t in 0..plane {
            assert!((base.data[c * plane + t] - srgb_encode(d[t])).abs() <= q);
            assert!((spec.data[c * plane + t] - srgb_encode(f0[t])).abs() <= q);
            assert!((normal.data[c * plane + t] - (0.5 * n[t] + 0.5)).abs() <= 2.0 * q);
        }
    }
    let r = channel(&maps, "roughness", 0);
    for (t, r) in r.iter().enumerate() {
        // glTF's roughness is perceptual with α = r², like ours: copied unchanged.
        assert!((mr.data[plane + t] - r).abs() <= q);
        assert_eq!(mr.data[2 * plane + t], 0.0, "metallic");
    }
    assert_eq!(set.files().len(), 4);
    assert!((srgb_encode(0.0031308) - 0.04045).abs() < 1e-4);
    assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
    // F0 = 0.04 · factor · texture: the factor makes every F0 in [0, 1] exact.
    assert!((DIELECTRIC_F0 * (1.0 / DIELECTRIC_F0) - 1.0).abs() < 1e-6);
}

#[test]
fn height_models_export_the_derived_normal() {
    let (brdf, maps) = material("height(ggx, scale=0.5)", 5);
    let dir = tempfile::tempdir().unwrap();
    let set = write_textures(dir.path(), brdf.as_ref(), &maps).unwrap();
    assert_eq!(set.normal.as_deref(), Some(files::NORMAL));
    let (normal, _) = read_png(&dir.path().join(files::NORMAL)).unwrap();
    let derived = brdf.shading_maps(&maps).unwrap();
    let z = channel(&derived, "normal", 2);
    let plane_len = SIZE * SIZE;
    // A bumpy height gives tilted normals, not a flat +z texture.
    assert!(z.iter().any(|&v| v < 0.99));
    for (t, z) in z.iter().enumerate() {
        assert!((normal.data[2 * plane_len + t] - (0.5 * z + 0.5)).abs() < 2.0 / 255.0);
    }
}

#[test]
fn materialx_parses_and_references_existing_files_and_nodes() {
    for spec in ["height(ggx)", "lambert", "coated"] {
        let (brdf, maps) = material(spec, 11);
        let dir = tempfile::tempdir().unwrap();
        let set = write_textures(dir.path(), brdf.as_ref(), &maps).unwrap();
        let path = write_materialx(dir.path(), "seed-0011 <&>", &set).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let doc = roxmltree::Document::parse(&text).unwrap_or_else(|e| panic!("{spec}: {e}"));
        let root = doc.root_element();
        assert_eq!(root.tag_name().name(), "materialx");
        assert_eq!(root.attribute("version"), Some("1.38"));
        let top: BTreeSet<&str> = root
            .children()
            .filter(|n| n.is_element())
            .filter_map(|n| n.attribute("name"))
            .collect();
        let mut files = 0;
        for node in doc.descendants().filter(|n| n.has_tag_name("input")) {
            if node.attribute("type") == Some("filename") {
                let file = node.attribute("value").unwrap();
                assert!(dir.path().join(file).is_file(), "{spec}: {file} missing");
                files += 1;
            }
            if let Some(target) = node.attribute("nodename") {
                // A node of the same graph (sibling of the input's node) or a top-level node.
                let scope = node.parent().unwrap().parent().unwrap();
                let in_scope = scope
                    .children()
                    .any(|n| n.attribute("name") == Some(target));
                assert!(in_scope || top.contains(target), "{spec}: node {target}");
            }
            if let Some(graph) = node.attribute("nodegraph") {
                let g = root
                    .children()
                    .find(|n| n.has_tag_name("nodegraph") && n.attribute("name") == Some(graph))
                    .unwrap_or_else(|| panic!("{spec}: nodegraph {graph}"));
                let output = node.attribute("output").unwrap();
                assert!(
                    g.children()
                        .any(|n| n.has_tag_name("output") && n.attribute("name") == Some(output)),
                    "{spec}: output {output}"
                );
            }
        }
        assert_eq!(
            files,
            set.files().len(),
            "{spec}: one image node per texture"
        );
        let material = root
            .children()
            .find(|n| n.has_tag_name("surfacematerial"))
            .unwrap();
        assert!(
            material
                .attribute("name")
                .unwrap()
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
        );
        let shader = root
            .children()
            .find(|n| n.has_tag_name("UsdPreviewSurface"))
            .unwrap();
        let input = |name: &str| {
            shader
                .children()
                .find(|n| n.attribute("name") == Some(name))
                .unwrap_or_else(|| panic!("{spec}: no {name}"))
        };
        assert_eq!(input("useSpecularWorkflow").attribute("value"), Some("1"));
        input("diffuseColor");
        input("roughness");
        if spec == "coated" {
            input("clearcoat");
            assert!(text.contains("dropped") || text.contains("approximation"));
        }
    }
}

/// A map whose texels are all equal (what `sample --simplify` makes) is a factor, not a
/// texture, in the texture set, the glTF document and the MaterialX document.
#[test]
fn exports_write_constant_maps_as_factors() {
    let (brdf, mut maps) = material("ggx", 11);
    let constant = |values: &[f32]| {
        let data = values
            .iter()
            .flat_map(|&v| std::iter::repeat_n(v, SIZE * SIZE))
            .collect();
        Tensor::from_vec(data, (1, values.len(), SIZE, SIZE), &Device::Cpu).unwrap()
    };
    maps.insert("roughness", constant(&[0.375]));
    maps.insert("normal", constant(&[0.0, 0.0, 1.0]));
    maps.insert("specular", constant(&[0.04, 0.05, 0.06]));
    let temp = tempfile::tempdir().unwrap();
    let set = write_textures(temp.path(), brdf.as_ref(), &maps).unwrap();
    assert!(set.base_color.is_some());
    assert_eq!(set.metallic_roughness, None);
    assert_eq!(set.normal, None);
    assert_eq!(set.specular_color, None);
    assert_eq!(set.factors.roughness, Some(0.375));
    assert_eq!(set.factors.specular_color, Some([0.04, 0.05, 0.06]));
    assert_eq!(set.files(), vec!["base_color.png"]);
    let gltf = write_gltf(temp.path(), "m", &set).unwrap();
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(gltf).unwrap()).unwrap();
    let material = &doc["materials"][0];
    assert_eq!(material["pbrMetallicRoughness"]["roughnessFactor"], 0.375);
    assert!(
        material["pbrMetallicRoughness"]
            .get("metallicRoughnessTexture")
            .is_none()
    );
    assert!(material.get("normalTexture").is_none());
    let specular = &material["extensions"]["KHR_materials_specular"];
    let factor: Vec<f64> = specular["specularColorFactor"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for (f, f0) in factor.iter().zip([0.04, 0.05, 0.06]) {
        assert!((f * 0.04 - f0).abs() < 1e-6, "{factor:?}");
    }
    assert!(specular.get("specularColorTexture").is_none());
    let mtlx = photomat_export::materialx::materialx_document(&set, "m");
    assert!(
        mtlx.contains(r#"<input name="roughness" type="float" value="0.375" />"#),
        "{mtlx}"
    );
    assert!(
        mtlx.contains(r#"name="specularColor" type="color3" value="0.04, 0.05, 0.06""#),
        "{mtlx}"
    );
    assert_eq!(mtlx.matches(r#"name="roughness""#).count(), 1, "{mtlx}");
}
