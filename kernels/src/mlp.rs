//! A per-texel MLP (PhotoMat's relighting network M, paper §3 "Relightable generator" and §4
//! "Implementation") as one fused CPU op with its backward pass.
//!
//! Every texel is one row of a chain of fully connected layers
//!
//! ```text
//! h₋₁ = x (the texel's input channels),  zᵢ = hᵢ₋₁·Ŵᵢᵀ + b̂ᵢ,
//! hᵢ = gain · LeakyReLU(zᵢ, slope) for i < L − 1,  y = z_{L−1},
//! ```
//!
//! with effective weights `Ŵᵢ = weight_gainᵢ · Wᵢ` and biases `b̂ᵢ = bias_gainᵢ · bᵢ` (the
//! equalised learning rate of Karras et al. 2018 §4.1). Composed from candle ops this is one
//! transpose and concatenation of the NCHW inputs into rows, per layer a scaled weight, its
//! transpose, a matrix product, a bias and an activation pass, and a transpose back — with as
//! many passes again backward (measured at 2.7–4.3× PyTorch's CPU time:
//! `docs/benchmarks/pytorch.md`, "photomat vs PyTorch CPU, re-measured with this session's
//! thread defaults"). Here the rows are processed in blocks of [`BLOCK_ROWS`] texels, each
//! block running the whole chain while its activations are in L2: the block's inputs are
//! gathered straight from the NCHW tensors (the `F ‖ ω` concatenation exists only block by
//! block), every layer is one `gemm` call on row-major activations against the weights
//! arranged once per call, bias and activation run on the cache-hot block right after it, and
//! the last layer writes the NCHW output. Blocks run in parallel on rayon's pool.
//!
//! The forward keeps the hidden activations (only when an input is tracked, so inference
//! keeps none) for the backward, which runs the chain in reverse per block: input gradients
//! of both inputs written in their NCHW layout, weight and bias gradients accumulated per
//! rayon task.
//!
//! # Higher derivatives
//! Path-length regularisation (StyleGAN2 §3.2) differentiates the input gradient of M again
//! with respect to M's weights (and, through F, G's). The input gradient
//! `dx = dy·Ŵ_{L−1}·D_{L−2}·Ŵ_{L−2} ⋯ D₀·Ŵ₀` (Dᵢ the diagonal LeakyReLU derivatives, piecewise
//! constant, so of zero derivative wherever it exists) is multilinear in `dy` and the
//! weights; its second-order op runs the masked chain forward on the incoming gradient and
//! forms the weight products from the backward's saved `dzᵢ`: exact, as the candle
//! composition's double backward. The second derivative of the *weight* gradients (which
//! depend on the activations) is not implemented: a second backward that reaches them fails
//! with an error instead of returning a wrong value, and so does any third derivative. Use
//! [`crate::with_reference_ops`] for those.
//!
//! CPU tensors of dtype f32 or f64 take this path; other devices and dtypes, and calls inside
//! [`crate::reference::with_reference_ops`], use [`per_texel_mlp_reference`].

use candle_core::{DType, Result, Shape, Tensor, bail};

use crate::activation::leaky_relu_gain;

mod backward;
mod forward;
mod net;
mod rows;
mod second_order;

use forward::Forward;
pub use net::{MlpActivation, MlpLayer};
use net::{Net, pack};
pub use rows::BLOCK_ROWS;
use rows::{Io, Plane};

/// The per-texel MLP `layers` on NCHW inputs, the texel's input row being the channels of
/// `features` followed by those of `omega`; fused on the CPU (module docs).
///
/// # Shapes
/// features (B, C, H, W), omega (B, K, H, W), layer i weight (dᵢ₊₁, dᵢ) with d₀ = C + K and
/// every hidden width equal, bias (dᵢ₊₁) → (B, d_L, H, W).
pub fn per_texel_mlp(
    features: &Tensor,
    omega: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (b, c, h, w) = features.dims4()?;
    let (ob, k, oh, ow) = omega.dims4()?;
    if (ob, oh, ow) != (b, h, w) {
        bail!(
            "per-texel mlp: omega {:?} does not match features {:?}",
            omega.dims(),
            features.dims()
        );
    }
    let net = Net::new(layers, c + k, act)?;
    if !fusable(&[features, omega], layers) {
        return per_texel_mlp_reference(features, omega, layers, act);
    }
    let io = Io {
        batch: b,
        pixels: h * w,
        inputs: vec![Plane::nchw(c, h * w), Plane::nchw(k, h * w)],
        output: Plane::nchw(net.out_width(), h * w),
        output_shape: Shape::from((b, net.out_width(), h, w)),
    };
    let save = features.track_op() || omega.track_op() || layers_track(layers);
    let params = pack(layers)?;
    features
        .contiguous()?
        .apply_op3(&omega.contiguous()?, &params, Forward::new(net, io, save))
}

