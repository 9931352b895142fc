//! Shared code of the golden tests (`golden_*.rs`): load the Mitsuba 3 / Dr.Jit references that
//! `golden/generate.py` wrote, evaluate our models on the same inputs with candle autodiff, and
//! compare with the tolerances documented in `golden/README.md`.
//!
//! Every JSON number is a float32 written with 9 significant digits; [`f32_exact`] recovers the
//! exact float32 Mitsuba used. Our side evaluates in f64 by default: then the difference measures
//! the float32 rounding inside Mitsuba (the noisier side), not ours. An f32 evaluation is also
//! compared, with the looser [`F32`] tolerances measured for it.

#![allow(dead_code)] // each golden test binary uses a different part of this module

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

use candle_core::{DType, Device, Tensor, Var};
use photomat_core::{DifferentiableBrdf, MaterialMaps};
use serde::Deserialize;
use serde::de::DeserializeOwned;

/// The golden file `golden/<stem>.json`, parsed.
pub fn load<T: DeserializeOwned>(stem: &str) -> T {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../golden/{stem}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "cannot read {} ({e}); regenerate with `golden/run.sh generate`",
            path.display()
        )
    });
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is malformed: {e}", path.display()))
}

/// The float32 a golden number stands for (9 significant digits identify it exactly).
pub fn f32_exact(x: f64) -> f64 {
    x as f32 as f64
}

/// Common metadata of every golden file.
#[derive(Debug, Deserialize)]
pub struct Meta {
    pub kind: String,
    pub model: String,
    pub mitsuba: String,
    pub drjit: String,
    pub dtype: String,
    pub params: Vec<ParamMeta>,
}

#[derive(Debug, Deserialize)]
pub struct ParamMeta {
    pub name: String,
    pub channels: usize,
}

// ---------------------------------------------------------------------------------------------
// BRDF point cases (ggx.json, coated.json)

/// How a case is compared (chosen by the generator from the case's float32 condition number).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Class {
    /// The strict tolerances of golden/README.md ("Tolerances") apply.
    Strict,
    /// float32 cannot resolve the reference to 1e-5: finiteness plus the looser bounds below.
    IllConditioned,
}

#[derive(Debug, Deserialize)]
pub struct BrdfGolden {
    pub meta: Meta,
    pub cases: Vec<BrdfCase>,
}

#[derive(Debug, Deserialize)]
pub struct BrdfCase {
    pub tag: String,
    pub class: Class,
    pub value_source: String,
    /// How far the float32 reference value moves (relative) when its inputs move by one
    /// roundoff: what float32 can resolve of it.
    pub value_noise: f64,
    /// The same for its gradients, relative to the gradient-row norm.
    pub grad_noise: f64,
    pub wi: [f64; 3],
    pub wo: [f64; 3],
    pub params: BTreeMap<String, Vec<f64>>,
    pub f: [f64; 3],
    pub f_cos: [f64; 3],
    /// grad[param][output channel][param channel] of f·cos θ_o; absent where Dr.Jit's gradient
    /// is not finite (the zero normal).
    pub grad: Option<BTreeMap<String, Vec<Vec<f64>>>>,
}

/// Our model's outputs on every case of a golden file.
pub struct Evaluation {
    /// f·cos θ_o per case.
    pub f_cos: Vec<[f64; 3]>,
    /// cos θ_o w.r.t. the normalised normal (+z without a normal map), per case.
    pub cos_o: Vec<f64>,
    /// grad[case][param][output channel][param channel].
    pub grad: Vec<BTreeMap<String, [Vec<f64>; 3]>>,
}

fn column(values: impl Iterator<Item = f64>, channels: usize, n: usize, dtype: DType) -> Tensor {
    let data: Vec<f64> = values.map(f32_exact).collect();
    Tensor::from_vec(data, (1, channels, 1, n), &Device::Cpu)
        .and_then(|t| t.to_dtype(dtype))
        .expect("golden inputs form a tensor")
}

