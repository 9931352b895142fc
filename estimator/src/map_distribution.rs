//! The maps a model folder's estimator makes of the generator's materials, as statistics to
//! compare with real materials' (`photomat eval-gan --library`; [`photomat_core::map_distribution`]):
//! what PhotoMat could not measure, whether E's decodings of sampled materials have the spread of
//! colour, roughness and relief that artist-made materials have.

use std::path::Path;

use anyhow::Context;
use candle_core::Device;
use photomat_core::map_distribution::{MaterialStats, material_stats};
use photomat_generator::GanModel;

use crate::EstimatorModel;

/// The statistics of E's maps of `count` materials of the model folder `dir` (seeds from
/// `seed`), each `side`² texels (a multiple of the estimator's stride and the generator's
/// cell for a spatial model), sampled one at a time.
pub fn sampled_stats(
    dir: &Path,
    count: usize,
    side: usize,
    seed: u64,
) -> anyhow::Result<Vec<MaterialStats>> {
    let device = Device::Cpu;
    let gan = GanModel::load(dir, &device)
        .with_context(|| format!("cannot load the GAN model in '{}'", dir.display()))?;
    let estimator = EstimatorModel::load(dir, &device).with_context(|| {
        format!(
            "'{}' has no estimator to decode its materials",
            dir.display()
        )
    })?;
    let texel = gan.config().world_side(side)? / side as f64;
    let mut stats = Vec::with_capacity(count);
    for k in 0..count as u64 {
        let features = gan.features_for_seeds_at(&[seed.wrapping_add(k)], 1.0, side)?;
        let raw = estimator.estimator().forward(&features)?;
        let maps = estimator.brdf().decode(&raw)?.with_texel_size(Some(texel));
        stats.push(material_stats(estimator.brdf(), &maps)?);
    }
    Ok(stats)
}
