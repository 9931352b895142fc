//! What a sampling run reports: per material the L1 distance between the analytic and the
//! neural render under each light, their means, and the wall time of each stage; written as
//! `OUT/summary.json` by [`super::Sampler::run`].

/// Per-stage wall time, seconds.
#[derive(Debug, Default, Clone, serde::Serialize)]
pub struct Timings {
    /// Loading the model folder and preparing the output folder.
    pub load: f64,
    /// G: z → F.
    pub generate: f64,
    /// E: F → maps.
    pub estimate: f64,
    /// M: F ‖ ω → neural renders.
    pub relight: f64,
    /// The analytic flash renders of the maps.
    pub render: f64,
    /// The 2×2 tiled and hex-tiled renders.
    pub extras: f64,
    /// Simplifying the maps (`--simplify`: the renders of each candidate form).
    pub simplify: f64,
    /// Writing maps, PNGs, exports and the contact sheet.
    pub write: f64,
    /// The whole run.
    pub total: f64,
}

impl Timings {
    /// The per-material stages: everything but loading.
    pub fn per_material(&self) -> f64 {
        self.generate
            + self.estimate
            + self.relight
            + self.render
            + self.simplify
            + self.extras
            + self.write
    }
}

/// One material of the run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MaterialSummary {
    /// The material's seed.
    pub seed: u64,
    /// Its folder, `OUT/seed-XXXX`.
    pub folder: String,
    /// The BRDF model of its maps.
    pub brdf: String,
    /// How that model was chosen (`--brdf auto` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub selection: Option<super::Selection>,
    /// Which maps were simplified, the error that added and the bytes saved (`--simplify`
    /// only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub simplification: Option<photomat_core::simplify::SimplifyRecord>,
    /// L1 analytic vs neural per light, display-encoded [0, 1].
    pub l1_per_light: Vec<f64>,
    /// Mean of [`Self::l1_per_light`].
    pub l1_mean: f64,
    /// The same L1 over the texels within a photo's reach of the flash
    /// (`FlashGeometry::within_photo_reach`): where M relights under geometry it was trained
    /// on. Equal to [`Self::l1_per_light`] (to rounding) when every texel is within √2 of each
    /// flash, as on a unit-square material under the reference lights; NaN (JSON null) for a
    /// light that reaches none of the material's texels.
    pub l1_within_photo_reach_per_light: Vec<f64>,
    /// Mean of the finite values of [`Self::l1_within_photo_reach_per_light`].
    pub l1_within_photo_reach: f64,
}

/// The run: `OUT/summary.json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SampleSummary {
    /// The model folder.
    pub model: String,
    /// The estimator's BRDF model specification, or `auto` (each material's is in
    /// [`MaterialSummary::brdf`]).
    pub brdf: String,
    /// How many materials got each model.
    pub brdf_counts: std::collections::BTreeMap<String, usize>,
    /// Side of F and of the maps, texels.
    pub resolution: usize,
    /// Truncation ψ.
    pub psi: f64,
    /// Whether the GAN was trained tileable.
    pub tileable_model: bool,
    /// Highlight positions (x, y) of the lights, in the order of the renders.
    pub lights: Vec<[f64; 2]>,
    /// The seeds, in order.
    pub seeds: Vec<u64>,
    /// One entry per material, in seed order.
    pub materials: Vec<MaterialSummary>,
    /// What `--simplify` did over the run (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub simplification: Option<SimplifyTotals>,
    /// Mean over materials of the L1 per light.
    pub l1_per_light: Vec<f64>,
    /// Mean of [`Self::l1_per_light`].
    pub l1_mean: f64,
    /// Mean over materials (of their finite values) of [`MaterialSummary::l1_within_photo_reach`].
    pub l1_within_photo_reach: f64,
    /// Wall time per stage.
    pub timings_s: Timings,
    /// Materials per minute of the per-material stages.
    pub materials_per_minute: f64,
}

/// The simplifications of a run, summed over its materials.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SimplifyTotals {
    /// How many materials had each map made `constant` or `grey`, keyed `map: form`.
    pub counts: std::collections::BTreeMap<String, usize>,
    /// Bytes of the material folders before and after.
    pub bytes_before: u64,
    /// See [`Self::bytes_before`].
    pub bytes_after: u64,
    /// What each error measures (`super::SIMPLIFY_METRICS`).
    pub metrics: Vec<String>,
    /// Mean over materials of each error before and after.
    pub error_before: Vec<f64>,
    /// See [`Self::error_before`].
    pub error_after: Vec<f64>,
}

use photomat_core::simplify::SimplifyRecord;

impl SimplifyTotals {
    /// The totals of the materials that were simplified; `None` when none was.
    pub fn of(materials: &[MaterialSummary]) -> Option<Self> {
        let records: Vec<_> = materials
            .iter()
            .filter_map(|m| m.simplification.as_ref())
            .collect();
        if records.is_empty() {
            return None;
        }
        let mut counts = std::collections::BTreeMap::new();
        for step in records.iter().flat_map(|r| &r.steps) {
            let form = match step.form {
                photomat_core::simplify::MapForm::Constant(_) => "constant",
                photomat_core::simplify::MapForm::Grey => "grey",
            };
            *counts.entry(format!("{}: {form}", step.map)).or_insert(0) += 1;
        }
        let n = records.len() as f64;
        let mean = |errors: &dyn Fn(&SimplifyRecord) -> &Vec<f64>| -> Vec<f64> {
            (0..errors(records[0]).len())
                .map(|i| records.iter().map(|r| errors(r)[i]).sum::<f64>() / n)
                .collect()
        };
        Some(Self {
            counts,
            bytes_before: records.iter().map(|r| r.bytes_before).sum(),
            bytes_after: records.iter().map(|r| r.bytes_after).sum(),
            metrics: records[0].metrics.clone(),
            error_before: mean(&|r| &r.error_before),
            error_after: mean(&|r| &r.error_after),
        })
    }
}