fn to_vec(t: &Tensor) -> Vec<f64> {
    t.to_dtype(DType::F64)
        .and_then(|t| t.flatten_all())
        .and_then(|t| t.to_vec1::<f64>())
        .expect("tensor to host")
}

/// Evaluate `model` on every case in one call: maps (1, C, 1, N) against directions (1, 3, 1, N);
/// gradients by reverse mode from the sum over cases of one output channel at a time (cases are
/// independent, so each case's gradient is its own).
pub fn evaluate(model: &dyn DifferentiableBrdf, cases: &[BrdfCase], dtype: DType) -> Evaluation {
    let n = cases.len();
    let dirs = |pick: fn(&BrdfCase) -> [f64; 3]| {
        column(
            (0..3).flat_map(|k| cases.iter().map(move |c| pick(c)[k])),
            3,
            n,
            dtype,
        )
    };
    let (wi, wo) = (dirs(|c| c.wi), dirs(|c| c.wo));
    let mut vars = Vec::new();
    let mut maps = MaterialMaps::new();
    for spec in model.params() {
        let ch = spec.channels;
        let values = (0..ch).flat_map(|k| cases.iter().map(move |c| c.params[spec.name][k]));
        let var = Var::from_tensor(&column(values, ch, n, dtype)).expect("var");
        maps.insert(spec.name, var.as_tensor().clone());
        vars.push((spec.name.to_string(), ch, var));
    }
    let out = model
        .eval(&wi, &wo, &maps)
        .expect("model evaluates the golden cases");
    assert_eq!(out.dims(), &[1, 3, 1, n], "eval output shape");
    let values = to_vec(&out);
    let f_cos = (0..n)
        .map(|i| [values[i], values[n + i], values[2 * n + i]])
        .collect();

    // cos θ_o w.r.t. the normalised normal, for f = f·cos θ_o / cos θ_o.
    let cos_o = (0..n)
        .map(|i| {
            let c = &cases[i];
            let wo = c.wo.map(f32_exact);
            let nrm = c.params.get("normal").map_or([0.0, 0.0, 1.0], |v| {
                let v: Vec<f64> = v.iter().copied().map(f32_exact).collect();
                let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                if len > 0.0 {
                    [v[0] / len, v[1] / len, v[2] / len]
                } else {
                    [0.0; 3]
                }
            });
            nrm[0] * wo[0] + nrm[1] * wo[1] + nrm[2] * wo[2]
        })
        .collect();

    let mut grad: Vec<BTreeMap<String, [Vec<f64>; 3]>> = vec![BTreeMap::new(); n];
    for c in 0..3 {
        let grads = out
            .narrow(1, c, 1)
            .and_then(|t| t.sum_all())
            .and_then(|t| t.backward())
            .expect("backward");
        for (name, ch, var) in &vars {
            let g = grads
                .get(var.as_tensor())
                .map_or_else(|| vec![0.0; ch * n], to_vec);
            for (i, case_grad) in grad.iter_mut().enumerate() {
                let entry = case_grad
                    .entry(name.clone())
                    .or_insert_with(|| [vec![], vec![], vec![]]);
                entry[c] = (0..*ch).map(|k| g[k * n + i]).collect();
            }
        }
    }
    Evaluation { f_cos, cos_o, grad }
}

/// Which tolerance a parameter's gradients get.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum GradKind {
    Albedo,
    Roughness,
    Normal,
}

pub fn grad_kind(param: &str) -> GradKind {
    match param {
        "normal" => GradKind::Normal,
        p if p.starts_with("roughness") => GradKind::Roughness,
        _ => GradKind::Albedo,
    }
}

