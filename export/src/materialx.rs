//! A MaterialX 1.38 document (ASWF, "MaterialX Specification" v1.38, and its
//! "Physically Based Shading Nodes" / `UsdPreviewSurface` node definition) for one material.
//!
//! [`write_materialx`] writes `<stem>.mtlx` next to a [`TextureSet`]: a node graph of `image`
//! nodes reading its PNGs (colour textures in `srgb_texture`, data textures `raw`), an
//! `extract` of the roughness and clear-coat channels, a `normalmap` node (tangent space), a
//! `UsdPreviewSurface` shader in the specular workflow (`specularColor` = F0 directly,
//! `metallic` 0, `roughness` perceptual as ours) and a `surfacematerial`. UsdPreviewSurface is
//! chosen over `standard_surface` because its specular workflow takes our F0 unchanged;
//! MaterialX viewers (MaterialXView, usdview with MaterialX, Houdini) load it. The mapping
//! and what it drops are those of [`crate::textures`]; they are repeated in an XML comment.
//!
//! The XML is written by hand with every attribute value escaped ([`escape`]); the structure
//! is fixed, so no XML library is needed.

use std::path::{Path, PathBuf};

use photomat_core::image_io::write_atomic;
use photomat_core::{Error, Result};

use crate::textures::TextureSet;

/// XML attribute / text escaping: `& < > " '`.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

/// Text safe inside an XML comment (`--` is not allowed there).
fn comment_text(text: &str) -> String {
    escape(text).replace("--", "- -")
}

/// A MaterialX element name: letters, digits and `_` (other characters become `_`; a leading
/// digit gets a `M_` prefix), as the specification requires of names.
pub fn element_name(text: &str) -> String {
    let mut name: String = text
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if name.is_empty() || name.starts_with(|c: char| c.is_ascii_digit()) {
        name.insert_str(0, "M_");
    }
    name
}