impl SampleSummary {
    /// The summary of `materials` (at least one) rendered under `lights`; the means are over
    /// materials, then over lights.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        model: String,
        brdf: String,
        resolution: usize,
        psi: f64,
        tileable_model: bool,
        lights: Vec<[f64; 2]>,
        materials: Vec<MaterialSummary>,
        timings: Timings,
    ) -> Self {
        let n = materials.len() as f64;
        let l1_per_light: Vec<f64> = (0..lights.len())
            .map(|i| materials.iter().map(|m| m.l1_per_light[i]).sum::<f64>() / n)
            .collect();
        let l1_mean = l1_per_light.iter().sum::<f64>() / l1_per_light.len() as f64;
        let in_reach: Vec<f64> = materials.iter().map(|m| m.l1_within_photo_reach).collect();
        let l1_within_photo_reach = super::finite_mean(&in_reach);
        // The floor keeps the rate finite for a run too fast to time.
        let materials_per_minute = 60.0 * n / timings.per_material().max(f64::MIN_POSITIVE);
        let mut brdf_counts = std::collections::BTreeMap::new();
        for m in &materials {
            *brdf_counts.entry(m.brdf.clone()).or_insert(0) += 1;
        }
        Self {
            model,
            brdf,
            brdf_counts,
            resolution,
            psi,
            tileable_model,
            lights,
            seeds: materials.iter().map(|m| m.seed).collect(),
            simplification: SimplifyTotals::of(&materials),
            materials,
            l1_per_light,
            l1_mean,
            l1_within_photo_reach,
            timings_s: timings,
            materials_per_minute,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn means_are_over_materials_then_lights() {
        let m = |seed, l1: Vec<f64>| MaterialSummary {
            seed,
            folder: String::new(),
            brdf: "ggx".into(),
            selection: None,
            simplification: None,
            l1_mean: l1.iter().sum::<f64>() / l1.len() as f64,
            l1_within_photo_reach: l1[0],
            l1_within_photo_reach_per_light: vec![l1[0], f64::NAN],
            l1_per_light: l1,
        };
        let timings = Timings {
            generate: 1.0,
            write: 2.0,
            load: 100.0,
            ..Timings::default()
        };
        let s = SampleSummary::new(
            "m".into(),
            "ggx".into(),
            32,
            1.0,
            false,
            vec![[0.0, 0.0], [0.1, 0.1]],
            vec![m(3, vec![0.1, 0.3]), m(4, vec![0.3, 0.5])],
            timings,
        );
        assert_eq!(s.seeds, vec![3, 4]);
        assert_eq!(s.brdf_counts.get("ggx"), Some(&2));
        assert!((s.l1_per_light[0] - 0.2).abs() < 1e-12);
        assert!((s.l1_per_light[1] - 0.4).abs() < 1e-12);
        assert!((s.l1_mean - 0.3).abs() < 1e-12);
        assert!((s.l1_within_photo_reach - 0.2).abs() < 1e-12);
        // Two materials in the 3 s of per-material stages (loading excluded): 40 per minute.
        assert!((s.materials_per_minute - 40.0).abs() < 1e-9);
    }

    #[test]
    fn simplify_totals_count_forms_and_sum_bytes() {
        use photomat_core::simplify::{MapForm, SimplifyStep};
        let step = |map: &str, form| SimplifyStep {
            map: map.into(),
            form,
            error: vec![0.0],
        };
        let material = |record: Option<SimplifyRecord>| MaterialSummary {
            seed: 0,
            folder: String::new(),
            brdf: "ggx".into(),
            selection: None,
            simplification: record,
            l1_per_light: vec![0.0],
            l1_mean: 0.0,
            l1_within_photo_reach_per_light: vec![0.0],
            l1_within_photo_reach: 0.0,
        };
        let record = |steps, before, after, e0, e1| SimplifyRecord {
            tolerance: 0.1,
            metrics: vec!["l1".into()],
            error_before: vec![e0],
            error_after: vec![e1],
            steps,
            bytes_before: before,
            bytes_after: after,
        };
        assert_eq!(SimplifyTotals::of(&[material(None)]), None);
        let totals = SimplifyTotals::of(&[
            material(Some(record(
                vec![
                    step("roughness", MapForm::Constant(vec![0.5])),
                    step("specular", MapForm::Grey),
                ],
                1000,
                400,
                0.1,
                0.12,
            ))),
            material(Some(record(
                vec![step("roughness", MapForm::Constant(vec![0.2]))],
                1000,
                800,
                0.3,
                0.3,
            ))),
        ])
        .unwrap();
        assert_eq!(totals.counts.get("roughness: constant"), Some(&2));
        assert_eq!(totals.counts.get("specular: grey"), Some(&1));
        assert_eq!((totals.bytes_before, totals.bytes_after), (2000, 1200));
        assert_eq!(totals.metrics, ["l1"]);
        assert!((totals.error_before[0] - 0.2).abs() < 1e-12);
        assert!((totals.error_after[0] - 0.21).abs() < 1e-12);
    }
}