/// Tolerances of one comparison (README "Tolerances"). Values are relative to the reference;
/// every gradient entry ∂f_c/∂p_j is relative to the per-case gradient norm of its output
/// channel, ‖∇f_c‖ over all parameters (entries that are 0 by symmetry, as ∂f/∂n at normal
/// incidence, would make a per-entry relative error meaningless).
#[derive(Debug, Clone, Copy)]
pub struct Tolerances {
    /// f·cos θ_o and f, relative.
    pub value: f64,
    /// Albedo (diffuse, specular) gradients.
    pub albedo: f64,
    /// Roughness gradients.
    pub roughness: f64,
    /// Normal gradients.
    pub normal: f64,
    /// Ill-conditioned cases are held to max(tolerance, `noise_factor` × the reference's
    /// measured float32 noise), after a finiteness check.
    pub noise_factor: f64,
}

/// Our f64 evaluation against the float32 references: golden/README.md's tolerances.
pub const F64: Tolerances = Tolerances {
    value: 1e-5,
    albedo: 1e-5,
    roughness: 1e-5,
    normal: 1e-4,
    noise_factor: 16.0,
};

/// Our f32 evaluation (the production dtype) holds the same tolerances on every case: since
/// sin²θ_h comes from `|n × h|²` and G1 is division-free (golden/FINDINGS.md, both fixed), the
/// measured worst f32 errors are 1.2e-6 (values) and 1.5e-6 (gradients), extremes included.
pub const F32: Tolerances = F64;

/// The worst error seen per kind, for the measured-worst note (golden/README.md).
#[derive(Debug, Default, Clone)]
pub struct Worst {
    pub err: f64,
    pub case: usize,
    pub tag: String,
}

/// Outcome of a comparison: the failures (with case index, inputs, ours vs reference) and the
/// worst error per kind of number.
#[derive(Debug, Default)]
pub struct Report {
    pub failures: Vec<String>,
    pub worst: BTreeMap<String, Worst>,
    pub checked: usize,
}

impl Report {
    /// How many failures are of a value (f·cos θ_o) rather than a gradient: what a model with
    /// a wrong formula must produce on most cases.
    pub fn value_failures(&self) -> usize {
        self.failures
            .iter()
            .filter(|f| f.contains("f·cos θ_o"))
            .count()
    }

    pub fn record(&mut self, kind: &str, err: f64, case: usize, tag: &str) {
        self.checked += 1;
        let w = self.worst.entry(kind.to_string()).or_insert_with(|| Worst {
            err: -1.0,
            ..Worst::default()
        });
        if err > w.err || err.is_nan() {
            *w = Worst {
                err,
                case,
                tag: tag.to_string(),
            };
        }
    }

    pub fn summary(&self, title: &str) -> String {
        let mut s = format!(
            "{title}: {} numbers compared, {} failures\n",
            self.checked,
            self.failures.len()
        );
        for (kind, w) in &self.worst {
            let _ = writeln!(
                s,
                "  worst {kind:<30} {:.3e}  (#{} {})",
                w.err, w.case, w.tag
            );
        }
        s
    }

    /// Panic with the failures (first 25) and the summary unless there are none; print the
    /// summary either way (`--nocapture` shows it).
    pub fn assert_clean(&self, title: &str) {
        eprintln!("{}", self.summary(title));
        if !self.failures.is_empty() {
            let shown: Vec<&str> = self.failures.iter().take(25).map(String::as_str).collect();
            panic!(
                "{title}: {} of {} numbers outside tolerance:\n{}\n{}",
                self.failures.len(),
                self.checked,
                shown.join("\n"),
                self.summary(title)
            );
        }
    }
}

fn describe(i: usize, c: &BrdfCase) -> String {
    format!(
        "case {i} [{}; {:?}; float32 noise {:.1e} / {:.1e}]: wi {:?} wo {:?} params {:?}",
        c.tag, c.class, c.value_noise, c.grad_noise, c.wi, c.wo, c.params
    )
}

/// Whether an error breaks its bound (NaN always does).
pub fn exceeds(err: f64, bound: f64) -> bool {
    err.is_nan() || err > bound
}

