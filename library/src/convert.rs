//! One texture set → the maps of a library material (docs/conventions.md, "Imported
//! materials"; docs/data.md, "What the importer writes"):
//!
//! - **square**: a `k:1` texture (k ≤ [`MAX_ASPECT`]) repeated along its short side, so the
//!   maps stay periodic; companions of another size resampled to the base's; sides above
//!   [`ConvertOptions::max_side`] halved;
//! - **diffuse** (linear): the base colour decoded with the display gamma, `rgb^2.2`;
//! - **normal**: the normal map in photomat's convention ([`crate::normals`], green decided
//!   per map), its slopes scaled by the engine's normal strength where the material file gives
//!   one;
//! - **height**: integrated from the normals ([`crate::relief`]), in world units for texels of
//!   [`PHOTO_SIDE`]`/N` (the material spans one photo's square at its stored resolution), as
//!   the `height(ggx, scale=S)` map that holds its range;
//! - **roughness**: `1 − gloss` from a gloss map, a roughness map as it is, else one value for
//!   the material: from the engine's Blinn–Phong exponent `n` where the material file gives
//!   one (α = √(2/(n+2)), Walter et al. 2007, §5.2; roughness = √α), else
//!   [`DEFAULT_ROUGHNESS`];
//! - **specular** (F0, rgb): the specular map's spatial pattern around a dielectric's mean,
//!   `F0 = 0.04 · clamp(s / max(s̄, 0.05), 0, 4)` (game specular maps scale an engine's
//!   highlight and have no unit); `0.04` without one.
//!
//! Materials that are not a surface a flash photo shows as its maps say are refused with the
//! reason ([`Rejection`]): a base colour under [`ConvertOptions::min_side`], an aspect the
//! maps cannot be tiled from, a cut-out (alpha), a missing or flat normal map, an emissive
//! material.

use photomat_core::flash::PHOTO_SIDE;
use photomat_core::image_io::PlanarImage;
use photomat_core::render::DISPLAY_GAMMA;
use serde::{Deserialize, Serialize};

use crate::normals::{self, GreenConvention};
use crate::relief::{HeightMap, integrate_periodic};
use crate::resample::{resize, tile_to_square};

/// Longest side over shortest side a texture may have: a 2:1 texture tiles into a square of
/// two repeats; longer ones are trims and strips, not surfaces.
pub const MAX_ASPECT: usize = 2;
/// A dielectric's F0, the specular albedo of glass, stone, wood and paint (4 %).
pub const F0_DIELECTRIC: f32 = 0.04;
/// Roughness of a material whose package says nothing about its gloss: a satin surface
/// between polished stone (0.3) and rough plaster (0.9); `photomat simulate --library` draws
/// such materials' roughness per photo instead (docs/data.md).
pub const DEFAULT_ROUGHNESS: f32 = 0.6;
/// Smallest roughness read from a gloss map: below 0.05 (α = 0.0025) a highlight is a
/// sub-texel mirror glint that game gloss maps do not mean.
pub const MIN_ROUGHNESS: f32 = 0.05;
/// Smallest mean specular map value the F0 formula divides by (module docs): below it the map
/// says "barely shiny", and dividing by its mean would blow its noise up to full strength.
const MIN_SPECULAR_MEAN: f32 = 0.05;
/// Largest multiple of [`F0_DIELECTRIC`] a specular map reaches (16 %: polished metal's
/// darker end), so that one bright texel does not become a mirror.
const MAX_SPECULAR_GAIN: f32 = 4.0;
/// Texels of a base colour's alpha under ½ that make it a cut-out (a decal, a grate): more
/// than 1 % of the texture.
const CUTOUT_FRACTION: f64 = 0.01;
/// Largest relief range a material may have, in world units: the `height(·)` adapter's `scale`
/// reaches 1 (the height of the flash above the photo's square of side 2). The surveyed
/// packages' surfaces span 0.03–0.14 (median per package), their tallest 0.9.
pub const MAX_RELIEF: f64 = 1.0;
/// A normal map whose normals are all within 0.5° of +z is flat (a placeholder map).
const FLAT_NORMAL_DEGREES: f64 = 0.5;

/// Size limits of the conversion.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvertOptions {
    /// Smallest side of a base colour. Default 256.
    pub min_side: usize,
    /// Largest side of the maps written; larger textures are halved. Default 1024.
    pub max_side: usize,
}

impl Default for ConvertOptions {
    fn default() -> Self {
        Self {
            min_side: 256,
            max_side: 1024,
        }
    }
}

