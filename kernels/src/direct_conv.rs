//! Direct convolution of f32 images on the SIMD families (AVX-512, AVX2 + FMA;
//! [`crate::simd`]): the forward and stride-1 input-gradient kernels of [`crate::conv`] for
//! the layers that dominate the generator's, discriminator's and estimator's steps (3×3 and
//! 4×4, strides 1 and 2).
//!
//! im2col + `gemm` copies every input texel `kh·kw` times into `col(x)` and has `gemm` pack it
//! again; here the input is copied once, into a padded plane per channel
//! ([`crate::padded_input`]), and the register tiles of [`crate::conv_tiles`] read it in
//! place, the scheme of direct convolutions on SIMD CPUs (Georganas et al., "Anatomy of
//! high-performance deep learning convolutions on SIMD architectures", SC 2018; oneDNN's
//! direct kernels, which PyTorch CPU calls).
//!
//! **Forward.** With the activations kept in NCHW order, one vector holds consecutive output
//! texels of one channel (16 on AVX-512, 8 on AVX2); a tile of output channels × vectors is
//! summed over every input channel and kernel tap. The weights are repacked once per call so
//! that a tile's weights of one (c, ky, kx) are adjacent. Output rows must hold at least one
//! vector (`W_out ≥ 16` or `≥ 8`); a row's last, partial vector reads and writes only its
//! lanes.
//!
//! **Input gradient.** That of a stride-1 convolution is itself such a convolution, of `dy`
//! with the kernel flipped in both axes and its two channel axes swapped, padded by
//! `k − 1 − p` (for circular padding only when `2p = k − 1`, where output and input planes
//! have the same size and the wrap-around has the same period). Strided ones are `s²` such
//! convolutions with sub-kernels, one per phase of the input grid
//! ([`crate::strided_input_grad`]); weight gradients are [`crate::direct_weight_grad`]'s.
//!
//! Only f32 on a vector family the CPU has takes this path, and not pointwise convolutions,
//! which `gemm` already reads in place (`supports_forward`, `supports_input_grad`);
//! everything else stays on im2col + `gemm`, which the equivalence tests compare it with.
//! Measurements: `docs/benchmarks/conv-kernels.md`, "A direct convolution kernel";
//! `docs/benchmarks/cpu-kernels.md`.

use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::conv_geometry::{Conv2dSpec, Geometry, PaddingMode};
use crate::conv_tiles::{MIN_BAND_ROWS, PAD_BAND_BYTES, TileGrid, pack_weights, run_tiles};
use crate::padded_input::{Padded, pad_rows};
use crate::simd::{Simd, SimdFamily, on_family};

/// Whether [`forward`] computes this convolution: any but a pointwise one with output rows of
/// at least one vector (a row's last, partial vector is masked).
pub(crate) fn supports_forward(g: &Geometry, family: SimdFamily) -> bool {
    family != SimdFamily::Scalar && !g.is_pointwise() && g.wo >= family.lanes()
}

/// The forward convolution whose value is the input gradient of `g`, with its
/// flipped-and-transposed kernel's geometry; `None` when that is not a stride-1 convolution
/// [`forward`] handles (module docs).
pub(crate) fn input_grad_geometry(g: &Geometry, family: SimdFamily) -> Option<Geometry> {
    if family == SimdFamily::Scalar
        || g.is_pointwise()
        || g.stride != 1
        || g.pad >= g.kh
        || g.pad >= g.kw
        || g.w < family.lanes()
    {
        return None;
    }
    if g.circular && (2 * g.pad + 1 != g.kh || 2 * g.pad + 1 != g.kw) {
        return None;
    }
    // Padding k − 1 − p on both axes: one value, so the kernel must be square.
    if g.kh != g.kw {
        return None;
    }
    let mode = if g.circular {
        PaddingMode::Circular
    } else {
        PaddingMode::Zeros
    };
    let spec = Conv2dSpec {
        stride: 1,
        padding: g.kh - 1 - g.pad,
        mode,
    };
    let adjoint = Geometry::new((g.b, g.co, g.ho, g.wo), (g.ci, g.co, g.kh, g.kw), spec).ok()?;
    (adjoint.ho == g.h && adjoint.wo == g.w).then_some(adjoint)
}