/// Relative error with an explicit scale; an exact 0 reference demands an exact 0.
fn rel(ours: f64, reference: f64, scale: f64) -> f64 {
    let d = (ours - reference).abs();
    if d == 0.0 {
        0.0
    } else if scale > 0.0 {
        d / scale
    } else {
        f64::INFINITY
    }
}

/// Compare our evaluation with a BRDF golden file.
pub fn compare_brdf(golden: &BrdfGolden, ours: &Evaluation, tol: &Tolerances) -> Report {
    let mut report = Report::default();
    for (i, case) in golden.cases.iter().enumerate() {
        let fail = |report: &mut Report, what: String| {
            report
                .failures
                .push(format!("{}\n    {what}", describe(i, case)));
        };
        let finite = ours.f_cos[i]
            .iter()
            .chain(ours.grad[i].values().flatten().flatten())
            .all(|x| x.is_finite());
        if !finite {
            fail(
                &mut report,
                format!(
                    "ours not finite: f·cos θ_o {:?}, gradients {:?}",
                    ours.f_cos[i], ours.grad[i]
                ),
            );
            report.record("non-finite", f64::INFINITY, i, &case.tag);
            continue;
        }
        let strict = case.class == Class::Strict;
        let class = if strict { "strict" } else { "ill-conditioned" };
        let value_tol = if strict {
            tol.value
        } else {
            tol.value.max(tol.noise_factor * case.value_noise)
        };

        // Values: f·cos θ_o, and f where θ_o is above the horizon.
        for c in 0..3 {
            let (o, r) = (ours.f_cos[i][c], case.f_cos[c]);
            let err = rel(o, r, r.abs());
            report.record(&format!("{class} value f·cos"), err, i, &case.tag);
            if exceeds(err, value_tol) {
                fail(
                    &mut report,
                    format!(
                        "f·cos θ_o[{c}]: ours {o:.9e} vs mitsuba {r:.9e} (rel {err:.2e} > {value_tol:.1e})"
                    ),
                );
            }
            if ours.cos_o[i] > 0.0 && case.f[c] != 0.0 {
                let o = ours.f_cos[i][c] / ours.cos_o[i];
                let r = case.f[c];
                let err = rel(o, r, r.abs());
                report.record(&format!("{class} value f"), err, i, &case.tag);
                if exceeds(err, value_tol) {
                    fail(
                        &mut report,
                        format!(
                            "f[{c}]: ours {o:.9e} vs mitsuba {r:.9e} (rel {err:.2e} > {value_tol:.1e})"
                        ),
                    );
                }
            }
        }

        // Gradients, where the reference has them (Dr.Jit's are NaN for the zero normal).
        let ours_grad = &ours.grad[i];
        let Some(reference) = &case.grad else {
            continue;
        };
        for c in 0..3 {
            let row_norm = reference
                .values()
                .flat_map(|g| g[c].iter())
                .map(|x| x * x)
                .sum::<f64>()
                .sqrt();
            for (name, r_block) in reference {
                let o_block = &ours_grad
                    .get(name)
                    .unwrap_or_else(|| panic!("our model has no '{name}' map"))[c];
                let r_block = &r_block[c];
                let kind = grad_kind(name);
                for (j, (&o, &r)) in o_block.iter().zip(r_block).enumerate() {
                    let kind_tol = match kind {
                        GradKind::Albedo => tol.albedo,
                        GradKind::Roughness => tol.roughness,
                        GradKind::Normal => tol.normal,
                    };
                    let bound = if strict {
                        kind_tol
                    } else {
                        kind_tol.max(tol.noise_factor * case.grad_noise)
                    };
                    let err = rel(o, r, row_norm);
                    let label = format!("{class} gradient {kind:?}");
                    report.record(&label, err, i, &case.tag);
                    if exceeds(err, bound) {
                        fail(
                            &mut report,
                            format!(
                                "d f·cos[{c}] / d {name}[{j}]: ours {o:.9e} vs dr.jit {r:.9e} (err {err:.2e} > {bound:.1e})"
                            ),
                        );
                    }
                }
            }
        }
    }
    report
}