/// Why a texture set is not imported.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rejection {
    /// The base colour is smaller than the minimum side.
    TooSmall,
    /// The sides are not k:1 with k ≤ [`MAX_ASPECT`] (trims, strips).
    Aspect,
    /// The base colour's alpha cuts holes (decals, grates, foliage).
    Cutout,
    /// The material lights itself.
    Emissive,
    /// No normal map, or one that cannot be read.
    NoNormal,
    /// The normal map is flat.
    FlatNormal,
    /// The normal map was made for another texture.
    BorrowedNormal,
    /// The path says it is not a surface (model skins, interface art, signs; [`crate::filter`]).
    NotSurface,
    /// The integrated relief spans more than [`MAX_RELIEF`] world units: a baked object's
    /// normals (a golf ball), not a surface's.
    SteepRelief,
    /// A near-duplicate of another material ([`crate::filter::Signature`]).
    Duplicate,
    /// A file of the set cannot be read or decoded (the message names it).
    Unreadable,
}

impl Rejection {
    /// A short description for reports.
    pub fn describe(&self) -> &'static str {
        match self {
            Rejection::TooSmall => "base colour under the minimum side",
            Rejection::Aspect => "not square or 2:1 (trims, strips)",
            Rejection::Cutout => "cut-out alpha (decals, grates)",
            Rejection::Emissive => "emissive (glow map or glow shader)",
            Rejection::NoNormal => "no normal map",
            Rejection::FlatNormal => "flat normal map",
            Rejection::BorrowedNormal => "normal map made for another texture",
            Rejection::NotSurface => "not a surface (skins, interface, signs)",
            Rejection::SteepRelief => "relief beyond the height model's range (baked objects)",
            Rejection::Duplicate => "near-duplicate of another material",
            Rejection::Unreadable => "a file cannot be read",
        }
    }
}

/// Where a material's roughness came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "from")]
pub enum RoughnessSource {
    GlossMap,
    RoughnessMap,
    /// The engine's Blinn–Phong exponent.
    SpecularPower {
        exponent: f64,
    },
    /// [`DEFAULT_ROUGHNESS`]: the package says nothing.
    Default,
}

/// The decoded files of one texture set (4-channel stored values, [`crate::decode`]).
pub struct DecodedSet {
    pub base: PlanarImage,
    pub normal: Option<PlanarImage>,
    pub specular: Option<PlanarImage>,
    pub gloss: Option<PlanarImage>,
    pub roughness: Option<PlanarImage>,
    pub height: Option<PlanarImage>,
    /// The engine's normal strength (slopes multiplied by it), if known.
    pub normal_strength: Option<f64>,
    /// The engine's Blinn–Phong exponent, if known.
    pub specular_power: Option<f64>,
}

/// The maps of one library material, N×N planar images.
#[derive(Debug, Clone)]
pub struct MaterialImages {
    /// Linear diffuse albedo (3).
    pub diffuse: PlanarImage,
    /// F0 (3).
    pub specular: PlanarImage,
    /// Roughness (1).
    pub roughness: PlanarImage,
    /// Unit normals in photomat's convention (3).
    pub normal: PlanarImage,
    /// Height for `height(ggx, scale)`.
    pub height: HeightMap,
    /// World units per texel ([`PHOTO_SIDE`]/N).
    pub texel_size: f64,
    pub green: GreenConvention,
    pub roughness_source: RoughnessSource,
    /// Whether a specular map set the F0's pattern.
    pub specular_map: bool,
}

impl MaterialImages {
    /// Side N of the square maps.
    pub fn side(&self) -> usize {
        self.diffuse.width
    }
}

/// The first `n` channels of `image`.
fn channels(image: &PlanarImage, n: usize) -> PlanarImage {
    let plane = image.width * image.height;
    PlanarImage {
        channels: n,
        height: image.height,
        width: image.width,
        data: image.data[..n * plane].to_vec(),
    }
}

/// `image` resized to `side`² (wrap-around: textures tile) unless it is that size already.
fn to_side(image: &PlanarImage, side: usize) -> PlanarImage {
    resize(image, side, side)
}

