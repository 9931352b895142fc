//! What is not a surface material, by its path, and which materials are near-duplicates of
//! each other (docs/data.md, "What the importer leaves out").
//!
//! **By path.** Game data keeps model skins (UV atlases: karts, characters, weapons), interface
//! art, skies and particles beside its world textures; signs, glass, lights and grates among
//! them are objects, not surfaces. A texture whose path has a folder of
//! [`NOT_SURFACE_FOLDERS`] or whose file name has a word of [`NOT_SURFACE_WORDS`] is left out.
//!
//! **Near-duplicates.** Packages ship one texture in several tints (Red Eclipse's `plaster3`
//! in twelve colours over one normal map), at several sizes, or copied between games. A
//! material's [`Signature`] is its base colour's luminance and its normals' x and y on a
//! 16×16 grid of box means, each normalised to zero mean and unit variance, so tints, exposure
//! and size do not change it; two materials whose luminance signatures and whose normal
//! signatures are both closer than [`DUPLICATE_DISTANCE`] (RMS per cell) are one cluster, of
//! which the importer keeps one.

use photomat_core::image_io::PlanarImage;

use crate::resample::resize;

/// Folders (matched as whole path components, without letter case) that hold no surface
/// materials in the surveyed packages.
pub const NOT_SURFACE_FOLDERS: [&str; 20] = [
    "actors",
    "models",
    "skins",
    "karts",
    "weapons",
    "vanities",
    "particles",
    "hud",
    "ui",
    "gui",
    "icons",
    "fonts",
    "sky",
    "skies",
    "skybox",
    "skyboxes",
    "projectiles",
    "caustics",
    // Red Eclipse's `torley/desat`: painted abstract patterns, not photographed surfaces.
    "desat",
    // SuperTuxKart's `library/`: scenery objects (trees, chests, birds) with UV atlases.
    "library",
];

/// Words (between `_`, `-`, `.` and digits, without letter case) of file names that are
/// objects or effects rather than surfaces.
pub const NOT_SURFACE_WORDS: [&str; 24] = [
    "glass", "light", "lights", "lamp", "sign", "signs", "logo", "decal", "grate", "grating",
    "window", "door", "font", "trim", "strip", "border", "water", "lava", "sky", "fire", "flame",
    "smoke", "blend", "mask",
];

/// Whether the texture at tree path `path` is not a surface by its path (module docs).
pub fn not_surface(path: &str) -> bool {
    let lower = path.to_lowercase();
    let mut components: Vec<&str> = lower.split('/').collect();
    let name = components.pop().unwrap_or("");
    if components.iter().any(|c| NOT_SURFACE_FOLDERS.contains(c)) {
        return true;
    }
    name.split(|c: char| !c.is_ascii_alphabetic())
        .any(|word| NOT_SURFACE_WORDS.contains(&word))
}

/// Side of the signature grid.
pub const SIGNATURE_SIDE: usize = 16;
/// Largest RMS difference (in standard deviations per cell) between two signatures of one
/// cluster: tinted copies of a texture differ by under 0.05 after normalisation, distinct
/// textures of one family (two bricks) by over 0.5; 0.2 lies between with room for the size
/// copies' resampling.
pub const DUPLICATE_DISTANCE: f64 = 0.2;

/// A material's near-duplicate signature (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Signature {
    luminance: Vec<f64>,
    normal: Vec<f64>,
}

impl Signature {
    /// The signature of a base colour (RGB, any size) and its unit normals (3 planes).
    pub fn new(base: &PlanarImage, normal: &PlanarImage) -> Self {
        let s = SIGNATURE_SIDE;
        let small = resize(base, s, s);
        let plane = s * s;
        let luminance: Vec<f64> = (0..plane)
            .map(|i| {
                0.2126 * small.data[i] as f64
                    + 0.7152 * small.data[plane + i] as f64
                    + 0.0722 * small.data[2 * plane + i] as f64
            })
            .collect();
        let n = resize(normal, s, s);
        let mut normal_signature = standardised(&n.data[..plane]);
        normal_signature.extend(standardised(&n.data[plane..2 * plane]));
        Self {
            luminance: standardised_f64(&luminance),
            normal: normal_signature,
        }
    }

