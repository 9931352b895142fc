//! The patched backward pass of `third_party/candle-core` (third_party/README.md): a node's first
//! gradient contribution is stored as it is instead of being added to a zero-filled tensor, so
//! it may be a strided view (a transpose, a broadcast). These graphs route such views into the
//! rules that need contiguous gradients or accumulators (index_select's index_add, a second
//! contribution, a reduction) and compare every gradient with its closed form.

use candle_core::{D, Device, IndexOp, Result, Tensor, Var};

fn values(t: &Tensor) -> Result<Vec<f32>> {
    t.flatten_all()?.to_vec1::<f32>()
}

fn assert_close(got: &Tensor, want: &[f32]) -> Result<()> {
    let got = values(got)?;
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 1e-6, "{got:?} vs {want:?}");
    }
    Ok(())
}

/// x (2×3) transposed, weighted, summed: d/dx = cᵀ, whose first contribution is a transposed view.
#[test]
fn a_transposed_first_contribution_is_the_right_gradient() -> Result<()> {
    let dev = Device::Cpu;
    let x = Var::new(&[[1f32, 2., 3.], [4., 5., 6.]], &dev)?;
    let c = Tensor::new(&[[1f32, 10.], [100., 1000.], [-1., -10.]], &dev)?;
    let grads = (x.t()? * &c)?.sum_all()?.backward()?;
    assert_close(
        grads.get(&x).expect("x has a gradient"),
        &[1., 100., -1., 10., 1000., -10.],
    )
}

/// Reversing the rows with index_select, then transposing (candle's `test_flip_backprop`
/// case): the gradient reaching index_select is a transposed view, and index_add needs it
/// contiguous. With loss Σ w ⊙ flip(x)ᵀ, d/dx[i][c] = w[c][2 − i].
#[test]
fn index_select_under_a_transpose_gets_a_contiguous_gradient() -> Result<()> {
    let dev = Device::Cpu;
    let x = Var::new(&[[1f32, 2.], [3., 4.], [5., 6.]], &dev)?;
    let idx = Tensor::new(&[2u32, 1, 0], &dev)?;
    let w = Tensor::new(&[[1f32, 2., 3.], [4., 5., 6.]], &dev)?;
    let flipped = x.index_select(&idx, 0)?;
    let grads = (flipped.t()? * &w)?.sum_all()?.backward()?;
    assert_close(
        grads.get(&x).expect("x has a gradient"),
        &[3., 6., 2., 5., 1., 4.],
    )
}

/// A variable used three times, first through a broadcast: the stored broadcast view must take
/// the later contributions. loss = Σ (x broadcast to 3×2) + 2·Σ x + Σ x[0]: d/dx = [6, 5].
#[test]
fn later_contributions_add_to_a_stored_broadcast_view() -> Result<()> {
    let dev = Device::Cpu;
    let x = Var::new(&[1f32, 2.], &dev)?;
    let a = x.broadcast_as((3, 2))?.sum_all()?;
    let b = (x.as_tensor() * 2.0)?.sum_all()?;
    let c = x.i(0)?;
    let grads = ((a + b)? + c)?.backward()?;
    assert_close(grads.get(&x).expect("x has a gradient"), &[6., 5.])
}

/// A subtraction whose first contribution is negated, through a keep-dim mean: loss =
/// Σ (y − mean_row(y)) ⊙ c with y = x, so d/dx = c − mean_row(c) broadcast.
#[test]
fn a_negated_first_contribution_through_a_reduction() -> Result<()> {
    let dev = Device::Cpu;
    let x = Var::new(&[[1f32, 2., 3.], [4., 5., 9.]], &dev)?;
    let c = Tensor::new(&[[3f32, 0., 0.], [1., 2., 6.]], &dev)?;
    let centred = x.as_tensor().broadcast_sub(&x.mean_keepdim(D::Minus1)?)?;
    let grads = (centred * &c)?.sum_all()?.backward()?;
    assert_close(
        grads.get(&x).expect("x has a gradient"),
        &[2., -1., -1., -2., -1., 3.],
    )
}