/// Converts the decoded set (module docs).
pub fn convert(set: &DecodedSet, options: &ConvertOptions) -> Result<MaterialImages, Rejection> {
    let (w, h) = (set.base.width, set.base.height);
    if w.min(h) < options.min_side {
        return Err(Rejection::TooSmall);
    }
    if w.max(h) > MAX_ASPECT * w.min(h) {
        return Err(Rejection::Aspect);
    }
    let alpha = &set.base.data[3 * w * h..];
    let holes = alpha.iter().filter(|&&a| a < 0.5).count();
    if holes as f64 > CUTOUT_FRACTION * (w * h) as f64 {
        return Err(Rejection::Cutout);
    }
    let base = tile_to_square(&set.base).ok_or(Rejection::Aspect)?;
    let mut side = base.width;
    while side > options.max_side && side.is_multiple_of(2) {
        side /= 2;
    }
    // Every companion at the base's own (unsquared) size, then squared like it.
    let squared = |image: &PlanarImage| -> Result<PlanarImage, Rejection> {
        let same = resize(image, w, h);
        tile_to_square(&same)
            .map(|s| to_side(&s, side))
            .ok_or(Rejection::Aspect)
    };
    let normal_rgb = squared(set.normal.as_ref().ok_or(Rejection::NoNormal)?)?;
    let height_hint = set.height.as_ref().map(squared).transpose()?;
    let green = normals::green_test(&normal_rgb, height_hint.as_ref());
    let mut normal = normals::decode(&normal_rgb, green.flipped);
    if let Some(strength) = set.normal_strength.filter(|s| *s > 0.0 && *s != 1.0) {
        normal = scale_slopes(&normal, strength as f32);
    }
    if max_tilt_degrees(&normal) < FLAT_NORMAL_DEGREES {
        return Err(Rejection::FlatNormal);
    }
    let texel_size = PHOTO_SIDE / side as f64;
    let (p, q) = normals::slopes(&normal);
    let heights = integrate_periodic(&p, &q, side, side, texel_size);
    let height = HeightMap::from_heights(&heights);
    if height.scale > MAX_RELIEF {
        return Err(Rejection::SteepRelief);
    }
    let diffuse = channels(&to_side(&base, side), 3).map(|v| v.powf(DISPLAY_GAMMA as f32));
    let specular_map = set.specular.as_ref().map(squared).transpose()?;
    let specular = match &specular_map {
        Some(map) => specular_from_map(&channels(map, 3)),
        None => PlanarImage::filled(3, side, side, F0_DIELECTRIC),
    };
    let (roughness, roughness_source) = roughness(set, &squared, side)?;
    Ok(MaterialImages {
        diffuse,
        specular,
        roughness,
        normal,
        height,
        texel_size,
        green,
        roughness_source,
        specular_map: specular_map.is_some(),
    })
}

/// The roughness map of `set` at `side`² and where it came from (module docs).
fn roughness(
    set: &DecodedSet,
    squared: &dyn Fn(&PlanarImage) -> Result<PlanarImage, Rejection>,
    side: usize,
) -> Result<(PlanarImage, RoughnessSource), Rejection> {
    if let Some(gloss) = &set.gloss {
        let map = channels(&squared(gloss)?, 1).map(|g| (1.0 - g).clamp(MIN_ROUGHNESS, 1.0));
        return Ok((map, RoughnessSource::GlossMap));
    }
    if let Some(rough) = &set.roughness {
        let map = channels(&squared(rough)?, 1).map(|r| r.clamp(MIN_ROUGHNESS, 1.0));
        return Ok((map, RoughnessSource::RoughnessMap));
    }
    if let Some(n) = set.specular_power.filter(|n| n.is_finite() && *n >= 0.0) {
        let value = roughness_from_exponent(n);
        return Ok((
            PlanarImage::filled(1, side, side, value),
            RoughnessSource::SpecularPower { exponent: n },
        ));
    }
    Ok((
        PlanarImage::filled(1, side, side, DEFAULT_ROUGHNESS),
        RoughnessSource::Default,
    ))
}

/// photomat's roughness for a Blinn–Phong exponent `n`: the Beckmann/GGX α of the same
/// highlight width, α = √(2/(n+2)) (Walter et al. 2007, §5.2), and roughness = √α
/// (docs/conventions.md: α = roughness²).
pub fn roughness_from_exponent(n: f64) -> f32 {
    let alpha = (2.0 / (n + 2.0)).sqrt();
    (alpha.sqrt() as f32).clamp(MIN_ROUGHNESS, 1.0)
}

/// F0 from a specular map's stored values (module docs).
fn specular_from_map(map: &PlanarImage) -> PlanarImage {
    let mean = map.data.iter().sum::<f32>() / map.data.len().max(1) as f32;
    let divisor = mean.max(MIN_SPECULAR_MEAN);
    map.map(|s| F0_DIELECTRIC * (s / divisor).clamp(0.0, MAX_SPECULAR_GAIN))
}

