//! The renderer texture set: one material's maps re-encoded as the 8-bit textures that
//! real-time and offline renderers read (glTF 2.0's metallic-roughness model with
//! `KHR_materials_specular` / `KHR_materials_clearcoat`, MaterialX `UsdPreviewSurface`).
//!
//! [`write_textures`] maps the model's **shading maps** (`DifferentiableBrdf::shading_maps`: an
//! adapter such as `height(…)` contributes the normal it derives) by their shared names
//! (docs/conventions.md, "Parameter maps"):
//!
//! | photomat map | texture (file)                                  | encoding                      |
//! |--------------|-------------------------------------------------|-------------------------------|
//! | `diffuse`    | base colour (`base_color.png`)                  | sRGB OETF, 8-bit RGB          |
//! | `roughness`  | G of `metallic_roughness.png` (B = metallic = 0) | linear; glTF's r is ours      |
//! | `specular`   | specular colour (`specular_color.png`)          | sRGB, F0 / 0.04 via a factor  |
//! | `normal`     | tangent-space normal (`normal.png`)             | `0.5·n + 0.5`, +y up (OpenGL) |
//! | `specular2`  | R of `clearcoat.png`: clear-coat weight         | `min(lum(F0₂)/0.04, 1)`       |
//! | `roughness2` | G of `clearcoat.png`: clear-coat roughness      | linear                        |
//!
//! Roughness: our `roughness` is perceptual r with GGX α = r² (`ROUGHNESS` in the built-in
//! plugins), exactly glTF's and UsdPreviewSurface's convention, so it is copied unchanged.
//!
//! Specular: glTF's dielectric F0 is `0.04 · specularColorFactor · specularColorTexture`
//! (ior 1.5, `KHR_materials_specular`), so the texture holds our F0 and the factor is
//! 1/0.04 = 25: every F0 in [0, 1] is represented exactly. UsdPreviewSurface takes F0 directly
//! (`useSpecularWorkflow = 1`).
//!
//! A map whose texels are all exactly equal (`photomat sample --simplify` makes them,
//! `photomat_core::simplify`) is written as a constant of the material ([`Factors`]: glTF's
//! `baseColorFactor`, `roughnessFactor`, `specularColorFactor`, `clearcoatFactor`; MaterialX
//! input values) instead of a texture, and a normal map of +z everywhere as no normal map.
//!
//! What renderers cannot take is never dropped silently: [`TextureSet::dropped`] lists every
//! shading map without an equivalent and [`TextureSet::approximations`] every lossy mapping,
//! per built-in plugin:
//! - `ggx`, `height(ggx)`: exact up to the layering below.
//! - `lambert`: base colour and normal; specular weight 0 (no lobe), roughness 1.
//! - `coated`: lobe 1 = the base specular layer (exact); lobe 2 → clear coat, whose F0 is fixed
//!   at 0.04 and achromatic in glTF and UsdPreviewSurface: the weight is the luminance of
//!   `specular2` over 0.04, clamped to 1 (colour and any F0 above 0.04 are lost); normal flat.
//! - any other map name (user plugins): listed in `dropped`.
//!
//! Layering: both targets put the specular layer *over* the diffuse base and darken the base by
//! the layer's Fresnel reflectance; our models add the lobes (docs/conventions.md). For the
//! typical dielectric F0 ≈ 0.04 the difference is a few percent of the diffuse term.
//!
//! # Shapes
//! Maps (1, C, R, R) (one material, as `map_files::save_maps` takes); textures R×R.

use std::path::Path;

use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::simplify::{LUMINANCE, constant_value};
use photomat_core::{DifferentiableBrdf, Error, MaterialMaps, Result};

/// F0 of a dielectric of ior 1.5, `((ior − 1)/(ior + 1))²`: glTF's and UsdPreviewSurface's
/// clear coat and glTF's default specular layer.
pub const DIELECTRIC_F0: f32 = 0.04;

/// File names of the texture set inside its folder.
pub mod files {
    /// sRGB base colour (diffuse albedo).
    pub const BASE_COLOR: &str = "base_color.png";
    /// Linear; G = roughness, B = metallic (0), R = 1 (unused: ambient occlusion slot).
    pub const METALLIC_ROUGHNESS: &str = "metallic_roughness.png";
    /// sRGB specular colour (F0).
    pub const SPECULAR_COLOR: &str = "specular_color.png";
    /// Tangent-space normal, `0.5·n + 0.5`.
    pub const NORMAL: &str = "normal.png";
    /// Linear; R = clear-coat weight, G = clear-coat roughness.
    pub const CLEARCOAT: &str = "clearcoat.png";
}

/// Constant values that replace textures: a shading map whose texels are exactly equal
/// (`photomat_core::simplify::constant_value`, what `sample --simplify` makes) is written as a
/// factor of the material, not as an image.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Factors {
    /// Linear base colour (diffuse albedo).
    pub base_color: Option<[f32; 3]>,
    /// Roughness (glTF's and UsdPreviewSurface's convention, as the maps').
    pub roughness: Option<f32>,
    /// Linear specular colour F0.
    pub specular_color: Option<[f32; 3]>,
    /// Clear-coat weight and roughness.
    pub clearcoat: Option<[f32; 2]>,
}