/// The per-texel MLP `layers` on rows, one texel per row; fused on the CPU (module docs).
///
/// # Shapes
/// rows (N, d₀), layers as in [`per_texel_mlp`] → (N, d_L).
pub fn per_texel_mlp_rows(
    rows: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (n, d0) = rows.dims2()?;
    let net = Net::new(layers, d0, act)?;
    if !fusable(&[rows], layers) {
        return per_texel_mlp_rows_reference(rows, layers, act);
    }
    let io = Io {
        batch: 1,
        pixels: n,
        inputs: vec![Plane::rows(d0, n)],
        output: Plane::rows(net.out_width(), n),
        output_shape: Shape::from((n, net.out_width())),
    };
    let save = rows.track_op() || layers_track(layers);
    let params = pack(layers)?;
    rows.contiguous()?
        .apply_op2(&params, Forward::new(net, io, save))
}

/// [`per_texel_mlp`] composed from candle ops: concatenation, transpose to rows, per layer a
/// matrix product, bias and [`crate::leaky_relu_gain`], transpose back.
///
/// # Shapes
/// As [`per_texel_mlp`].
pub fn per_texel_mlp_reference(
    features: &Tensor,
    omega: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (b, c, h, w) = features.dims4()?;
    let k = omega.dim(1)?;
    let rows = Tensor::cat(&[features, omega], 1)?
        .permute((0, 2, 3, 1))?
        .contiguous()?
        .reshape((b * h * w, c + k))?;
    let y = per_texel_mlp_rows_reference(&rows, layers, act)?;
    let out = y.dim(1)?;
    y.reshape((b, h, w, out))?
        .permute((0, 3, 1, 2))?
        .contiguous()
}

/// [`per_texel_mlp_rows`] composed from candle ops.
///
/// # Shapes
/// As [`per_texel_mlp_rows`].
pub fn per_texel_mlp_rows_reference(
    rows: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (_n, d0) = rows.dims2()?;
    Net::new(layers, d0, act)?;
    let mut x = rows.clone();
    for (i, l) in layers.iter().enumerate() {
        let w = l.weight.affine(l.weight_gain, 0.0)?;
        x = x
            .matmul(&w.t()?)?
            .broadcast_add(&l.bias.affine(l.bias_gain, 0.0)?)?;
        if i + 1 < layers.len() {
            x = leaky_relu_gain(&x, act.slope, act.gain)?;
        }
    }
    Ok(x)
}