/// Unit normals with their slopes multiplied by `k` (the engine's normal strength).
fn scale_slopes(normal: &PlanarImage, k: f32) -> PlanarImage {
    let plane = normal.width * normal.height;
    let mut out = normal.clone();
    for i in 0..plane {
        let (x, y, z) = (
            k * normal.data[i],
            k * normal.data[plane + i],
            normal.data[2 * plane + i],
        );
        let l = (x * x + y * y + z * z).sqrt();
        out.data[i] = x / l;
        out.data[plane + i] = y / l;
        out.data[2 * plane + i] = z / l;
    }
    out
}

/// The largest angle between a normal of the map and +z, in degrees.
fn max_tilt_degrees(normal: &PlanarImage) -> f64 {
    let plane = normal.width * normal.height;
    let min_z = normal.data[2 * plane..3 * plane]
        .iter()
        .fold(1.0f32, |a, &z| a.min(z));
    (min_z.clamp(-1.0, 1.0) as f64).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::normals::tests::{stored_normals, test_height};

    /// A decoded set: a grey base, the normals of the test height (DirectX), nothing else.
    fn set(side_w: usize, side_h: usize) -> DecodedSet {
        let mut base = PlanarImage::filled(4, side_h, side_w, 0.5);
        base.data[3 * side_w * side_h..].fill(1.0);
        let side = side_w.min(side_h);
        let mut rgba = stored_normals(&test_height(side), side, true).data;
        rgba.extend(vec![1.0; side * side]);
        let normal = PlanarImage::new(4, side, side, rgba).unwrap();
        DecodedSet {
            base,
            normal: Some(resize(&normal, side_w, side_h)),
            specular: None,
            gloss: None,
            roughness: None,
            height: None,
            normal_strength: None,
            specular_power: None,
        }
    }

    #[test]
    fn small_strips_cutouts_and_missing_normals_are_refused_with_their_reason() {
        let options = ConvertOptions {
            min_side: 32,
            max_side: 64,
        };
        assert_eq!(
            convert(&set(16, 16), &options).err(),
            Some(Rejection::TooSmall)
        );
        assert_eq!(
            convert(&set(128, 32), &options).err(),
            Some(Rejection::Aspect)
        );
        let mut cut = set(32, 32);
        cut.base.data[3 * 1024..3 * 1024 + 100].fill(0.0);
        assert_eq!(convert(&cut, &options).err(), Some(Rejection::Cutout));
        let mut bare = set(32, 32);
        bare.normal = None;
        assert_eq!(convert(&bare, &options).err(), Some(Rejection::NoNormal));
        let mut flat = set(32, 32);
        flat.normal =
            Some(PlanarImage::new(4, 32, 32, [vec![0.5; 2048], vec![1.0; 2048]].concat()).unwrap());
        assert_eq!(convert(&flat, &options).err(), Some(Rejection::FlatNormal));
    }

    #[test]
    fn a_two_to_one_set_tiles_to_a_square_and_maps_follow_the_conventions() {
        let options = ConvertOptions {
            min_side: 32,
            max_side: 32,
        };
        let mut two = set(64, 32);
        two.gloss = Some(PlanarImage::filled(4, 32, 64, 0.75));
        let m = convert(&two, &options).unwrap();
        assert_eq!(m.side(), 32, "halved to the maximum side");
        assert!((m.diffuse.get(0, 3, 3) - 0.5f32.powf(2.2)).abs() < 1e-5);
        assert!((m.roughness.get(0, 0, 0) - 0.25).abs() < 1e-6);
        assert_eq!(m.roughness_source, RoughnessSource::GlossMap);
        assert!((m.specular.get(1, 5, 5) - F0_DIELECTRIC).abs() < 1e-7);
        assert!(m.green.flipped, "the test normals are stored DirectX-style");
        assert!((m.texel_size - PHOTO_SIDE / 32.0).abs() < 1e-15);
        assert!(m.height.scale > 0.0);
    }

    #[test]
    fn a_blinn_phong_exponent_gives_the_roughness_of_the_same_lobe_width() {
        // n = 15: α = √(2/17) = 0.343, roughness √α = 0.586.
        assert!((roughness_from_exponent(15.0) - 0.5857).abs() < 1e-3);
        // A huge exponent is a mirror, floored; n = 0 a uniform lobe, α = 1.
        assert_eq!(roughness_from_exponent(1e12), MIN_ROUGHNESS);
        assert!((roughness_from_exponent(0.0) - 1.0).abs() < 1e-6);
    }
}
