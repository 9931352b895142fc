//! The statistics of a library split's true maps ([`photomat_core::map_distribution`]), what
//! sampled materials are compared against (`photomat eval-gan --library`): each material's
//! `height(ggx)` maps resampled to the compared side (a material spans one photo's square, so a
//! 256² sample and a 1024² library material cover the same plane and their normals compare at
//! the same resolution once the library's is box-filtered to 256²).

use std::path::Path;

use candle_core::Device;
use photomat_core::image_io::PlanarImage;
use photomat_core::map_distribution::{MaterialStats, material_stats};
use photomat_core::{MaterialMaps, Result};

use crate::index::{LibraryIndex, MATERIALS_DIR};
use crate::material::MaterialFolders;
use crate::resample::resize;
use crate::split::Split;

/// The statistics of at most `count` materials of `split` of the library at `library`
/// (evenly spread over the split), each resampled to `side`².
pub fn split_stats(
    library: &Path,
    split: Split,
    count: usize,
    side: usize,
) -> Result<Vec<MaterialStats>> {
    let index = LibraryIndex::load(library)?;
    let members = index.split(split);
    let shown = count.min(members.len());
    let mut stats = Vec::with_capacity(shown);
    for k in 0..shown {
        let entry = members[k * members.len() / shown];
        let folders = MaterialFolders::of(&library.join(MATERIALS_DIR).join(&entry.id));
        let height = folders.load_height()?;
        let mut resized = MaterialMaps::new();
        for (name, map) in height.maps.iter() {
            let image = PlanarImage::from_tensor(map)?;
            resized.insert(name, resize(&image, side, side).to_tensor(&Device::Cpu)?);
        }
        let texel = height
            .maps
            .texel_size()
            .map(|t| t * height.manifest.resolution as f64 / side as f64);
        stats.push(material_stats(
            &height.brdf,
            &resized.with_texel_size(texel),
        )?);
    }
    Ok(stats)
}