/// Whether [`input_grad`] computes this (stride-1) convolution's input gradient, as the
/// adjoint forward.
pub(crate) fn supports_input_grad(g: &Geometry, family: SimdFamily) -> bool {
    input_grad_geometry(g, family).is_some()
}

/// Forward convolution: writes every element of `y` (B·C_out·H_out·W_out) from `x`
/// (B·C_in·H·W) and `w` (C_out·C_in·kh·kw) on `family`'s kernels. Requires
/// [`supports_forward`] (`family` is then one the CPU has: [`SimdFamily::active`]).
pub(crate) fn forward(
    g: &Geometry,
    x: &[f32],
    w: &[f32],
    y: &mut [f32],
    (threads, family): (usize, SimdFamily),
) {
    assert!(
        supports_forward(g, family),
        "direct conv: unsupported geometry {g:?}"
    );
    on_family!(family, S => run::<S>(g, x, &pack_forward::<S>(g, w), y, threads));
}

/// The forward's weights (C_out·C_in·kh·kw) in tile order ([`pack_weights`]).
fn pack_forward<S: Simd>(g: &Geometry, w: &[f32]) -> Vec<f32> {
    pack_weights::<S>(g.co, g.k(), |o, dst| {
        dst.copy_from_slice(&w[o * g.k()..][..g.k()])
    })
}

/// Input gradient: writes every element of `dx` (B·C_in·H·W) from `dy` (B·C_out·H_out·W_out)
/// and `w` (C_out·C_in·kh·kw), as the forward convolution of `dy` with the flipped,
/// transposed kernel, on `family`'s kernels. Requires [`supports_input_grad`].
pub(crate) fn input_grad(
    g: &Geometry,
    dy: &[f32],
    w: &[f32],
    dx: &mut [f32],
    (threads, family): (usize, SimdFamily),
) {
    let adjoint = input_grad_geometry(g, family).expect("direct conv: unsupported input gradient");
    on_family!(family, S => run::<S>(&adjoint, dy, &pack_adjoint::<S>(g, w), dx, threads));
}

/// The adjoint kernel of `g`'s weights in tile order: [c][o][ky'][kx'] =
/// W[o][c][kh−1−ky'][kw−1−kx'], each (o, c) kernel reversed.
fn pack_adjoint<S: Simd>(g: &Geometry, w: &[f32]) -> Vec<f32> {
    let taps = g.kh * g.kw;
    pack_weights::<S>(g.ci, g.co * taps, |c, dst| {
        for (o, flipped) in dst.chunks_exact_mut(taps).enumerate() {
            let kernel = &w[(o * g.ci + c) * taps..][..taps];
            for (d, &v) in flipped.iter_mut().zip(kernel.iter().rev()) {
                *d = v;
            }
        }
    })
}

/// Runs the forward tiles of every image, band of output rows by band of output rows: the
/// (image, band) pairs are the parallel tasks, each padding the input rows its band reads
/// into its own buffer. Bands hold [`PAD_BAND_BYTES`] of padded input, and are cut finer when
/// there are fewer images than threads, so that every thread has work.
fn run<S: Simd>(g: &Geometry, x: &[f32], packed: &[f32], y: &mut [f32], threads: usize) {
    // Padded input bytes per output row: `s` padded rows of every channel.
    let row_bytes = 4 * g.ci * g.stride * Padded::new(g, 1).row;
    let mut band = (PAD_BAND_BYTES / row_bytes.max(1)).max(MIN_BAND_ROWS);
    if threads > 1 && g.b < threads {
        band = band.min(g.ho.div_ceil(2 * threads));
    }
    run_in_bands::<S>(g, x, packed, y, band.clamp(1, g.ho));
}

