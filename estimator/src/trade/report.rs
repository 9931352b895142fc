//! The trade study's results: one [`TradeEntry`] per BRDF model (accuracy, cost, whether it is
//! on the Pareto front), serialised as `trade.json` and written as the `trade.md` table.

use serde::{Deserialize, Serialize};

use super::TradeSettings;
use super::cost::{MapBytes, RenderCost};

/// One evaluation light, in plane coordinates of the unit square (scaled to the material).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LightRow {
    pub x: f64,
    pub y: f64,
    /// Not one of the reference's five lights.
    pub held_out: bool,
}

/// How well a model's analytic render reproduces M's relighting, averaged over materials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Accuracy {
    /// L1 of display-encoded images in [0, 1], per light (the report's light order).
    pub l1_per_light: Vec<f64>,
    /// Mean of `l1_per_light`.
    pub l1_mean: f64,
    /// Mean over the reference's five lights.
    pub l1_reference: f64,
    /// Mean over the held-out lights.
    pub l1_held_out: f64,
    /// SSIM per light (1 = identical structure).
    pub ssim_per_light: Vec<f64>,
    /// Mean of `ssim_per_light`.
    pub ssim_mean: f64,
}

impl Accuracy {
    /// From per-light figures whose first `reference` lights are the reference's.
    pub fn new(l1_per_light: Vec<f64>, ssim_per_light: Vec<f64>, reference: usize) -> Self {
        let mean = |v: &[f64]| {
            if v.is_empty() {
                f64::NAN
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            }
        };
        Self {
            l1_mean: mean(&l1_per_light),
            l1_reference: mean(&l1_per_light[..reference.min(l1_per_light.len())]),
            l1_held_out: mean(&l1_per_light[reference.min(l1_per_light.len())..]),
            ssim_mean: mean(&ssim_per_light),
            l1_per_light,
            ssim_per_light,
        }
    }
}

/// What a model costs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cost {
    /// Render and render + gradient time per megatexel.
    pub render: RenderCost,
    /// Parameters of its estimator E.
    pub estimator_parameters: usize,
    /// Mean seconds per training step of E.
    pub step_seconds: f64,
    /// Bytes of one evaluation material's exported maps.
    pub map_bytes: MapBytes,
}

/// One model of the study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TradeEntry {
    /// Canonical specification.
    pub spec: String,
    /// Channels of its maps (n).
    pub channels: usize,
    /// Its estimator's run folder.
    pub estimator_dir: String,
    /// Whether the estimator came from the cache.
    pub reused: bool,
    pub accuracy: Accuracy,
    pub cost: Cost,
    /// No other model is both cheaper to render and more accurate (L1).
    pub pareto: bool,
}

/// The whole study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TradeReport {
    pub settings: TradeSettings,
    pub lights: Vec<LightRow>,
    /// Sorted by render cost, cheapest first.
    pub entries: Vec<TradeEntry>,
}

impl TradeReport {
    /// Sorts the entries by render cost and marks the Pareto front of (render cost, L1).
    pub fn new(
        settings: TradeSettings,
        lights: Vec<LightRow>,
        mut entries: Vec<TradeEntry>,
    ) -> Self {
        entries.sort_by(|a, b| {
            a.cost
                .render
                .eval_ms_per_megatexel
                .total_cmp(&b.cost.render.eval_ms_per_megatexel)
        });
        let flags: Vec<bool> = entries
            .iter()
            .map(|e| {
                !entries.iter().any(|other| {
                    let (c, l) = (cost_of(other), other.accuracy.l1_mean);
                    let (c0, l0) = (cost_of(e), e.accuracy.l1_mean);
                    c <= c0 && l <= l0 && (c < c0 || l < l0)
                })
            })
            .collect();
        for (entry, flag) in entries.iter_mut().zip(flags) {
            entry.pareto = flag;
        }
        Self {
            settings,
            lights,
            entries,
        }
    }

