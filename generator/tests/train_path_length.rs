//! The path-length penalty's plumbing on a linear "generator" x = A·w, where the path
//! lengths have a closed form and the penalty's gradient (a double backward) is checked
//! against central finite differences.

use candle_core::{Device, Tensor, Var};
use photomat_generator::train::path_length::{PathLengthMean, path_lengths, pl_loss};

/// x = A·w per sample (a linear "generator"): g = Aᵀy in closed form, and the penalty's
/// gradient with respect to A matches central finite differences (the double backward).
#[test]
fn lengths_and_penalty_gradient_match_closed_form_and_finite_differences() {
    let dev = Device::Cpu;
    // ws (2, 1, 3) → images (2, 1, 2, 2) through A (4, 3).
    let a_vals: Vec<f64> = (0..12).map(|i| ((i * 7 % 5) as f64 - 2.0) * 0.3).collect();
    let ws = Tensor::new(&[[[0.5f64, -1.0, 0.25]], [[1.5, 0.5, -0.75]]], &dev).unwrap();
    let y_vals: Vec<f64> = (0..8).map(|i| ((i * 3 % 7) as f64 - 3.0) * 0.2).collect();
    let y = Tensor::from_vec(y_vals.clone(), (2, 1, 2, 2), &dev).unwrap();
    let penalty = |a: &Tensor| -> Tensor {
        let wsv = Var::from_tensor(&ws).unwrap();
        let x = wsv
            .as_tensor()
            .reshape((2, 3))
            .unwrap()
            .matmul(&a.t().unwrap())
            .unwrap()
            .reshape((2, 1, 2, 2))
            .unwrap();
        let l = path_lengths(&x, wsv.as_tensor(), &y).unwrap();
        pl_loss(&l, 0.5, 2.0, 4).unwrap()
    };
    let a = Var::from_vec(a_vals.clone(), (4, 3), &dev).unwrap();
    // Closed form of the lengths: g_b = Aᵀ y_b, one layer.
    let wsv = Var::from_tensor(&ws).unwrap();
    let x = wsv
        .as_tensor()
        .reshape((2, 3))
        .unwrap()
        .matmul(&a.as_tensor().t().unwrap())
        .unwrap()
        .reshape((2, 1, 2, 2))
        .unwrap();
    let l = path_lengths(&x, wsv.as_tensor(), &y)
        .unwrap()
        .to_vec1::<f64>()
        .unwrap();
    for (b, lb) in l.iter().enumerate() {
        let g: Vec<f64> = (0..3)
            .map(|j| (0..4).map(|i| a_vals[i * 3 + j] * y_vals[b * 4 + i]).sum())
            .collect();
        let expect = g.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!((lb - expect).abs() < 1e-12, "{lb} vs {expect}");
    }
    let grads = penalty(a.as_tensor()).backward().unwrap();
    let analytic = grads
        .get(&a)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f64>()
        .unwrap();
    let h = 1e-6;
    for k in 0..12 {
        let shifted = |d: f64| {
            let mut v = a_vals.clone();
            v[k] += d;
            // A variable, as G's weights are: its graph is what the detach check looks for.
            let t = Var::from_vec(v, (4, 3), &dev).unwrap();
            penalty(t.as_tensor()).to_scalar::<f64>().unwrap()
        };
        let fd = (shifted(h) - shifted(-h)) / (2.0 * h);
        assert!(
            (analytic[k] - fd).abs() < 1e-6,
            "A[{k}]: {} vs {fd}",
            analytic[k]
        );
    }
    let mean = PathLengthMean::new(&dev).unwrap();
    assert!((mean.update(2.0).unwrap() - 0.02).abs() < 1e-15);
    assert!((mean.update(2.0).unwrap() - (0.02 + 1.98 * 0.01)).abs() < 1e-15);
}
