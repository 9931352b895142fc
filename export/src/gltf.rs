//! A glTF 2.0 asset (Khronos, "glTF 2.0 Specification", §3) for one material: a unit quad
//! with the material of a [`TextureSet`], loadable in Blender, three.js and the Khronos
//! sample viewer.
//!
//! [`write_gltf`] writes `<stem>.gltf` (JSON) and `<stem>.bin` (the quad's vertex data) next to
//! the texture set's PNGs. The document is built from serde structs, never pasted text:
//! - **mesh**: the unit square of `docs/conventions.md` ("The material plane") in the XY plane
//!   facing +Z (4 vertices: POSITION, NORMAL = +Z, TANGENT = (+X, w = 1; only with a normal
//!   texture), TEXCOORD_0 with (0, 0) at the top-left corner as glTF and our image rows agree; 2
//!   triangles, counter-clockwise seen from +Z). With bitangent = N × T · w = +Y, tangent space is
//!   the plane frame, so our normal maps (+y up) are glTF normal textures unchanged.
//! - **material**: `pbrMetallicRoughness` (base colour texture, metallic 0, roughness from G of
//!   the metallic-roughness texture), `normalTexture`, `KHR_materials_specular`
//!   (`specularColorTexture` = F0, `specularColorFactor` = 1/0.04) and, for two-lobe models,
//!   `KHR_materials_clearcoat`; every extension used is declared in `extensionsUsed`. What
//!   the mapping drops or approximates is recorded in the material's `extras` (see
//!   [`crate::textures`]).
//! - one sampler: linear filtering with mipmaps, REPEAT wrapping (the maps are tileable).

use std::collections::BTreeMap;
use std::path::Path;

use photomat_core::image_io::write_atomic;
use photomat_core::{Error, Result};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::textures::{DIELECTRIC_F0, Factors, TextureSet};

/// `KHR_materials_specular`: coloured F0 of the dielectric layer.
pub const KHR_MATERIALS_SPECULAR: &str = "KHR_materials_specular";
/// `KHR_materials_clearcoat`: a second, clear specular layer.
pub const KHR_MATERIALS_CLEARCOAT: &str = "KHR_materials_clearcoat";

/// WebGL enums used below (glTF 2.0 §5).
const FLOAT: u32 = 5126;
const UNSIGNED_SHORT: u32 = 5123;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const LINEAR: u32 = 9729;
const LINEAR_MIPMAP_LINEAR: u32 = 9987;
const REPEAT: u32 = 10497;
const TRIANGLES: u32 = 4;