/// What [`write_textures`] wrote and how renderers should use it. File names are relative to
/// the folder it wrote into; a map that is a constant has a factor in [`Self::factors`] and no
/// file.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureSet {
    /// Canonical model specification of the material (`DifferentiableBrdf::name`).
    pub model: String,
    /// Side of every texture, in texels.
    pub resolution: usize,
    /// sRGB base colour texture (absent: the model has no `diffuse`, base colour black).
    pub base_color: Option<String>,
    /// G = roughness (absent: the model has no `roughness`, renderers use roughness 1).
    pub metallic_roughness: Option<String>,
    /// sRGB F0 texture; absent: the model has no specular lobe (specular weight 0).
    pub specular_color: Option<String>,
    /// Tangent-space normal texture (absent: flat).
    pub normal: Option<String>,
    /// R = clear-coat weight, G = clear-coat roughness (present for `specular2`+`roughness2`).
    pub clearcoat: Option<String>,
    /// Constant maps, written as values instead of files.
    pub factors: Factors,
    /// Shading maps with no renderer equivalent, each with the reason.
    pub dropped: Vec<String>,
    /// Lossy mappings, one sentence each.
    pub approximations: Vec<String>,
}

impl TextureSet {
    /// Every texture file of the set.
    pub fn files(&self) -> Vec<&str> {
        [
            &self.base_color,
            &self.metallic_roughness,
            &self.specular_color,
            &self.normal,
            &self.clearcoat,
        ]
        .into_iter()
        .flatten()
        .map(String::as_str)
        .collect()
    }
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1): linear [0, 1] → encoded.
pub fn srgb_encode(linear: f32) -> f32 {
    let x = linear.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Map names [`write_textures`] consumes.
const MAPPED: [&str; 6] = [
    "diffuse",
    "roughness",
    "specular",
    "normal",
    "specular2",
    "roughness2",
];

/// Write the texture set of one material into `dir` (created if missing), 8-bit PNGs written
/// atomically; see the module docs for the mapping.
pub fn write_textures(
    dir: &Path,
    brdf: &dyn DifferentiableBrdf,
    maps: &MaterialMaps,
) -> Result<TextureSet> {
    let model = brdf.name();
    maps.validate(&model, brdf.params())?;
    let (batch, height, width) = maps.batch_and_size()?;
    if batch != 1 || height != width {
        return Err(Error::Invalid(format!(
            "renderer textures are written for one square material, got a batch of {batch} of \
             {height}×{width} maps"
        )));
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::file(dir, format!("cannot create the texture folder: {e}")))?;
    let shading = Shading {
        maps: brdf.shading_maps(maps)?,
        dir,
    };
    let mut set = TextureSet {
        model,
        resolution: height,
        base_color: None,
        metallic_roughness: None,
        specular_color: None,
        normal: None,
        clearcoat: None,
        factors: Factors::default(),
        dropped: Vec::new(),
        approximations: Vec::new(),
    };
    base_layer(&shading, &mut set)?;
    clear_coat(&shading, &mut set)?;
    if set.specular_color.is_some()
        || set.clearcoat.is_some()
        || set.factors.specular_color.is_some()
        || set.factors.clearcoat.is_some()
    {
        set.approximations.push(
            "renderers layer the specular over the diffuse base and darken the base by the \
             layer's Fresnel reflectance; photomat adds the lobes"
                .to_string(),
        );
    }
    for (name, _) in shading.maps.iter() {
        if !MAPPED.contains(&name) {
            set.dropped
                .push(format!("{name}: no glTF / UsdPreviewSurface equivalent"));
        }
    }
    Ok(set)
}

/// A material's shading maps and the folder their textures go to.
struct Shading<'a> {
    maps: MaterialMaps,
    dir: &'a Path,
}

impl Shading<'_> {
    /// Map `name` as an image, if the model has it.
    fn image(&self, name: &str) -> Result<Option<PlanarImage>> {
        match self.maps.contains(name) {
            true => Ok(Some(PlanarImage::from_tensor(self.maps.get(name)?)?)),
            false => Ok(None),
        }
    }

    /// Map `name`'s value if the model has it and every texel is exactly that value.
    fn constant(&self, name: &str) -> Result<Option<Vec<f32>>> {
        match self.maps.contains(name) {
            true => constant_value(self.maps.get(name)?),
            false => Ok(None),
        }
    }

    /// Writes `image` as the 8-bit PNG `file`; returns the file name.
    fn write(&self, file: &str, image: &PlanarImage) -> Result<String> {
        write_png(&self.dir.join(file), image, PngBits::Eight)?;
        Ok(file.to_string())
    }
}