    /// Whether `self` and `other` are near-duplicates (module docs).
    pub fn is_duplicate_of(&self, other: &Signature) -> bool {
        rms_distance(&self.luminance, &other.luminance) < DUPLICATE_DISTANCE
            && rms_distance(&self.normal, &other.normal) < DUPLICATE_DISTANCE
    }
}

fn standardised(v: &[f32]) -> Vec<f64> {
    standardised_f64(&v.iter().map(|&x| x as f64).collect::<Vec<_>>())
}

/// `v` shifted to zero mean and scaled to unit variance (left at zero when constant).
fn standardised_f64(v: &[f64]) -> Vec<f64> {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    // A constant grid (a flat or uniform texture) has no pattern to compare: all zeros.
    let scale = if var > 1e-12 { 1.0 / var.sqrt() } else { 0.0 };
    v.iter().map(|x| (x - mean) * scale).collect()
}

fn rms_distance(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().max(1) as f64;
    (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / n).sqrt()
}

/// Clusters of near-duplicates among `signatures`: the cluster index of each, clusters
/// numbered in order of their first member (single linkage over all pairs).
pub fn clusters(signatures: &[Signature]) -> Vec<usize> {
    let n = signatures.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for i in 0..n {
        for j in i + 1..n {
            if signatures[i].is_duplicate_of(&signatures[j]) {
                let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                // The smaller index stays the root: clusters keep their first member.
                parent[a.max(b)] = a.min(b);
            }
        }
    }
    let mut numbers = vec![usize::MAX; n];
    let mut next = 0;
    (0..n)
        .map(|i| {
            let r = root(&mut parent, i);
            if numbers[r] == usize::MAX {
                numbers[r] = next;
                next += 1;
            }
            numbers[r]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::normals::decode;
    use crate::normals::tests::{stored_normals, test_height};

    #[test]
    fn skins_signs_and_interface_art_are_not_surfaces() {
        assert!(not_surface("data/actors/player/body_n.png"));
        assert!(not_surface("tracks/x/road_sign_03.png"));
        assert!(not_surface("data/luckystrike/Glass1.jpg"));
        assert!(not_surface("data/torley/desat/cloudy.png"));
        assert!(!not_surface("data/wicked/highqualitybrick.jpg"));
        assert!(!not_surface("data/trak/trak5/wall4a.jpg"));
        // Words are whole: "skyline" is not "sky", "stripes" not "strip".
        assert!(!not_surface("data/x/skyline_stripes.png"));
    }

    #[test]
    fn tints_and_sizes_of_one_texture_are_one_cluster_and_others_are_not() {
        let side = 64;
        let normal = decode(&stored_normals(&test_height(side), side, false), false);
        let base = |tint: [f32; 3]| {
            let mut data = Vec::new();
            for t in tint {
                data.extend(
                    normal.data[..side * side]
                        .iter()
                        .map(|x| t * (0.5 + 0.4 * x)),
                );
            }
            PlanarImage::new(3, side, side, data).unwrap()
        };
        let red = Signature::new(&base([0.9, 0.2, 0.1]), &normal);
        let blue = Signature::new(&base([0.1, 0.3, 0.8]), &normal);
        let half = Signature::new(
            &resize(&base([0.9, 0.2, 0.1]), 32, 32),
            &resize(&normal, 32, 32),
        );
        // Another texture: the same relief turned by 90°.
        let mut turned = normal.clone();
        for c in 0..3 {
            for r in 0..side {
                for col in 0..side {
                    turned.data[(c * side + r) * side + col] = normal.get(c, col, r);
                }
            }
        }
        let other = Signature::new(&base([0.9, 0.2, 0.1]), &turned);
        assert!(red.is_duplicate_of(&blue) && red.is_duplicate_of(&half));
        assert!(!red.is_duplicate_of(&other));
        assert_eq!(clusters(&[red, other, blue, half]), [0, 1, 0, 0]);
    }
}
