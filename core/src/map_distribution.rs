//! Whether a set of materials is distributed like another: the distributions over materials of
//! their maps' statistics (the diffuse albedo's mean and spread, the roughness's, the specular
//! level, the normals' spread) and over texels of the normals' tilt, compared by the 1-D
//! Wasserstein distance (the mean absolute difference of the two distributions' quantiles), so
//! that "a generator's materials have flat normals while real ones do not" is a number that
//! fails (docs/neural-models.md, "Map distributions").
//!
//! A statistic's distance is in its own units (albedo, roughness, degrees); each row also
//! gives both sets' medians so that the direction of a difference shows.

use serde::Serialize;

use crate::map_stats::map_spread;
use crate::{Brdf, MaterialMaps, Result};

/// Tilts of at most this many texels per material enter the per-texel distribution, evenly
/// spaced: 4096 give its quantiles to about 1 % and keep a set of hundred 512² materials in a
/// few megabytes.
const TILT_SAMPLES: usize = 4096;

/// One material's statistics (module docs).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialStats {
    /// Mean and standard deviation of the diffuse albedo's luminance (linear).
    pub diffuse: Option<(f64, f64)>,
    /// Mean of the specular F0's luminance.
    pub specular: Option<f64>,
    /// Mean and standard deviation of the roughness.
    pub roughness: Option<(f64, f64)>,
    /// RMS angle of the shading normals from their mean, degrees.
    pub normal_rms_deg: Option<f64>,
    /// Angles of sampled texels' normals from +z, degrees.
    pub tilts_deg: Vec<f64>,
}

/// Luminance weights of linear RGB (Rec. 709).
const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The statistics of one material (batch 1) of model `brdf`.
pub fn material_stats(brdf: &Brdf, maps: &MaterialMaps) -> Result<MaterialStats> {
    let spread = map_spread(brdf, maps)?;
    let find = |name: &str| spread.maps.iter().find(|m| m.name == name);
    let luma = |v: &[f64]| -> f64 {
        if v.len() == 3 {
            v.iter().zip(LUMA).map(|(x, w)| x * w).sum()
        } else {
            v.iter().sum::<f64>() / v.len().max(1) as f64
        }
    };
    let shading = brdf.shading_maps(maps)?;
    let tilts_deg = match shading.get("normal") {
        Ok(normal) => {
            let z: Vec<f32> = normal.narrow(1, 2, 1)?.flatten_all()?.to_vec1()?;
            let step = (z.len() / TILT_SAMPLES).max(1);
            z.iter()
                .step_by(step)
                // Rounding can put a unit normal's z a hair above 1: clamped for acos.
                .map(|&c| (c as f64).clamp(-1.0, 1.0).acos().to_degrees())
                .collect()
        }
        Err(_) => Vec::new(),
    };
    Ok(MaterialStats {
        diffuse: find("diffuse").map(|m| (luma(&m.mean), luma(&m.std))),
        specular: find("specular").map(|m| luma(&m.mean)),
        roughness: find("roughness").map(|m| (m.mean[0], m.std[0])),
        normal_rms_deg: spread.normal_angle_rms_deg,
        tilts_deg,
    })
}

/// One statistic compared between two sets.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatisticDistance {
    /// What is compared (`normal tilt per texel (deg)`, …).
    pub statistic: &'static str,
    /// Median over the compared set.
    pub median: f64,
    /// Median over the reference set.
    pub reference_median: f64,
    /// 1-D Wasserstein distance between the two distributions, in the statistic's units.
    pub wasserstein: f64,
}

/// The statistics of `set` against those of `reference` (module docs); a statistic absent
/// from either set (no roughness map, …) is left out.
pub fn compare(set: &[MaterialStats], reference: &[MaterialStats]) -> Vec<StatisticDistance> {
    type Pick = fn(&MaterialStats) -> Option<f64>;
    let per_material: [(&'static str, Pick); 6] = [
        ("diffuse mean (linear)", |s| s.diffuse.map(|d| d.0)),
        ("diffuse std (linear)", |s| s.diffuse.map(|d| d.1)),
        ("specular mean", |s| s.specular),
        ("roughness mean", |s| s.roughness.map(|r| r.0)),
        ("roughness std", |s| s.roughness.map(|r| r.1)),
        ("normal angle rms (deg)", |s| s.normal_rms_deg),
    ];
    let mut rows = Vec::new();
    for (statistic, pick) in per_material {
        let a: Vec<f64> = set.iter().filter_map(pick).collect();
        let b: Vec<f64> = reference.iter().filter_map(pick).collect();
        if let Some(row) = row(statistic, a, b) {
            rows.push(row);
        }
    }
    let tilts = |s: &[MaterialStats]| -> Vec<f64> {
        s.iter().flat_map(|m| m.tilts_deg.iter().copied()).collect()
    };
    rows.extend(row(
        "normal tilt per texel (deg)",
        tilts(set),
        tilts(reference),
    ));
    rows
}

/// The rows of [`compare`] as the table `photomat eval-gan --library` prints.
pub struct MapDistributionTable<'a>(pub &'a [StatisticDistance]);

impl std::fmt::Display for MapDistributionTable<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "maps of sampled materials against the library's (medians; 1-D Wasserstein \
             distance, lower is closer):"
        )?;
        writeln!(
            f,
            "{:>30}  {:>9}  {:>9}  {:>11}",
            "", "sampled", "library", "distance"
        )?;
        for r in self.0 {
            writeln!(
                f,
                "{:>30}  {:>9.4}  {:>9.4}  {:>11.4}",
                r.statistic, r.median, r.reference_median, r.wasserstein
            )?;
        }
        Ok(())
    }
}

fn row(statistic: &'static str, a: Vec<f64>, b: Vec<f64>) -> Option<StatisticDistance> {
    if a.is_empty() || b.is_empty() {
        return None;
    }
    Some(StatisticDistance {
        statistic,
        median: quantile(&sorted(a.clone()), 0.5),
        reference_median: quantile(&sorted(b.clone()), 0.5),
        wasserstein: wasserstein_1d(&a, &b),
    })
}

fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v
}

/// The `q`-quantile of sorted `v` (linear interpolation between order statistics).
fn quantile(v: &[f64], q: f64) -> f64 {
    let x = q * (v.len() - 1) as f64;
    let (i, f) = (x.floor() as usize, x - x.floor());
    let next = v[(i + 1).min(v.len() - 1)];
    v[i] * (1.0 - f) + next * f
}

/// The 1-D Wasserstein distance between the empirical distributions of `a` and `b`: the mean
/// absolute difference of their quantile functions, evaluated at 1000 evenly spaced levels
/// (exact for equal-sized samples up to that resolution).
pub fn wasserstein_1d(a: &[f64], b: &[f64]) -> f64 {
    let (a, b) = (sorted(a.to_vec()), sorted(b.to_vec()));
    let levels = 1000;
    (0..levels)
        .map(|k| {
            let q = (k as f64 + 0.5) / levels as f64;
            (quantile(&a, q) - quantile(&b, q)).abs()
        })
        .sum::<f64>()
        / levels as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wasserstein_distance_of_shifted_samples_is_the_shift() {
        let a: Vec<f64> = (0..100).map(|i| i as f64).collect();
        let b: Vec<f64> = a.iter().map(|x| x + 3.0).collect();
        assert!((wasserstein_1d(&a, &b) - 3.0).abs() < 1e-9);
        assert!(wasserstein_1d(&a, &a) < 1e-12);
    }
}
