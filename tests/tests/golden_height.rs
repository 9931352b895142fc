//! The `height` adapter against Mitsuba 3's `bumpmap`: `golden/height.json` holds bumpmap's
//! shading normals at every texel centre (the mean of its one-sided bilinear gradients either
//! side = wrap-around central differences) and Dr.Jit's gradient of a weighted sum of the normals
//! w.r.t. every height texel. Tolerances in `golden/README.md`.

use photomat_tests as _;

#[path = "golden_support/mod.rs"]
mod support;

use candle_core::{DType, Tensor, Var};
use photomat_core::vecops::normalize3;
use photomat_core::{MaterialMaps, lookup};
use support::{HeightCase, HeightGolden, Report, channels, exceeds, f32_exact, load, map_tensor};

/// Normal components are unit-vector coordinates: compared absolutely (≈ angle in radians).
const NORMAL_TOL: f64 = 1e-5;
/// Height gradients, relative to the largest |∂L/∂h| of the map.
const GRAD_TOL: f64 = 1e-5;

/// Our normals and ∂(Σ weights·normal)/∂height for one case, through the registered adapter.
fn ours(case: &HeightCase, dtype: DType) -> (Vec<Vec<f64>>, Vec<f64>) {
    let model = lookup(&format!("height(ggx, scale={})", f32_exact(case.scale))).unwrap();
    let height = Var::from_tensor(&map_tensor(
        std::slice::from_ref(&case.height),
        case.rows,
        case.cols,
        dtype,
    ))
    .unwrap();
    let maps = MaterialMaps::new().with("height", height.as_tensor().clone());
    let normal = model
        .shading_maps(&maps)
        .unwrap()
        .get("normal")
        .unwrap()
        .clone();
    (
        channels(&normal),
        weighted_gradient(&normal, &height, case, dtype),
    )
}

fn weighted_gradient(normal: &Tensor, height: &Var, case: &HeightCase, dtype: DType) -> Vec<f64> {
    let weights = map_tensor(&case.weights, case.rows, case.cols, dtype);
    let grads = (normal * weights)
        .unwrap()
        .sum_all()
        .unwrap()
        .backward()
        .unwrap();
    channels(
        grads
            .get(height.as_tensor())
            .expect("the height receives a gradient"),
    )
    .remove(0)
}

/// Normals `normal[k][texel]` and, optionally, ∂(Σ weights·normal)/∂height of one case.
type Outputs = (Vec<Vec<f64>>, Option<Vec<f64>>);

/// Compare normals (and, when given, height gradients) with the golden file.
fn compare(golden: &HeightGolden, normals: &dyn Fn(&HeightCase) -> Outputs) -> Report {
    let mut report = Report::default();
    for (i, case) in golden.cases.iter().enumerate() {
        let (n, grad) = normals(case);
        for (k, (ours_k, reference_k)) in n.iter().zip(&case.normal).enumerate() {
            for (t, (&o, &r)) in ours_k.iter().zip(reference_k).enumerate() {
                let err = if o.is_finite() {
                    (o - r).abs()
                } else {
                    f64::INFINITY
                };
                report.record("normal (abs)", err, i, &case.tag);
                if exceeds(err, NORMAL_TOL) {
                    let (row, col) = (t / case.cols, t % case.cols);
                    report.failures.push(format!(
                        "case {i} [{}; {}×{}; scale {}] texel (row {row}, col {col}) normal[{k}]: ours {o:.9} vs \
                         bumpmap {r:.9} (|Δ| {err:.2e} > {NORMAL_TOL:.0e}); heights around it: {:?}",
                        case.tag,
                        case.rows,
                        case.cols,
                        case.scale,
                        neighbourhood(case, row, col)
                    ));
                }
            }
        }
        let Some(grad) = grad else { continue };
        let scale = case.grad_height.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        for (t, (&o, &r)) in grad.iter().zip(&case.grad_height).enumerate() {
            let err = if o.is_finite() {
                (o - r).abs() / scale
            } else {
                f64::INFINITY
            };
            report.record("gradient height (rel. max)", err, i, &case.tag);
            if exceeds(err, GRAD_TOL) {
                report.failures.push(format!(
                    "case {i} [{}] d(Σ w·n)/d height[row {}, col {}]: ours {o:.9e} vs dr.jit {r:.9e} \
                     (err {err:.2e} > {GRAD_TOL:.0e})",
                    case.tag,
                    t / case.cols,
                    t % case.cols
                ));
            }
        }
    }
    report
}