/// Load a BRDF golden file and check its shape: ≥ 256 random cases, tagged
/// extremes, float32 references from the pinned Mitsuba, our model's parameter list.
pub fn load_brdf(stem: &str, model: &dyn DifferentiableBrdf) -> BrdfGolden {
    let golden: BrdfGolden = load(stem);
    assert_eq!(golden.meta.kind, "brdf");
    assert_eq!(golden.meta.model, model.name());
    assert_eq!(golden.meta.dtype, "float32");
    let ours: Vec<(&str, usize)> = model
        .params()
        .iter()
        .map(|s| (s.name, s.channels))
        .collect();
    let theirs: Vec<(&str, usize)> = golden
        .meta
        .params
        .iter()
        .map(|p| (p.name.as_str(), p.channels))
        .collect();
    assert_eq!(ours, theirs, "golden parameters differ from the model's");
    let random = golden
        .cases
        .iter()
        .filter(|c| c.tag.starts_with("random"))
        .count();
    assert!(random >= 256, "{stem}: only {random} random cases");
    assert!(
        golden
            .cases
            .iter()
            .filter(|c| c.tag.starts_with("random"))
            .all(|c| c.class == Class::Strict),
        "{stem}: every random case must be well-conditioned"
    );
    for needle in [
        "roughness_zero",
        "roughness_one",
        "grazing",
        "below_horizon",
    ] {
        assert!(
            golden.cases.iter().any(|c| c.tag.starts_with(needle)),
            "{stem}: no '{needle}' case"
        );
    }
    golden
}

// ---------------------------------------------------------------------------------------------
// Height → normal (height.json)

#[derive(Debug, Deserialize)]
pub struct HeightGolden {
    pub meta: Meta,
    pub cases: Vec<HeightCase>,
}

#[derive(Debug, Deserialize)]
pub struct HeightCase {
    pub tag: String,
    pub rows: usize,
    pub cols: usize,
    pub scale: f64,
    /// Row-major, row 0 at the top (+y).
    pub height: Vec<f64>,
    /// weights[k][texel] of the scalar Σ weights·normal whose gradient is `grad_height`.
    pub weights: Vec<Vec<f64>>,
    /// normal[k][texel].
    pub normal: Vec<Vec<f64>>,
    pub grad_height: Vec<f64>,
}

// ---------------------------------------------------------------------------------------------
// Renders (render_*.json)

#[derive(Debug, Deserialize)]
pub struct RenderGolden {
    pub meta: Meta,
    pub model: String,
    pub size: usize,
    pub highlight: [f64; 2],
    /// maps[name][channel][texel], row-major, row 0 at the top.
    pub maps: BTreeMap<String, Vec<Vec<f64>>>,
    /// radiance[channel][pixel].
    pub radiance: Vec<Vec<f64>>,
}

/// A golden map as an NCHW tensor (1, C, rows, cols) holding the exact float32 values.
pub fn map_tensor(channels: &[Vec<f64>], rows: usize, cols: usize, dtype: DType) -> Tensor {
    let data: Vec<f64> = channels.iter().flatten().copied().map(f32_exact).collect();
    Tensor::from_vec(data, (1, channels.len(), rows, cols), &Device::Cpu)
        .and_then(|t| t.to_dtype(dtype))
        .expect("golden map forms a tensor")
}

/// A tensor (1, C, H, W) as C lists of H·W numbers.
pub fn channels(t: &Tensor) -> Vec<Vec<f64>> {
    let (_, c, h, w) = t.dims4().expect("NCHW");
    let v = to_vec(t);
    (0..c)
        .map(|k| v[k * h * w..(k + 1) * h * w].to_vec())
        .collect()
}