/// [`run`] with bands of `band` output rows (the last one shorter when they do not divide
/// `H_out`).
fn run_in_bands<S: Simd>(g: &Geometry, x: &[f32], packed: &[f32], y: &mut [f32], band: usize) {
    let (x_len, y_len) = (g.ci * g.h * g.w, g.co * g.ho * g.wo);
    // The tasks write through raw pointers: the output must be exactly the batch's.
    assert_eq!(
        y.len(),
        g.b * y_len,
        "direct conv: output of the wrong size"
    );
    assert_eq!(x.len(), g.b * x_len, "direct conv: input of the wrong size");
    let layout = Padded::new(g, band);
    let bands = g.ho.div_ceil(band);
    let taps: Vec<usize> = (0..g.kh)
        .flat_map(|ky| (0..g.kw).map(move |kx| layout.tap(g, ky, kx)))
        .collect();
    let y_addr = y.as_mut_ptr() as usize;
    (0..g.b * bands).into_par_iter().for_each_init(
        // SAFETY: `pad_rows` writes every row of the band before the tiles read it.
        || unsafe { output_buffer::<f32>(g.ci * layout.plane) },
        |xp, job| {
            let (i, r0) = (job / bands, (job % bands) * band);
            let r1 = (r0 + band).min(g.ho);
            // The last band may read fewer rows: pad only those.
            let read = (r1 - r0 - 1) * g.stride + g.kh;
            pad_rows::<S>(
                g,
                layout,
                &x[i * x_len..(i + 1) * x_len],
                r0 * g.stride..r0 * g.stride + read,
                xp,
            );
            let yi = (y_addr as *mut f32).wrapping_add(i * y_len) as usize;
            let grid = TileGrid {
                ci: g.ci,
                plane_in: layout.plane,
                taps: &taps,
                in_base: 0,
                in_row: layout.origin(g, 1, 0),
                co: g.co,
                plane_out: g.ho * g.wo,
                rows: r1 - r0,
                wo: g.wo,
                out_base: r0 * g.wo,
            };
            // SAFETY: the CPU has S's features (`forward`'s contract); `y` outlives the tasks;
            // task (i, band) writes only output rows r0..r1 of image i, which no other task
            // writes; `xp` holds the padded rows they read.
            unsafe { run_tiles::<S>(&grid, xp, packed, yi) };
        },
    );
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Result, Tensor};

    use super::*;
    use crate::conv::conv2d_reference;
    use crate::simd::vector_families;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    #[test]
    fn direct_forward_in_bands_of_rows_equals_the_whole_image() -> Result<()> {
        // 16 output rows in bands of 3 (the last of 1), stride 1 and 2: each band pads its own
        // halo rows, zero or wrapped, and writes only its rows.
        let dev = Device::Cpu;
        for family in vector_families() {
            for (stride, pad, w) in [(1, 1, 16), (2, 1, 32)] {
                for mode in [PaddingMode::Zeros, PaddingMode::Circular] {
                    let spec = Conv2dSpec {
                        stride,
                        padding: pad,
                        mode,
                    };
                    let x = pseudo_random((2, 3, 16 * stride, w), 11, DType::F32, &dev)?;
                    let wt = pseudo_random((5, 3, 3, 3), 12, DType::F32, &dev)?;
                    let g = Geometry::new(x.dims4()?, wt.dims4()?, spec)?;
                    assert_eq!(g.ho, 16);
                    let (xv, wv) = (
                        x.flatten_all()?.to_vec1::<f32>()?,
                        wt.flatten_all()?.to_vec1::<f32>()?,
                    );
                    let run = |band: usize| {
                        let mut y = vec![f32::NAN; g.y_shape().elem_count()];
                        on_family!(family, S => {
                            run_in_bands::<S>(&g, &xv, &pack_forward::<S>(&g, &wv), &mut y, band)
                        });
                        y
                    };
                    let (whole, banded) = (run(16), run(3));
                    // Same sums in the same order: equal to the bit.
                    assert_eq!(whole, banded, "{family:?} {spec:?}");
                    let reference = conv2d_reference(&x, &wt, spec)?;
                    let banded = Tensor::from_vec(banded, g.y_shape(), &dev)?;
                    assert!(
                        max_abs_diff(&banded, &reference)? < 1e-4,
                        "{family:?} {spec:?}"
                    );
                }
            }
        }
        Ok(())
    }
}
