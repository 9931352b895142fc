//! The patched backward pass of `third_party/candle-core` (third_party/README.md): a node's first
//! gradient contribution is stored as it is instead of being added to a zero-filled tensor, so
//! it may be a strided view (a transpose, a broadcast). These graphs route such views into the
//! rules that need contiguous gradients or accumulators (index_select's index_add, a second
//! contribution, a reduction) and compare every gradient with its closed form. The patch's
//! `backward_keeping_graph` keeps the graph of one pass's gradients only: a second derivative
//! through it equals its closed form, and the passes before and after it detach.

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

/// z = Σ (x²)²: ∂z/∂x = 4x³ passes through the node x², where a plain pass detaches the
/// incoming gradient 2x², so differentiating Σ ∂z/∂x again gives 4x² there instead of the
/// true 12x². A pass keeping its graph gives 12x², and only that pass keeps it.
#[test]
fn a_pass_keeping_its_graph_gives_second_derivatives_and_only_it() -> Result<()> {
    let dev = Device::Cpu;
    let x = Var::new(&[1f32, -2., 0.5], &dev)?;
    let z = |x: &Var| x.as_tensor().sqr()?.sqr()?.sum_all();
    let second = |grads: candle_core::backprop::GradStore| -> Result<Tensor> {
        let dx = grads.get(&x).expect("a gradient");
        assert_close(dx, &[4.0, -32.0, 0.5])?;
        let d2 = dx.sum_all()?.backward()?;
        Ok(d2.get(&x).expect("a second derivative").clone())
    };
    assert!(!candle_core::backprop::keeps_graph());
    assert_close(&second(z(&x)?.backward()?)?, &[4.0, 16.0, 1.0])?;
    assert_close(
        &second(z(&x)?.backward_keeping_graph()?)?,
        &[12.0, 48.0, 3.0],
    )?;
    assert!(!candle_core::backprop::keeps_graph());
    assert_close(&second(z(&x)?.backward()?)?, &[4.0, 16.0, 1.0])?;
    Ok(())
}