/// The root glTF object (the subset this exporter writes).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Gltf {
    pub asset: Asset,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extensions_used: Vec<String>,
    pub scene: usize,
    pub scenes: Vec<Scene>,
    pub nodes: Vec<Node>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub textures: Vec<Texture>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub images: Vec<Image>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub samplers: Vec<Sampler>,
    pub accessors: Vec<Accessor>,
    pub buffer_views: Vec<BufferView>,
    pub buffers: Vec<Buffer>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Asset {
    pub version: String,
    pub generator: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Scene {
    pub nodes: Vec<usize>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Node {
    pub name: String,
    pub mesh: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Mesh {
    pub name: String,
    pub primitives: Vec<Primitive>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Primitive {
    pub attributes: BTreeMap<String, usize>,
    pub indices: usize,
    pub material: usize,
    pub mode: u32,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Material {
    pub name: String,
    pub pbr_metallic_roughness: PbrMetallicRoughness,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal_texture: Option<TextureInfo>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub extensions: BTreeMap<String, Value>,
    #[serde(default, skip_serializing_if = "Value::is_null")]
    pub extras: Value,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct PbrMetallicRoughness {
    pub base_color_factor: [f32; 4],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_color_texture: Option<TextureInfo>,
    pub metallic_factor: f32,
    pub roughness_factor: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metallic_roughness_texture: Option<TextureInfo>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct TextureInfo {
    pub index: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Texture {
    pub sampler: usize,
    pub source: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Image {
    pub uri: String,
    pub mime_type: String,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Sampler {
    pub mag_filter: u32,
    pub min_filter: u32,
    pub wrap_s: u32,
    pub wrap_t: u32,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Accessor {
    pub buffer_view: usize,
    pub byte_offset: usize,
    pub component_type: u32,
    pub count: usize,
    #[serde(rename = "type")]
    pub kind: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<Vec<f32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<Vec<f32>>,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct BufferView {
    pub buffer: usize,
    pub byte_offset: usize,
    pub byte_length: usize,
    pub target: u32,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
pub struct Buffer {
    pub uri: String,
    pub byte_length: usize,
}

/// Quad vertices: (position, uv); normal +Z and tangent +X for all.
const QUAD: [([f32; 3], [f32; 2]); 4] = [
    ([-0.5, 0.5, 0.0], [0.0, 0.0]),
    ([0.5, 0.5, 0.0], [1.0, 0.0]),
    ([0.5, -0.5, 0.0], [1.0, 1.0]),
    ([-0.5, -0.5, 0.0], [0.0, 1.0]),
];
/// Two counter-clockwise triangles seen from +Z.
const QUAD_INDICES: [u16; 6] = [0, 3, 2, 0, 2, 1];

/// The quad's binary buffer (POSITION, NORMAL, TEXCOORD_0, TANGENT when `tangents` (only a
/// normal texture uses them), then the u16 indices), one tightly packed buffer view per
/// accessor (glTF requires a `byteStride` when vertex accessors share a view), and the
/// accessors, in that order.
fn quad_buffer(tangents: bool) -> (Vec<u8>, Vec<Accessor>, Vec<BufferView>) {
    let mut bytes = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut attribute = |values: Vec<f32>, kind: &str, bounds: Option<(Vec<f32>, Vec<f32>)>| {
        let start = bytes.len();
        for v in &values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        views.push(BufferView {
            buffer: 0,
            byte_offset: start,
            byte_length: bytes.len() - start,
            target: ARRAY_BUFFER,
        });
        let (min, max) = bounds.unzip();
        accessors.push(Accessor {
            buffer_view: views.len() - 1,
            byte_offset: 0,
            component_type: FLOAT,
            count: QUAD.len(),
            kind: kind.to_string(),
            min,
            max,
        });
    };
    let bounds = (vec![-0.5, -0.5, 0.0], vec![0.5, 0.5, 0.0]);
    attribute(
        QUAD.iter().flat_map(|(p, _)| *p).collect(),
        "VEC3",
        Some(bounds),
    );
    attribute(
        QUAD.iter().flat_map(|_| [0.0, 0.0, 1.0]).collect(),
        "VEC3",
        None,
    );
    attribute(QUAD.iter().flat_map(|(_, t)| *t).collect(), "VEC2", None);
    if tangents {
        attribute(
            QUAD.iter().flat_map(|_| [1.0, 0.0, 0.0, 1.0]).collect(),
            "VEC4",
            None,
        );
    }
    let start = bytes.len();
    for i in QUAD_INDICES {
        bytes.extend_from_slice(&i.to_le_bytes());
    }
    views.push(BufferView {
        buffer: 0,
        byte_offset: start,
        byte_length: bytes.len() - start,
        target: ELEMENT_ARRAY_BUFFER,
    });
    accessors.push(Accessor {
        buffer_view: views.len() - 1,
        byte_offset: 0,
        component_type: UNSIGNED_SHORT,
        count: QUAD_INDICES.len(),
        kind: "SCALAR".to_string(),
        min: None,
        max: None,
    });
    (bytes, accessors, views)
}

/// The quad's mesh: positions, normals, uvs, and tangents where a normal texture needs them.
fn quad_mesh(name: &str, with_tangents: bool) -> Mesh {
    let mut attributes = BTreeMap::from([
        ("POSITION".to_string(), 0),
        ("NORMAL".to_string(), 1),
        ("TEXCOORD_0".to_string(), 2),
    ]);
    if with_tangents {
        attributes.insert("TANGENT".to_string(), 3);
    }
    // The index accessor follows the vertex attributes' accessors (`quad_buffer`).
    let indices = attributes.len();
    Mesh {
        name: name.to_string(),
        primitives: vec![Primitive {
            attributes,
            indices,
            material: 0,
            mode: TRIANGLES,
        }],
    }
}

/// The material's extensions: `KHR_materials_specular` always (weight 0 for a model without
/// a specular lobe), `KHR_materials_clearcoat` for a clear coat.
fn material_extensions(
    factors: &Factors,
    specular_texture: &Option<TextureInfo>,
    clearcoat_texture: &Option<TextureInfo>,
) -> BTreeMap<String, serde_json::Value> {
    let mut extensions = BTreeMap::new();
    // Without a specular map the model has no specular lobe (lambert): weight 0.
    let specular = match (specular_texture, factors.specular_color) {
        (Some(info), _) => json!({
            "specularFactor": 1.0,
            "specularColorFactor": [1.0 / DIELECTRIC_F0, 1.0 / DIELECTRIC_F0, 1.0 / DIELECTRIC_F0],
            "specularColorTexture": { "index": info.index },
        }),
        (None, Some(f0)) => json!({
            "specularFactor": 1.0,
            "specularColorFactor": f0.map(|v| v / DIELECTRIC_F0),
        }),
        (None, None) => json!({ "specularFactor": 0.0 }),
    };
    extensions.insert(KHR_MATERIALS_SPECULAR.to_string(), specular);
    if let Some([weight, roughness]) = factors.clearcoat {
        extensions.insert(
            KHR_MATERIALS_CLEARCOAT.to_string(),
            json!({ "clearcoatFactor": weight, "clearcoatRoughnessFactor": roughness }),
        );
    } else if let Some(info) = clearcoat_texture {
        extensions.insert(
            KHR_MATERIALS_CLEARCOAT.to_string(),
            json!({
                "clearcoatFactor": 1.0,
                "clearcoatTexture": { "index": info.index },
                "clearcoatRoughnessFactor": 1.0,
                "clearcoatRoughnessTexture": { "index": info.index },
            }),
        );
    }
    extensions
}

/// The glTF document for `textures` whose buffer is the file `bin_uri`; `name` names the
/// material, mesh and node.
pub fn gltf_document(textures: &TextureSet, name: &str, bin_uri: &str) -> Gltf {
    let (bytes, accessors, buffer_views) = quad_buffer(textures.normal.is_some());
    let mut images = Vec::new();
    let mut texture = |file: &Option<String>| {
        file.as_ref().map(|uri| {
            images.push(Image {
                uri: uri.clone(),
                mime_type: "image/png".to_string(),
            });
            TextureInfo {
                index: images.len() - 1,
            }
        })
    };
    let base_color_texture = texture(&textures.base_color);
    let metallic_roughness_texture = texture(&textures.metallic_roughness);
    let normal_texture = texture(&textures.normal);
    let specular_texture = texture(&textures.specular_color);
    let clearcoat_texture = texture(&textures.clearcoat);
    let gltf_textures = (0..images.len())
        .map(|source| Texture { sampler: 0, source })
        .collect::<Vec<_>>();

    let factors = &textures.factors;
    let extensions = material_extensions(factors, &specular_texture, &clearcoat_texture);
    let extensions_used = extensions.keys().cloned().collect();
    let material = Material {
        name: name.to_string(),
        pbr_metallic_roughness: PbrMetallicRoughness {
            // Without a diffuse map the base is black (no diffuse reflection).
            base_color_factor: match (&base_color_texture, factors.base_color) {
                (Some(_), _) => [1.0; 4],
                (None, Some([r, g, b])) => [r, g, b, 1.0],
                (None, None) => [0.0, 0.0, 0.0, 1.0],
            },
            base_color_texture,
            metallic_factor: 0.0,
            // A roughness texture is scaled by 1; a constant roughness is the factor itself;
            // without roughness the material is fully rough.
            roughness_factor: factors.roughness.unwrap_or(1.0),
            metallic_roughness_texture,
        },
        normal_texture,
        extensions,
        extras: json!({
            "photomat": {
                "brdf": textures.model,
                "dropped": textures.dropped,
                "approximations": textures.approximations,
            }
        }),
    };
    Gltf {
        asset: Asset {
            version: "2.0".to_string(),
            generator: format!("photomat-export {}", env!("CARGO_PKG_VERSION")),
        },
        extensions_used,
        scene: 0,
        scenes: vec![Scene { nodes: vec![0] }],
        nodes: vec![Node {
            name: name.to_string(),
            mesh: 0,
        }],
        meshes: vec![quad_mesh(name, textures.normal.is_some())],
        materials: vec![material],
        samplers: if gltf_textures.is_empty() {
            Vec::new()
        } else {
            vec![Sampler {
                mag_filter: LINEAR,
                min_filter: LINEAR_MIPMAP_LINEAR,
                wrap_s: REPEAT,
                wrap_t: REPEAT,
            }]
        },
        textures: gltf_textures,
        images,
        accessors,
        buffer_views,
        buffers: vec![Buffer {
            uri: bin_uri.to_string(),
            byte_length: bytes.len(),
        }],
    }
}

/// Write `dir/<stem>.gltf` and `dir/<stem>.bin` for `textures`, whose files lie in `dir`
/// (as [`crate::textures::write_textures`] wrote them). Returns the path of the `.gltf`.
pub fn write_gltf(dir: &Path, stem: &str, textures: &TextureSet) -> Result<std::path::PathBuf> {
    let bin_name = format!("{stem}.bin");
    let document = gltf_document(textures, stem, &bin_name);
    let (bytes, _, _) = quad_buffer(textures.normal.is_some());
    write_atomic(&dir.join(&bin_name), &bytes)?;
    let path = dir.join(format!("{stem}.gltf"));
    let mut text = serde_json::to_string_pretty(&document)
        .map_err(|e| Error::file(&path, format!("cannot serialise the glTF document: {e}")))?;
    text.push('\n');
    write_atomic(&path, text.as_bytes())?;
    Ok(path)
}