/// The document text for `textures` (files relative to the document's folder); `name` names
/// the material.
pub fn materialx_document(textures: &TextureSet, name: &str) -> String {
    let name = element_name(name);
    let graph = format!("NG_{name}");
    let shader = format!("SR_{name}");
    let mut x = Xml::default();
    x.line(r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    x.line(r#"<materialx version="1.38">"#);
    x.line(&format!(
        "  <!-- photomat material, BRDF model {} -->",
        comment_text(&textures.model)
    ));
    for note in &textures.dropped {
        x.line(&format!("  <!-- dropped: {} -->", comment_text(note)));
    }
    for note in &textures.approximations {
        x.line(&format!("  <!-- approximation: {} -->", comment_text(note)));
    }
    let connected = node_graph(&mut x, textures, &graph);
    surface_shader(&mut x, textures, &shader, &graph, &connected);
    x.line(&format!(
        r#"  <surfacematerial name="{name}" type="material">"#
    ));
    x.line(&format!(
        r#"    <input name="surfaceshader" type="surfaceshader" nodename="{shader}" />"#
    ));
    x.line("  </surfacematerial>");
    x.line("</materialx>");
    x.text
}

/// A shader input wired to an output of the node graph: (input, type, graph output).
type Connection = (&'static str, &'static str, &'static str);

/// The document being written, line by line.
#[derive(Default)]
struct Xml {
    text: String,
}

impl Xml {
    fn line(&mut self, line: &str) {
        self.text.push_str(line);
        self.text.push('\n');
    }

    /// A periodic `image` node reading `file` in colour space `space`.
    fn image(&mut self, node: &str, kind: &str, file: &str, space: &str) {
        self.line(&format!(r#"    <image name="{node}" type="{kind}">"#));
        self.line(&format!(
            r#"      <input name="file" type="filename" value="{}" colorspace="{space}" />"#,
            escape(file)
        ));
        self.line(r#"      <input name="uaddressmode" type="string" value="periodic" />"#);
        self.line(r#"      <input name="vaddressmode" type="string" value="periodic" />"#);
        self.line("    </image>");
    }

    /// An `extract` node taking channel `index` of the vector3 node `from`.
    fn extract(&mut self, node: &str, from: &str, index: usize) {
        self.line(&format!(r#"    <extract name="{node}" type="float">"#));
        self.line(&format!(
            r#"      <input name="in" type="vector3" nodename="{from}" />"#
        ));
        self.line(&format!(
            r#"      <input name="index" type="integer" value="{index}" />"#
        ));
        self.line("    </extract>");
    }

    /// A node graph output named `out` of node `node`.
    fn output(&mut self, out: &str, kind: &str, node: &str) {
        self.line(&format!(
            r#"    <output name="{out}" type="{kind}" nodename="{node}" />"#
        ));
    }
}

/// The node graph `graph` reading the set's textures; returns the shader inputs it feeds.
fn node_graph(x: &mut Xml, textures: &TextureSet, graph: &str) -> Vec<Connection> {
    let mut connected = Vec::new();
    x.line(&format!(r#"  <nodegraph name="{graph}">"#));
    if let Some(file) = &textures.base_color {
        x.image("base_color_image", "color3", file, "srgb_texture");
        x.output("out_diffuse", "color3", "base_color_image");
        connected.push(("diffuseColor", "color3", "out_diffuse"));
    }
    if let Some(file) = &textures.specular_color {
        x.image("specular_image", "color3", file, "srgb_texture");
        x.output("out_specular", "color3", "specular_image");
        connected.push(("specularColor", "color3", "out_specular"));
    }
    if let Some(file) = &textures.metallic_roughness {
        x.image("metallic_roughness_image", "vector3", file, "raw");
        x.extract("roughness", "metallic_roughness_image", 1);
        x.output("out_roughness", "float", "roughness");
        connected.push(("roughness", "float", "out_roughness"));
    }
    if let Some(file) = &textures.normal {
        x.image("normal_image", "vector3", file, "raw");
        x.line(r#"    <normalmap name="normal_map" type="vector3">"#);
        x.line(r#"      <input name="in" type="vector3" nodename="normal_image" />"#);
        x.line(r#"      <input name="space" type="string" value="tangent" />"#);
        x.line("    </normalmap>");
        x.output("out_normal", "vector3", "normal_map");
        connected.push(("normal", "vector3", "out_normal"));
    }
    if let Some(file) = &textures.clearcoat {
        x.image("clearcoat_image", "vector3", file, "raw");
        x.extract("clearcoat", "clearcoat_image", 0);
        x.extract("clearcoat_roughness", "clearcoat_image", 1);
        x.output("out_clearcoat", "float", "clearcoat");
        x.output("out_clearcoat_roughness", "float", "clearcoat_roughness");
        connected.push(("clearcoat", "float", "out_clearcoat"));
        connected.push(("clearcoatRoughness", "float", "out_clearcoat_roughness"));
    }
    x.line("  </nodegraph>");
    connected
}

/// The `UsdPreviewSurface` shader `shader` in the specular workflow: the graph's outputs
/// `connected`, the set's constant maps as values, and defaults for maps the model lacks.
fn surface_shader(
    x: &mut Xml,
    textures: &TextureSet,
    shader: &str,
    graph: &str,
    connected: &[Connection],
) {
    x.line(&format!(
        r#"  <UsdPreviewSurface name="{shader}" type="surfaceshader">"#
    ));
    x.line(r#"    <input name="useSpecularWorkflow" type="integer" value="1" />"#);
    x.line(r#"    <input name="metallic" type="float" value="0" />"#);
    for (input, kind, out) in connected {
        x.line(&format!(
            r#"    <input name="{input}" type="{kind}" nodegraph="{graph}" output="{out}" />"#
        ));
    }
    let factors = &textures.factors;
    let color = |c: [f32; 3]| format!("{}, {}, {}", c[0], c[1], c[2]);
    // Constant maps are input values (linear, as UsdPreviewSurface reads unconnected inputs).
    let mut constants: Vec<(&str, &str, String)> = Vec::new();
    if let Some(c) = factors.base_color {
        constants.push(("diffuseColor", "color3", color(c)));
    }
    if let Some(c) = factors.specular_color {
        constants.push(("specularColor", "color3", color(c)));
    }
    if let Some(r) = factors.roughness {
        constants.push(("roughness", "float", r.to_string()));
    }
    if let Some([weight, roughness]) = factors.clearcoat {
        constants.push(("clearcoat", "float", weight.to_string()));
        constants.push(("clearcoatRoughness", "float", roughness.to_string()));
    }
    for (input, kind, value) in &constants {
        x.line(&format!(
            r#"    <input name="{input}" type="{kind}" value="{value}" />"#
        ));
    }
    let has = |input: &str| {
        connected.iter().any(|(i, _, _)| *i == input)
            || constants.iter().any(|(i, _, _)| *i == input)
    };
    // Defaults for maps the model lacks: no diffuse → black base; no specular → no lobe; no
    // roughness → fully rough.
    for (input, kind, value) in [
        ("diffuseColor", "color3", "0, 0, 0"),
        ("specularColor", "color3", "0, 0, 0"),
        ("roughness", "float", "1"),
    ] {
        if !has(input) {
            x.line(&format!(
                r#"    <input name="{input}" type="{kind}" value="{value}" />"#
            ));
        }
    }
    x.line("  </UsdPreviewSurface>");
}

/// Write `dir/<stem>.mtlx` for `textures`, whose files lie in `dir`. Returns its path.
pub fn write_materialx(dir: &Path, stem: &str, textures: &TextureSet) -> Result<PathBuf> {
    let path = dir.join(format!("{stem}.mtlx"));
    if !dir.is_dir() {
        return Err(Error::file(dir, "the MaterialX folder does not exist"));
    }
    write_atomic(&path, materialx_document(textures, stem).as_bytes())?;
    Ok(path)
}