/// Base colour, roughness, specular colour and normal: a texture each, or a factor for a
/// constant map (no texture for a flat normal).
fn base_layer(shading: &Shading, set: &mut TextureSet) -> Result<()> {
    let rgb = |v: Vec<f32>| [v[0], v[1], v[2]];
    if let Some(value) = shading.constant("diffuse")? {
        set.factors.base_color = Some(rgb(value));
    } else if let Some(diffuse) = shading.image("diffuse")? {
        set.base_color = Some(shading.write(files::BASE_COLOR, &diffuse.map(srgb_encode))?);
    }
    if let Some(value) = shading.constant("roughness")? {
        set.factors.roughness = Some(value[0]);
    } else if let Some(roughness) = shading.image("roughness")? {
        let plane = roughness.texels();
        let r = &roughness.data[..plane];
        let packed = [vec![1.0; plane], r.to_vec(), vec![0.0; plane]].concat();
        let (height, width) = (roughness.height, roughness.width);
        set.metallic_roughness = Some(shading.write(
            files::METALLIC_ROUGHNESS,
            &PlanarImage::new(3, height, width, packed)?,
        )?);
    }
    if let Some(value) = shading.constant("specular")? {
        set.factors.specular_color = Some(rgb(value));
    } else if let Some(specular) = shading.image("specular")? {
        set.specular_color =
            Some(shading.write(files::SPECULAR_COLOR, &specular.map(srgb_encode))?);
    }
    // A normal map of +z everywhere is the flat default: no texture.
    let flat = shading
        .constant("normal")?
        .is_some_and(|n| n[0] == 0.0 && n[1] == 0.0 && n[2] > 0.0);
    if let Some(normal) = shading.image("normal")?.filter(|_| !flat) {
        set.normal = Some(shading.write(files::NORMAL, &encode_normal(&normal))?);
    }
    Ok(())
}

/// `specular2` + `roughness2` as a clear coat (texture or factors, with the approximation
/// note); one of them alone is dropped.
fn clear_coat(shading: &Shading, set: &mut TextureSet) -> Result<()> {
    let coat = (
        shading.constant("specular2")?,
        shading.constant("roughness2")?,
    );
    match (shading.image("specular2")?, shading.image("roughness2")?) {
        _ if let (Some(specular2), Some(roughness2)) = &coat => {
            let texel = PlanarImage::new(3, 1, 1, specular2.clone())?;
            let (weight, clipped) = clearcoat_weight(&texel);
            set.factors.clearcoat = Some([weight[0], roughness2[0]]);
            set.approximations
                .push(clearcoat_note(100.0 * clipped as f64));
        }
        (Some(specular2), Some(roughness2)) => {
            let plane = specular2.texels();
            let (weight, clipped) = clearcoat_weight(&specular2);
            let packed = [weight, roughness2.data[..plane].to_vec(), vec![0.0; plane]].concat();
            let (height, width) = (specular2.height, specular2.width);
            set.clearcoat = Some(shading.write(
                files::CLEARCOAT,
                &PlanarImage::new(3, height, width, packed)?,
            )?);
            set.approximations
                .push(clearcoat_note(100.0 * clipped as f64 / plane as f64));
        }
        (one, other) => {
            for (name, present) in [
                ("specular2", one.is_some()),
                ("roughness2", other.is_some()),
            ] {
                if present {
                    set.dropped.push(format!(
                        "{name}: a clear coat needs both specular2 and roughness2"
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The clear-coat weight per texel of a `specular2` image, `min(lum(F0₂)/0.04, 1)`, and how
/// many texels the clamp clipped.
fn clearcoat_weight(specular2: &PlanarImage) -> (Vec<f32>, usize) {
    let plane = specular2.texels();
    let mut clipped = 0usize;
    let weight = (0..plane)
        .map(|t| {
            let lum: f32 = (0..3)
                .map(|c| LUMINANCE[c] * specular2.data[c * plane + t])
                .sum();
            let w = lum / DIELECTRIC_F0;
            clipped += usize::from(w > 1.0);
            w.min(1.0)
        })
        .collect();
    (weight, clipped)
}

/// The approximation note of the clear coat, with the percentage of clipped texels.
fn clearcoat_note(clipped_percent: f64) -> String {
    format!(
        "specular2 → clear-coat weight = luminance(specular2)/{DIELECTRIC_F0} clamped to 1 \
         (the clear coat's F0 is fixed at {DIELECTRIC_F0} and achromatic): colour dropped, \
         {clipped_percent:.1} % of texels clipped"
    )
}

/// Unit normals (x right, y up, z out) → `0.5·n + 0.5` after renormalising (the normal map
/// of a `ggx` material is normalised only when shaded).
fn encode_normal(normal: &PlanarImage) -> PlanarImage {
    let plane = normal.texels();
    let mut out = normal.clone();
    for t in 0..plane {
        let v = [0, 1, 2].map(|c| normal.data[c * plane + t]);
        let len = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        // A zero vector (never produced by the plugins) exports as flat +z.
        let n = if len > 1e-6 {
            v.map(|x| x / len)
        } else {
            [0.0, 0.0, 1.0]
        };
        for (c, x) in n.iter().enumerate() {
            out.data[c * plane + t] = 0.5 * x + 0.5;
        }
    }
    out
}
