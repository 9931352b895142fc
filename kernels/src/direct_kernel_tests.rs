//! Tests of every direct convolution kernel ([`crate::direct_conv`],
//! [`crate::strided_input_grad`], [`crate::direct_weight_grad`]) of every vector family this
//! CPU runs (forced, so that an AVX-512 machine tests the AVX2 kernels too) against the f64
//! reference on the same inputs, and of the gates that decide which geometries they take.

use candle_core::{DType, Device, Result, Tensor};

use crate::conv::{apply_input_grad, apply_weight_grad, conv2d_reference};
use crate::conv_geometry::{Conv2dSpec, Geometry, PaddingMode};
use crate::simd::{SimdFamily, vector_families};
use crate::testing::max_abs_diff;
use crate::{direct_conv, direct_weight_grad, strided_input_grad};
use photomat_core::rng::pseudo_random;

/// (B, C_in, H, W, C_out, k, stride, padding).
type Case = (usize, usize, usize, usize, usize, usize, usize, usize);

/// The paths and edges of the kernels:
/// - widths of whole vectors (16, 32) with one and several tiles, and partial tiles (5 rows
///   × 2 vectors = 10 vectors);
/// - partial output-channel blocks (C_out 7 and 13 against blocks of 6);
/// - 1×1, 3×3, 4×4 and 5×5 kernels;
/// - unpadded 3×3 convolutions whose forward (W 18 → 16) or input gradient (W 16) alone is
///   direct;
/// - stride 2 on odd and even widths (the discriminator's 33 → 16 after its blur, the
///   estimator's padded 4×4, a padded 3×3) and stride 3, whose input gradients run phase
///   by phase (circular ones only where H = s·H_out);
/// - 70 and 40 output channels (weight-gradient tiles of 4 + 1 and 3 vectors);
/// - rows ending in a partial, masked vector (20, 33 and strided 33 output columns);
/// - 24 output channels at 24 × 32 texels (2-vector weight-gradient tiles over three L1
///   bands, split between tasks).
///
/// Pointwise convolutions stay on gemm, which reads their input in place.
const CASES: &[Case] = &[
    (2, 5, 16, 16, 7, 3, 1, 1),
    (1, 3, 5, 32, 13, 3, 1, 1),
    (2, 4, 6, 16, 3, 1, 1, 0),
    (1, 3, 8, 18, 5, 3, 1, 0),
    (1, 3, 8, 16, 5, 3, 1, 0),
    (1, 2, 7, 16, 3, 5, 1, 2),
    (3, 2, 4, 16, 6, 3, 1, 1),
    (2, 3, 9, 33, 5, 3, 2, 0),
    (1, 4, 6, 32, 7, 4, 2, 1),
    (1, 7, 4, 16, 70, 3, 1, 1),
    (2, 2, 5, 16, 40, 3, 1, 1),
    (1, 3, 5, 20, 7, 3, 1, 1),
    (2, 2, 4, 33, 5, 3, 1, 1),
    (1, 3, 9, 67, 6, 3, 2, 0),
    (1, 2, 24, 32, 24, 3, 1, 1),
    (2, 3, 8, 32, 5, 3, 2, 1),
    (1, 2, 9, 48, 4, 3, 3, 0),
];

#[test]
fn direct_kernels_of_every_family_match_the_f64_reference() -> Result<()> {
    for family in vector_families() {
        check_family(family)?;
    }
    Ok(())
}

