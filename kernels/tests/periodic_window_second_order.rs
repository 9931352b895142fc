//! Second-order gradients through [`photomat_kernels::periodic_window`]: path-length
//! regularisation differentiates the gradient that flows back through the generator's rolled
//! window again, so the window's backward (a scatter-add) must itself have a backward (the
//! gather). Checks the double backward against the same computation through candle's
//! `narrow` + `cat` composition (f64).
//!
//! The inner pass keeps the graph of its gradients (`backward_keeping_graph`,
//! `docs/candle-notes.md`, "Second-order gradients").

use candle_core::{DType, Device, Result, Tensor, Var};
use photomat_core::rng::pseudo_random;
use photomat_kernels::testing::max_abs_diff;
use photomat_kernels::{periodic_window, with_reference_ops};

#[test]
fn double_backward_through_the_window_equals_candle() -> Result<()> {
    let dev = Device::Cpu;
    // A window inside the map and one larger than it (texels read twice).
    for (i, (shape, origins, window)) in [
        ((2, 3, 7, 9), vec![(3, 5), (6, 0)], (4, 5)),
        ((1, 2, 3, 4), vec![(2, 1)], (7, 9)),
    ]
    .into_iter()
    .enumerate()
    {
        let seed = 40 * i as u64;
        let x = Var::from_tensor(&pseudo_random(shape, seed, DType::F64, &dev)?)?;
        let (b, c, _, _) = shape;
        let g = pseudo_random((b, c, window.0, window.1), seed + 1, DType::F64, &dev)?;
        let h = pseudo_random(shape, seed + 2, DType::F64, &dev)?;
        let run = || -> Result<Vec<Tensor>> {
            // L = Σ g ⊙ window(x)²: ∂L/∂x = adjoint(2·g ⊙ window(x)) depends on x through the
            // gather, so differentiating ⟨∂L/∂x, h⟩ again runs the adjoint's own backward.
            let y = periodic_window(x.as_tensor(), &origins, window)?;
            let dx = (y.sqr()? * &g)?.sum_all()?.backward_keeping_graph()?;
            let dx = dx.get(x.as_tensor()).expect("dx").clone();
            let ddx = (&dx * &h)?.sum_all()?.backward()?;
            let ddx = ddx.get(x.as_tensor()).expect("a second derivative");
            Ok(vec![dx, ddx.clone()])
        };
        let fast = run()?;
        let reference = with_reference_ops(run)?;
        for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
            // Sums of at most four products of the same O(1) values in another order.
            assert!(
                max_abs_diff(a, r)? < 1e-12,
                "case {i}, derivative {}",
                j + 1
            );
        }
    }
    Ok(())
}