/// The 3×3 heights around a texel (wrapping), for failure messages.
fn neighbourhood(case: &HeightCase, row: usize, col: usize) -> Vec<Vec<f64>> {
    let (r, c) = (case.rows as isize, case.cols as isize);
    (-1..=1)
        .map(|di| {
            (-1..=1)
                .map(|dj| {
                    let i = (row as isize + di).rem_euclid(r) as usize;
                    let j = (col as isize + dj).rem_euclid(c) as usize;
                    case.height[i * case.cols + j]
                })
                .collect()
        })
        .collect()
}

fn golden() -> HeightGolden {
    let golden: HeightGolden = load("height");
    assert_eq!(golden.meta.kind, "height");
    assert!(
        golden.cases.iter().any(|c| c.rows != c.cols),
        "a non-square map guards against swapped axes"
    );
    assert!(
        golden.cases.iter().any(|c| c.scale >= 1.0),
        "a huge-slope case is required"
    );
    golden
}

#[test]
fn height_normals_and_gradients_match_mitsuba_bumpmap_f64() {
    let golden = golden();
    let report = compare(&golden, &|case| {
        let (n, g) = ours(case, DType::F64);
        (n, Some(g))
    });
    report.assert_clean("height adapter (f64) vs Mitsuba bumpmap");
}

#[test]
fn height_normals_and_gradients_match_mitsuba_bumpmap_f32() {
    let golden = golden();
    let report = compare(&golden, &|case| {
        let (n, g) = ours(case, DType::F32);
        (n, Some(g))
    });
    report.assert_clean("height adapter (f32) vs Mitsuba bumpmap");
}

/// A height → normal conversion written out in the test: exact, or deliberately wrong.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Perturbation {
    /// The documented convention (the harness reproduces the adapter).
    None,
    /// Forward differences `h[j+1] − h[j]` instead of central ones.
    ForwardDifference,
    /// Row index growing towards +y (∂h/∂y with the opposite sign).
    RowsGrowUp,
    /// Clamped instead of wrapped borders.
    ClampedBorders,
}

fn perturbed_normals(case: &HeightCase, how: Perturbation) -> Vec<Vec<f64>> {
    let h = map_tensor(
        std::slice::from_ref(&case.height),
        case.rows,
        case.cols,
        DType::F64,
    );
    let (rows, cols) = (case.rows, case.cols);
    let s = f32_exact(case.scale);
    let shift = |t: &Tensor, by: i32, dim: usize| -> Tensor {
        match how {
            Perturbation::ClampedBorders => {
                let n = t.dim(dim).unwrap();
                let idx: Vec<u32> = (0..n as i64)
                    .map(|i| (i - by as i64).clamp(0, n as i64 - 1) as u32)
                    .collect();
                t.index_select(&Tensor::new(idx.as_slice(), t.device()).unwrap(), dim)
                    .unwrap()
            }
            _ => t.roll(by, dim).unwrap(),
        }
    };
    let (gx, gy) = match how {
        Perturbation::ForwardDifference => (
            ((shift(&h, -1, 3) - &h).unwrap() * cols as f64).unwrap(),
            ((&h - shift(&h, -1, 2)).unwrap() * rows as f64).unwrap(),
        ),
        Perturbation::RowsGrowUp => (
            ((shift(&h, -1, 3) - shift(&h, 1, 3)).unwrap() * (cols as f64 / 2.0)).unwrap(),
            ((shift(&h, -1, 2) - shift(&h, 1, 2)).unwrap() * (rows as f64 / 2.0)).unwrap(),
        ),
        Perturbation::None | Perturbation::ClampedBorders => (
            ((shift(&h, -1, 3) - shift(&h, 1, 3)).unwrap() * (cols as f64 / 2.0)).unwrap(),
            ((shift(&h, 1, 2) - shift(&h, -1, 2)).unwrap() * (rows as f64 / 2.0)).unwrap(),
        ),
    };
    let n = Tensor::cat(
        &[
            (gx * -s).unwrap(),
            (gy * -s).unwrap(),
            h.ones_like().unwrap(),
        ],
        1,
    )
    .unwrap();
    channels(&normalize3(&n).unwrap())
}

#[test]
fn height_golden_bites_wrong_differences() {
    let golden = golden();
    let exact = compare(&golden, &|case| {
        (perturbed_normals(case, Perturbation::None), None)
    });
    exact.assert_clean("height → normal written out in the test");
    for how in [
        Perturbation::ForwardDifference,
        Perturbation::RowsGrowUp,
        Perturbation::ClampedBorders,
    ] {
        let report = compare(&golden, &|case| (perturbed_normals(case, how), None));
        eprintln!(
            "{}",
            report.summary(&format!("perturbed height adapter ({how:?})"))
        );
        assert!(
            !report.failures.is_empty(),
            "{how:?} must fail the bumpmap comparison"
        );
    }
}