/// Every case through `family`'s direct kernels (forced: the family the test names, not the
/// process's), each kernel at three thread counts, against the f64 reference.
fn check_family(family: SimdFamily) -> Result<()> {
    let dev = Device::Cpu;
    let mut direct = (0, 0, 0);
    for (seed, &(b, ci, h, w, co, k, stride, p)) in CASES.iter().enumerate() {
        for mode in [PaddingMode::Zeros, PaddingMode::Circular] {
            let spec = Conv2dSpec {
                stride,
                padding: p,
                mode,
            };
            let seed = 5 * seed as u64;
            let x = pseudo_random((b, ci, h, w), seed, DType::F64, &dev)?;
            let wt = pseudo_random((co, ci, k, k), seed + 1, DType::F64, &dev)?;
            let g = Geometry::new(x.dims4()?, wt.dims4()?, spec)?;
            let dy = pseudo_random(g.y_shape(), seed + 2, DType::F64, &dev)?;
            let y_ref = conv2d_reference(&x, &wt, spec)?;
            let dx_ref = apply_input_grad(g, &dy, &wt)?;
            let dw_ref = apply_weight_grad(g, &x, &dy)?;
            let f32s = |t: &Tensor| t.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>();
            let (xv, wv, dyv) = (f32s(&x)?, f32s(&wt)?, f32s(&dy)?);
            let case = format!(
                "{family:?} {mode:?} x{:?} co {co} k{k} s{stride} p{p}",
                (b, ci, h, w)
            );
            // f32 sums of ≤ 70·9 = 630 products of values in [−1, 1]: rounding ≲ 630·6e-8;
            // a wrong tap or channel is off by O(0.1).
            // Weight gradients sum over B·H_out·W_out ≤ 768 texels: rounding ≲ 5e-5.
            let tol = 1e-4;
            for threads in [1, 2, 3] {
                let on = (threads, family);
                // Runs one kernel into a NaN-filled buffer (an unwritten output stays NaN
                // and fails the comparison) and compares it with the f64 reference.
                let check = |what: &str, reference: &Tensor, run: &dyn Fn(&mut [f32])| {
                    let mut out = vec![f32::NAN; reference.elem_count()];
                    run(&mut out);
                    let out =
                        Tensor::from_vec(out, reference.shape(), &dev)?.to_dtype(DType::F64)?;
                    let err = max_abs_diff(&out, reference)?;
                    assert!(err < tol, "{what} {case} threads {threads}: {err}");
                    Result::Ok(())
                };
                if direct_conv::supports_forward(&g, family) {
                    direct.0 += 1;
                    check("forward", &y_ref, &|y| {
                        direct_conv::forward(&g, &xv, &wv, y, on)
                    })?;
                }
                if direct_conv::supports_input_grad(&g, family) {
                    direct.1 += 1;
                    let run = |dx: &mut [f32]| direct_conv::input_grad(&g, &dyv, &wv, dx, on);
                    check("input gradient", &dx_ref, &run)?;
                }
                if strided_input_grad::supports(&g, family) {
                    direct.1 += 1;
                    let run =
                        |dx: &mut [f32]| strided_input_grad::input_grad(&g, &dyv, &wv, dx, on);
                    check("strided input gradient", &dx_ref, &run)?;
                }
                if direct_weight_grad::supports(&g, family) {
                    direct.2 += 1;
                    let run =
                        |dw: &mut [f32]| direct_weight_grad::weight_grad(&g, &xv, &dyv, dw, on);
                    check("weight gradient", &dw_ref, &run)?;
                }
            }
        }
    }
    // Of the 34 (case, mode) pairs, 30 forwards are direct on AVX-512 (not the pointwise one,
    // left to gemm, nor the unpadded one at W 16, 14 output columns: narrower than its
    // 16-lane vector; on AVX2, whose vectors hold 8, that one too: 32), 28 input gradients
    // (nor the unpadded circular 3×3s, whose adjoint needs a padding of 2 that wraps another
    // way, nor the circular stride-2 ones of 9 rows, not 2·H_out) and 32 weight gradients
    // (all but the pointwise one), at 3 thread counts: the gates did not silently turn a
    // kernel off.
    let forwards = if family == SimdFamily::Avx2 { 32 } else { 30 };
    assert_eq!(direct, (3 * forwards, 3 * 28, 3 * 32), "{family:?}");
    Ok(())
}

#[test]
fn direct_kernels_decline_what_they_do_not_compute() -> Result<()> {
    let g = |x, w, spec| Geometry::new(x, w, spec);
    for family in vector_families() {
        let lanes = family.lanes();
        // Strided input gradients with a phase row of half a vector, a phase without a tap
        // (1×1 stride 2), a circular wrap of another period (H 9 ≠ 2·H_out); a row narrower
        // than a vector; circular padding that is not "same".
        let strided = g((1, 2, 16, lanes), (2, 2, 4, 4), Conv2dSpec::zeros(2, 1))?;
        assert!(!strided_input_grad::supports(&strided, family));
        let tapless = g((1, 2, 16, 64), (2, 2, 1, 1), Conv2dSpec::zeros(2, 0))?;
        assert!(!strided_input_grad::supports(&tapless, family));
        let odd_wrap = g((1, 2, 9, 64), (2, 2, 3, 3), Conv2dSpec::circular(2, 0))?;
        assert!(!strided_input_grad::supports(&odd_wrap, family));
        let narrow = g(
            (1, 2, 8, lanes - 2),
            (2, 2, 3, 3),
            Conv2dSpec::circular(1, 1),
        )?;
        assert!(!direct_conv::supports_forward(&narrow, family));
        assert!(!direct_conv::supports_input_grad(&narrow, family));
        let wrapped = g((1, 2, 16, 16), (2, 2, 3, 3), Conv2dSpec::circular(1, 2))?;
        assert!(direct_conv::input_grad_geometry(&wrapped, family).is_none());
        // Pointwise: gemm reads x in place, nothing to gain.
        let pointwise = g((1, 2, 16, 16), (2, 2, 1, 1), Conv2dSpec::zeros(1, 0))?;
        assert!(
            !direct_conv::supports_forward(&pointwise, family)
                && !direct_conv::supports_input_grad(&pointwise, family)
                && !direct_weight_grad::supports(&pointwise, family)
        );
    }
    // The scalar family runs none of them.
    let common = g((2, 4, 32, 32), (4, 4, 3, 3), Conv2dSpec::zeros(1, 1))?;
    let strided = g((2, 4, 32, 32), (4, 4, 4, 4), Conv2dSpec::zeros(2, 1))?;
    let scalar = SimdFamily::Scalar;
    assert!(
        !direct_conv::supports_forward(&common, scalar)
            && !direct_conv::supports_input_grad(&common, scalar)
            && !strided_input_grad::supports(&strided, scalar)
            && !direct_weight_grad::supports(&common, scalar)
    );
    Ok(())
}