    /// `trade.md`: the settings, then one row per model, cheapest first.
    pub fn markdown(&self) -> String {
        let s = &self.settings;
        let held_out = self.lights.iter().filter(|l| l.held_out).count();
        let mut text = format!(
            "# Speed against accuracy of BRDF models\n\n\
             GAN `{}`; every estimator trained with the same budget ({} + {} steps, width {}, \
             seed {}); evaluated on {} materials under {} lights ({} reference, {} held out). \
             Accuracy: the analytic render of E's maps against M's relighting, display-encoded \
             [0, 1] (L1, lower is better; SSIM, higher is better). Cost: flash render and \
             render + gradient time per megatexel on this machine, E's parameters and step \
             time, one material's PNG and EXR maps. ★: on the Pareto front of render time and L1.\n\n",
            s.gan.display(),
            s.steps,
            s.finetune_steps,
            s.width,
            s.seed,
            s.materials,
            self.lights.len(),
            self.lights.len() - held_out,
            held_out,
        );
        text.push_str(
            "| model | n | L1 | L1 reference | L1 held out | SSIM | render ms/Mtexel | \
             render+grad ms/Mtexel | E parameters | E s/step | PNG bytes | EXR bytes | |\n\
             |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for e in &self.entries {
            text.push_str(&format!(
                "| `{}` | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.1} | {:.1} | {} | {:.3} | {} | {} | {} |\n",
                e.spec,
                e.channels,
                e.accuracy.l1_mean,
                e.accuracy.l1_reference,
                e.accuracy.l1_held_out,
                e.accuracy.ssim_mean,
                e.cost.render.eval_ms_per_megatexel,
                e.cost.render.eval_grad_ms_per_megatexel,
                e.cost.estimator_parameters,
                e.cost.step_seconds,
                e.cost.map_bytes.png,
                e.cost.map_bytes.exr,
                if e.pareto { "★" } else { "" },
            ));
        }
        text
    }
}

/// The cost axis of the Pareto front and the plot.
pub fn cost_of(entry: &TradeEntry) -> f64 {
    entry.cost.render.eval_ms_per_megatexel
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(spec: &str, cost: f64, l1: f64) -> TradeEntry {
        TradeEntry {
            spec: spec.into(),
            channels: 3,
            estimator_dir: String::new(),
            reused: false,
            accuracy: Accuracy::new(vec![l1; 3], vec![0.9; 3], 2),
            cost: Cost {
                render: RenderCost {
                    eval_ms_per_megatexel: cost,
                    eval_grad_ms_per_megatexel: 2.0 * cost,
                },
                estimator_parameters: 10,
                step_seconds: 0.1,
                map_bytes: MapBytes { png: 1, exr: 2 },
            },
            pareto: false,
        }
    }

    #[test]
    fn entries_are_sorted_by_cost_and_the_pareto_front_is_marked() {
        let settings = TradeSettings::new("g".into(), vec![], "c".into());
        let report = TradeReport::new(
            settings,
            vec![],
            vec![
                entry("rich", 30.0, 0.02),
                entry("cheap", 5.0, 0.05),
                entry("dominated", 20.0, 0.06),
                entry("middle", 10.0, 0.03),
            ],
        );
        let order: Vec<(&str, bool)> = report
            .entries
            .iter()
            .map(|e| (e.spec.as_str(), e.pareto))
            .collect();
        assert_eq!(
            order,
            [
                ("cheap", true),
                ("middle", true),
                ("dominated", false),
                ("rich", true)
            ]
        );
        let table = report.markdown();
        assert_eq!(
            table.matches("★").count(),
            4,
            "3 rows and the legend:\n{table}"
        );
    }

    #[test]
    fn accuracy_splits_reference_and_held_out_lights() {
        let a = Accuracy::new(vec![1.0, 3.0, 5.0, 7.0], vec![1.0; 4], 3);
        assert_eq!(a.l1_reference, 3.0);
        assert_eq!(a.l1_held_out, 7.0);
        assert_eq!(a.l1_mean, 4.0);
    }
}