/// Whether the fused op applies: CPU, f32 or f64 throughout, not in reference mode.
fn fusable(inputs: &[&Tensor], layers: &[MlpLayer<'_>]) -> bool {
    let dtype = inputs[0].dtype();
    let mut all = inputs
        .iter()
        .copied()
        .chain(layers.iter().flat_map(|l| [l.weight, l.bias]));
    matches!(dtype, DType::F32 | DType::F64)
        && all.all(|t| t.device().is_cpu() && t.dtype() == dtype)
        && !crate::reference::reference_ops()
}

fn layers_track(layers: &[MlpLayer<'_>]) -> bool {
    layers
        .iter()
        .any(|l| l.weight.track_op() || l.bias.track_op())
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    const ACT: MlpActivation = MlpActivation {
        slope: 0.2,
        gain: std::f64::consts::SQRT_2,
    };

    /// Weights and biases of a `dims` MLP as variables, with equalised-lr-like gains.
    fn layers(dims: &[usize], seed: u64, dtype: DType) -> Result<Vec<(Var, Var, f64, f64)>> {
        let dev = Device::Cpu;
        (0..dims.len() - 1)
            .map(|i| {
                let s = seed + 2 * i as u64;
                let w = Var::from_tensor(&pseudo_random((dims[i + 1], dims[i]), s, dtype, &dev)?)?;
                let b = Var::from_tensor(&pseudo_random(dims[i + 1], s + 1, dtype, &dev)?)?;
                Ok((w, b, 1.3 / (dims[i] as f64).sqrt(), 0.7))
            })
            .collect()
    }

    fn views(l: &[(Var, Var, f64, f64)]) -> Vec<MlpLayer<'_>> {
        l.iter()
            .map(|(w, b, g, bg)| MlpLayer {
                weight: w.as_tensor(),
                bias: b.as_tensor(),
                weight_gain: *g,
                bias_gain: *bg,
            })
            .collect()
    }

    /// The layers' weights and biases as constant tensors (outside any graph), with their gains.
    fn detached(l: &[(Var, Var, f64, f64)]) -> Vec<(Tensor, Tensor, f64, f64)> {
        l.iter()
            .map(|(w, b, g, bg)| (w.as_tensor().detach(), b.as_tensor().detach(), *g, *bg))
            .collect()
    }

    /// [`views`] of [`detached`] layers.
    fn constant_views(l: &[(Tensor, Tensor, f64, f64)]) -> Vec<MlpLayer<'_>> {
        l.iter()
            .map(|(w, b, g, bg)| MlpLayer {
                weight: w,
                bias: b,
                weight_gain: *g,
                bias_gain: *bg,
            })
            .collect()
    }

    /// Output and the gradients of `Σ y ⊙ r` with respect to every input and parameter.
    fn value_and_grads(
        y: &Tensor,
        r: &Tensor,
        wrt: &[&Var],
        params: &[(Var, Var, f64, f64)],
    ) -> Result<Vec<Tensor>> {
        let store = (y * r)?.sum_all()?.backward()?;
        let mut out = vec![y.clone()];
        for v in wrt
            .iter()
            .copied()
            .chain(params.iter().flat_map(|(w, b, _, _)| [w, b]))
        {
            out.push(store.get(v.as_tensor()).cloned().expect("a gradient"));
        }
        Ok(out)
    }

    fn compare(fused: &[Tensor], reference: &[Tensor], tol: f64, what: &str) -> Result<()> {
        assert_eq!(fused.len(), reference.len());
        for (j, (f, r)) in fused.iter().zip(reference).enumerate() {
            assert_eq!(f.dims(), r.dims(), "{what}, output {j}");
            let scale = r.abs()?.max_keepdim(0)?.flatten_all()?.max(0)?;
            let scale = scale.to_dtype(DType::F64)?.to_scalar::<f64>()?.max(1.0);
            let d = max_abs_diff(f, r)?;
            assert!(
                d <= tol * scale,
                "{what}, output {j}: |Δ| {d}, scale {scale}"
            );
        }
        Ok(())
    }

    /// With constant parameters (a frozen M) the inputs' gradients are those of the full
    /// backward pass, and the parameters get none.
    #[test]
    fn a_frozen_mlp_passes_the_same_input_gradients() -> Result<()> {
        let dev = Device::Cpu;
        let params = layers(&[7, 16, 16, 3], 5, DType::F64)?;
        let f = Var::from_tensor(&pseudo_random((2, 4, 17, 19), 6, DType::F64, &dev)?)?;
        let om = pseudo_random((2, 3, 17, 19), 7, DType::F64, &dev)?;
        let r = pseudo_random((2, 3, 17, 19), 8, DType::F64, &dev)?;
        let y = per_texel_mlp(f.as_tensor(), &om, &views(&params), ACT)?;
        let full = (y * &r)?.sum_all()?.backward()?;
        let frozen = detached(&params);
        let y = per_texel_mlp(f.as_tensor(), &om, &constant_views(&frozen), ACT)?;
        let store = (y * &r)?.sum_all()?.backward()?;
        let df = store.get(f.as_tensor()).expect("an input gradient");
        assert!(max_abs_diff(df, full.get(f.as_tensor()).expect("df"))? < 1e-12);
        assert!(
            params
                .iter()
                .all(|(w, _, _, _)| store.get(w.as_tensor()).is_none())
        );
        Ok(())
    }

    /// The parameter gradients sum over blocks of texels on several threads: they must come out
    /// the same, to the bit, every time (a training run must repeat, and a resumed one continue
    /// exactly), whichever thread takes which block.
    #[test]
    fn parameter_gradients_do_not_depend_on_thread_timing() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [7, 16, 16, 3];
        let params = layers(&dims, 1, DType::F32)?;
        // 4·48·48 = 9216 texels: 36 blocks over 4 threads.
        let f = pseudo_random((4, 4, 48, 48), 2, DType::F32, &dev)?;
        let om = pseudo_random((4, 3, 48, 48), 3, DType::F32, &dev)?;
        let r = pseudo_random((4, 3, 48, 48), 4, DType::F32, &dev)?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .expect("a pool");
        let grads = || -> Result<Vec<Vec<f32>>> {
            let y = per_texel_mlp(&f, &om, &views(&params), ACT)?;
            let store = (y * &r)?.sum_all()?.backward()?;
            params
                .iter()
                .flat_map(|(w, b, _, _)| [w, b])
                .map(|v| {
                    store
                        .get(v.as_tensor())
                        .expect("a gradient")
                        .flatten_all()?
                        .to_vec1()
                })
                .collect()
        };
        let first = pool.install(grads)?;
        for _ in 0..20 {
            assert!(
                pool.install(grads)? == first,
                "gradients differ between runs"
            );
        }
        Ok(())
    }

    #[test]
    fn fused_mlp_matches_the_candle_composition_and_its_gradients() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [7, 16, 16, 16, 3];
        // Odd texel counts, one of them above a block (17·19 = 323 = 256 + 67), batch 1 and 2.
        for (case, (b, h, w)) in [(2, 17, 19), (1, 3, 5), (3, 1, 1)].into_iter().enumerate() {
            let seed = 100 * case as u64;
            let params = layers(&dims, seed, DType::F64)?;
            let f = Var::from_tensor(&pseudo_random((b, 4, h, w), seed + 50, DType::F64, &dev)?)?;
            let om = Var::from_tensor(&pseudo_random((b, 3, h, w), seed + 51, DType::F64, &dev)?)?;
            let r = pseudo_random((b, 3, h, w), seed + 52, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = per_texel_mlp(f.as_tensor(), om.as_tensor(), &views(&params), ACT)?;
                value_and_grads(&y, &r, &[&f, &om], &params)
            };
            let fused = run()?;
            let reference = crate::reference::with_reference_ops(run)?;
            // f64 sums of ≤ 323·16 O(1) terms in another order: far below 1e-9 (relative to
            // the largest value); pseudo-random inputs put no pre-activation exactly at 0.
            compare(&fused, &reference, 1e-9, &format!("nchw case {case}"))?;
            assert_eq!(fused.len(), 3 + 2 * (dims.len() - 1));
        }
        Ok(())
    }

    #[test]
    fn fused_mlp_on_rows_matches_the_candle_composition() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [5, 8, 8, 2];
        for (case, n) in [1usize, 255, 513].into_iter().enumerate() {
            let seed = 7 + 10 * case as u64;
            let params = layers(&dims, seed, DType::F64)?;
            let x = Var::from_tensor(&pseudo_random((n, 5), seed + 8, DType::F64, &dev)?)?;
            let r = pseudo_random((n, 2), seed + 9, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = per_texel_mlp_rows(x.as_tensor(), &views(&params), ACT)?;
                value_and_grads(&y, &r, &[&x], &params)
            };
            let fused = run()?;
            let reference = crate::reference::with_reference_ops(run)?;
            compare(&fused, &reference, 1e-9, &format!("rows case {case}"))?;
        }
        Ok(())
    }

    #[test]
    fn fused_mlp_f32_and_untracked_inputs_match() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [6, 32, 32, 3];
        let params = layers(&dims, 3, DType::F32)?;
        let f = pseudo_random((2, 3, 20, 20), 4, DType::F32, &dev)?;
        let om = pseudo_random((2, 3, 20, 20), 5, DType::F32, &dev)?;
        // Plain tensors only: the forward keeps no activations, and still equals the reference.
        let plain = detached(&params);
        let l = constant_views(&plain);
        let fused = per_texel_mlp(&f, &om, &l, ACT)?;
        let reference = per_texel_mlp_reference(&f, &om, &l, ACT)?;
        // f32 sums of ≤ 38 O(1) terms per layer over 3 layers: ≈ 1e-6 relative.
        compare(&[fused], &[reference], 1e-5, "f32 untracked")?;
        Ok(())
    }

    #[test]
    fn fused_mlp_rejects_bad_arguments() -> Result<()> {
        let dev = Device::Cpu;
        let params = layers(&[5, 4, 4, 3], 1, DType::F32)?;
        let l = views(&params);
        let f = Tensor::zeros((1, 2, 4, 4), DType::F32, &dev)?;
        let om = Tensor::zeros((1, 3, 4, 4), DType::F32, &dev)?;
        assert!(per_texel_mlp(&f, &om, &l, ACT).is_ok());
        let om_bad = Tensor::zeros((1, 3, 4, 5), DType::F32, &dev)?;
        assert!(
            per_texel_mlp(&f, &om_bad, &l, ACT).is_err(),
            "ω of another size"
        );
        let f_bad = Tensor::zeros((1, 3, 4, 4), DType::F32, &dev)?;
        assert!(
            per_texel_mlp(&f_bad, &om, &l, ACT).is_err(),
            "wrong input width"
        );
        assert!(per_texel_mlp(&f, &om, &l[..1], ACT).is_err(), "one layer");
        let bad = MlpActivation {
            slope: 1.5,
            gain: 1.0,
        };
        assert!(per_texel_mlp(&f, &om, &l, bad).is_err(), "slope");
        let bad = MlpActivation {
            slope: 0.2,
            gain: 0.0,
        };
        assert!(per_texel_mlp(&f, &om, &l, bad).is_err(), "gain");
        let uneven = layers(&[5, 4, 6, 3], 2, DType::F32)?;
        assert!(
            per_texel_mlp(&f, &om, &views(&uneven), ACT).is_err(),
            "hidden widths"
        );
        Ok(())
    }
}
