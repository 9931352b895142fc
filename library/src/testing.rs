//! A small material library for tests of what reads libraries (the simulator's library
//! family, the relief prior's trainer): synthetic materials whose relief and colour are
//! periodic waves drawn from a seed, written with the importer's own writer
//! ([`crate::material::write_material`]) and indexed with a material per split at least.

use std::path::{Path, PathBuf};

use photomat_core::image_io::PlanarImage;
use photomat_core::rng::SplitMix64;

use crate::convert::{MaterialImages, RoughnessSource};
use crate::index::{IndexEntry, LibraryIndex, MATERIALS_DIR};
use crate::material::{Provenance, write_material};
use crate::normals::{GreenConvention, GreenEvidence};
use crate::pairing::Scheme;
use crate::relief::{HeightMap, integrate_periodic};
use crate::split::{Split, SplitShares};

/// Writes a library of `count` synthetic `side`² materials under `dir/library` (splits cycle
/// train, train, validation, test, …) and returns its folder.
pub fn tiny_library(dir: &Path, count: usize, side: usize) -> PathBuf {
    let library = dir.join("library");
    let mut materials = Vec::new();
    for k in 0..count {
        let id = format!("test/material-{k}");
        let images = synthetic_material(k as u64, side);
        let provenance = Provenance {
            package: "test".into(),
            version: "1".into(),
            scheme: Scheme::Suffix,
            defined_in: "tests".into(),
            files: Vec::new(),
            licences: vec!["CC0-1.0".into()],
            green: images.green,
            roughness: images.roughness_source,
            specular_map: false,
            normal_strength: None,
        };
        write_material(&library.join(MATERIALS_DIR).join(&id), &images, &provenance)
            .unwrap_or_else(|e| panic!("{e}"));
        let split = match k % 4 {
            2 => Split::Validation,
            3 => Split::Test,
            _ => Split::Train,
        };
        materials.push(IndexEntry {
            cluster: id.clone(),
            id,
            split,
            package: "test".into(),
            base: format!("material-{k}.png"),
            licences: vec!["CC0-1.0".into()],
            side,
            height_scale: images.height.scale,
        });
    }
    LibraryIndex {
        format: crate::index::FORMAT_TAG.into(),
        version: crate::index::FORMAT_VERSION,
        seed: 0,
        shares: SplitShares::default(),
        packages: Vec::new(),
        materials,
    }
    .save(&library)
    .unwrap_or_else(|e| panic!("{e}"));
    library
}

/// Material `seed`: a height of two periodic waves of random frequency, phase and strength,
/// and a diffuse colour that follows it.
pub fn synthetic_material(seed: u64, side: usize) -> MaterialImages {
    let mut rng = SplitMix64(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0x5eed);
    let texel = photomat_core::flash::PHOTO_SIDE / side as f64;
    let tau = std::f64::consts::TAU;
    let (kx, ky) = (
        1 + (rng.next_u64() % 4) as usize,
        1 + (rng.next_u64() % 4) as usize,
    );
    let amplitude = 0.005 + 0.02 * rng.next_unit();
    let phase = tau * rng.next_unit();
    let plane = side * side;
    let mut height = vec![0.0; plane];
    for r in 0..side {
        for c in 0..side {
            let (x, y) = (c as f64 / side as f64, r as f64 / side as f64);
            height[r * side + c] =
                amplitude * ((tau * kx as f64 * x + phase).sin() + (tau * ky as f64 * y).cos());
        }
    }
    // Normals of the heights, as the height adapter derives them (central differences).
    let at = |r: usize, c: usize| height[(r % side) * side + c % side];
    let mut normal = vec![0.0f32; 3 * plane];
    for r in 0..side {
        for c in 0..side {
            let gx = (at(r, c + 1) - at(r, c + side - 1)) / (2.0 * texel);
            let gy = (at(r + side - 1, c) - at(r + 1, c)) / (2.0 * texel);
            let l = (gx * gx + gy * gy + 1.0).sqrt();
            let i = r * side + c;
            normal[i] = (-gx / l) as f32;
            normal[plane + i] = (-gy / l) as f32;
            normal[2 * plane + i] = (1.0 / l) as f32;
        }
    }
    let normal = PlanarImage::new(3, side, side, normal).unwrap_or_else(|e| panic!("{e}"));
    let (p, q) = crate::normals::slopes(&normal);
    let integrated = integrate_periodic(&p, &q, side, side, texel);
    let tint = [
        0.3 + 0.5 * rng.next_unit(),
        0.3 + 0.5 * rng.next_unit(),
        0.3 + 0.5 * rng.next_unit(),
    ];
    let mut diffuse = Vec::with_capacity(3 * plane);
    for t in tint {
        diffuse.extend(
            height
                .iter()
                .map(|h| (t * (0.7 + 10.0 * h)).clamp(0.02, 0.98) as f32),
        );
    }
    MaterialImages {
        diffuse: PlanarImage::new(3, side, side, diffuse).unwrap_or_else(|e| panic!("{e}")),
        specular: PlanarImage::filled(3, side, side, 0.04),
        roughness: PlanarImage::filled(1, side, side, 0.4 + 0.4 * rng.next_unit() as f32),
        normal,
        height: HeightMap::from_heights(&integrated),
        texel_size: texel,
        green: GreenConvention {
            flipped: false,
            correlation: 1.0,
            evidence: GreenEvidence::Curl,
        },
        roughness_source: RoughnessSource::RoughnessMap,
        specular_map: false,
    }
}
