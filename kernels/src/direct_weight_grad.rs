//! The direct weight gradient of f32 convolutions on AVX-512 ([`crate::conv`]'s choice for
//! weight gradients over at least [`WG_MIN_TEXELS`] output texels): a reduction over texels
//! whose 16 lanes run over output channels, `dy` copied channels-last one L1-sized band of
//! rows at a time, and a tile of `WG_VECTORS` × 16 output channels × `WG_CHANNELS` input
//! channels of one tap adding `dy` rows times broadcast input texels, its sums kept
//! channels-last between bands and transposed once (the scheme of Georganas et al., SC 2018,
//! for the weight-update pass). It reads the padded input of [`crate::padded_input`].

use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::avx512::{LANES, has_avx512};
use crate::conv_geometry::Geometry;
use crate::padded_input::{Padded, pad_rows};

/// Input channels per weight-gradient tile; with [`WG_VECTORS`] vectors of 16 output
/// channels, `6 × 4` = 24 accumulators.
const WG_CHANNELS: usize = 6;

/// Vectors of 16 output channels per weight-gradient tile.
const WG_VECTORS: usize = 4;

/// Bytes of `dy`'s channels-last copy per band of output rows: two thirds of a 48 KiB L1, so
/// that the band stays in L1 while every (tap, input channel) tile sweeps it.
const WG_BAND_BYTES: usize = 32 << 10;

/// Fewest output texels (over the batch) for the direct weight gradient: below, its fixed
/// costs per weight (the channels-last sums, zeroed, then transposed back) outweigh the
/// `2·texels` FLOP each weight takes, and im2col + `gemm` writes the weights in place (the
/// estimator's 4² and 8² layers; `docs/benchmarks.md`, "A direct convolution kernel").
const WG_MIN_TEXELS: usize = 1024;

/// Whether [`weight_grad`] computes this convolution's weight gradient: every f32 geometry
/// but a pointwise one, on AVX-512.
pub(crate) fn supports(g: &Geometry) -> bool {
    !g.is_pointwise() && has_avx512()
}

/// Whether [`weight_grad`] is the faster way: [`supports_weight_grad`] with at least
/// [`WG_MIN_TEXELS`] output texels.
pub(crate) fn prefers(g: &Geometry) -> bool {
    supports(g) && g.b * g.ho * g.wo >= WG_MIN_TEXELS
}

/// Weight gradient: writes every element of `dw` (C_out·C_in·kh·kw) from `x` (B·C_in·H·W)
/// and `dy` (B·C_out·H_out·W_out),
///
/// ```text
/// dW[o, c, ky, kx] = Σ_b Σ_(oy, ox) dy[b, o, oy, ox] · xpad[b, c, s·oy + ky, s·ox + kx]
/// ```
///
/// with the 16 lanes of a vector over output channels: `dy` is copied channels-last one
/// L1-sized band of output rows at a time (row `(oy, ox)` of C_out floats, padded to whole
/// vectors), and a tile of [`WG_VECTORS`] × 16 output channels × [`WG_CHANNELS`] input
/// channels of one tap adds `dy` row × broadcast input texel over the band, its sums kept in
/// a channels-last gradient buffer between bands. Each task pads whole input images (weight
/// gradients run in training, on images of at most 256² here). Requires
/// [`supports_weight_grad`]. Tasks (ranges of images, or of one image's bands when there are
/// fewer images than threads) sum into their own buffers, added in task order, so the result
/// does not depend on thread timing.
pub(crate) fn weight_grad(g: &Geometry, x: &[f32], dy: &[f32], dw: &mut [f32], threads: usize) {
    assert!(supports(g), "direct conv: unsupported geometry");
    assert_eq!(
        dw.len(),
        g.co * g.k(),
        "direct conv: weight gradient of the wrong size"
    );
    let (x_len, y_len) = (g.ci * g.h * g.w, g.co * g.ho * g.wo);
    let co_pad = g.co.next_multiple_of(LANES);
    let band = (WG_BAND_BYTES / (4 * g.wo * co_pad)).clamp(1, g.ho);
    let bands = g.ho.div_ceil(band);
    // The (image, band) units in order, cut into at most `threads` contiguous tasks: whole
    // images each when there are enough, else runs of one image's bands.
    let units = g.b * bands;
    let per = units.div_ceil(threads.max(1)).max(1);
    let layout = Padded::new(g, g.ho);
    let taps = g.kh * g.kw;
    let ci_pad = g.ci.next_multiple_of(WG_CHANNELS);
    let partials: Vec<Vec<f32>> = (0..units)
        .step_by(per)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|first| {
            // Channels-last sums: [c][tap][o], C_in and C_out padded to whole tiles.
            let mut sums = vec![0.0; ci_pad * taps * co_pad];
            // SAFETY: `pad_rows` writes all of it before the first band reads it.
            let mut xp = unsafe { output_buffer::<f32>(g.ci * layout.plane) };
            let mut dy_rows = vec![0.0; band * g.wo * co_pad];
            let mut padded = None;
            for unit in first..(first + per).min(units) {
                let (i, j) = (unit / bands, unit % bands);
                if padded != Some(i) {
                    let xi = &x[i * x_len..(i + 1) * x_len];
                    pad_rows(g, layout, xi, 0..layout.rows, &mut xp);
                    padded = Some(i);
                }
                let dyi = &dy[i * y_len..(i + 1) * y_len];
                let rows = j * band..((j + 1) * band).min(g.ho);
                channels_last(g, dyi, co_pad, rows.clone(), &mut dy_rows);
                weight_grad_band(g, layout, &xp, &dy_rows, co_pad, rows, &mut sums);
            }
            sums
        })
        .collect();
    // Back to dW's [o][c][tap] order, 16 (c, tap) rows of the sums at a time: their reads run
    // along o, the writes along (c, tap), both within a few cache lines.
    let row = g.ci * taps;
    for ct0 in (0..row).step_by(LANES) {
        let cts = ct0..(ct0 + LANES).min(row);
        for (o, dw_o) in dw.chunks_exact_mut(row).enumerate() {
            for ct in cts.clone() {
                dw_o[ct] = partials.iter().map(|s| s[ct * co_pad + o]).sum();
            }
        }
    }
}

/// Rows `rows` of one image's `dy` (C_out·H_out·W_out) channels-last into `out`: texel
/// `(oy, ox)` at `((oy − rows.start)·W_out + ox)·co_pad`, its C_out values then zeros up to
/// `co_pad`. One band at a time, so that the scattered writes stay in L1.
fn channels_last(
    g: &Geometry,
    dy: &[f32],
    co_pad: usize,
    rows: std::ops::Range<usize>,
    out: &mut [f32],
) {
    let plane = g.ho * g.wo;
    let texels = rows.start * g.wo..rows.end * g.wo;
    for p in 0..texels.len() {
        out[p * co_pad + g.co..(p + 1) * co_pad].fill(0.0);
    }
    for o in 0..g.co {
        for (p, v) in dy[o * plane..][texels.clone()].iter().enumerate() {
            out[p * co_pad + o] = *v;
        }
    }
}

/// Adds the weight gradient of output rows `rows` into `sums` ([c][tap][o], module docs of
/// [`weight_grad`]) from the padded input `xp` and the band's channels-last `dy_rows`.
fn weight_grad_band(
    g: &Geometry,
    layout: Padded,
    xp: &[f32],
    dy_rows: &[f32],
    co_pad: usize,
    rows: std::ops::Range<usize>,
    sums: &mut [f32],
) {
    let taps = g.kh * g.kw;
    let vectors = co_pad / LANES;
    for t in 0..taps {
        let shift = layout.tap(g, t / g.kw, t % g.kw);
        for c0 in (0..g.ci).step_by(WG_CHANNELS) {
            // Channels past C_in repeat the last one; their sums land in the padding of `sums`.
            let planes: [usize; WG_CHANNELS] =
                std::array::from_fn(|b| (c0 + b).min(g.ci - 1) * layout.plane + shift);
            let sum_at = (c0 * taps + t) * co_pad;
            for v0 in (0..vectors).step_by(WG_VECTORS) {
                let n = WG_VECTORS.min(vectors - v0);
                let at = sum_at + v0 * LANES;
                // SAFETY: AVX-512F was detected (`supports_weight_grad`); `dy_rows` holds the
                // band's rows of `co_pad` floats, `xp` the padded texels every tap reads, and
                // `sums` the tile's 6 rows of `taps · co_pad` apart.
                unsafe {
                    match n {
                        4 => weight_tile::<4>(
                            g, layout, xp, planes, dy_rows, co_pad, v0, &rows, sums, at, taps,
                        ),
                        3 => weight_tile::<3>(
                            g, layout, xp, planes, dy_rows, co_pad, v0, &rows, sums, at, taps,
                        ),
                        2 => weight_tile::<2>(
                            g, layout, xp, planes, dy_rows, co_pad, v0, &rows, sums, at, taps,
                        ),
                        _ => weight_tile::<1>(
                            g, layout, xp, planes, dy_rows, co_pad, v0, &rows, sums, at, taps,
                        ),
                    }
                }
            }
        }
    }
}

/// One weight-gradient tile: `NV` vectors of output channels from `v0` × [`WG_CHANNELS`]
/// input channels (`planes`: each one's padded plane offset plus the tap's shift), summed over
/// the band's texels onto `sums[at + b·taps·co_pad + 16j ..]`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn weight_tile<const NV: usize>(
    g: &Geometry,
    layout: Padded,
    xp: &[f32],
    planes: [usize; WG_CHANNELS],
    dy_rows: &[f32],
    co_pad: usize,
    v0: usize,
    rows: &std::ops::Range<usize>,
    sums: &mut [f32],
    at: usize,
    taps: usize,
) {
    use std::arch::x86_64::*;
    let stride = taps * co_pad;
    assert!(at + (WG_CHANNELS - 1) * stride + NV * LANES <= sums.len());
    let s = sums.as_mut_ptr();
    let mut acc = [[_mm512_setzero_ps(); NV]; WG_CHANNELS];
    for (b, row) in acc.iter_mut().enumerate() {
        for (j, a) in row.iter_mut().enumerate() {
            *a = unsafe { _mm512_loadu_ps(s.add(at + b * stride + j * LANES)) };
        }
    }
    let (x0, d0) = (xp.as_ptr(), dy_rows.as_ptr());
    for oy in rows.clone() {
        let (x_row, d_row) = (layout.origin(g, oy, 0), (oy - rows.start) * g.wo);
        for ox in 0..g.wo {
            let d = unsafe { d0.add((d_row + ox) * co_pad + v0 * LANES) };
            let dv: [__m512; NV] =
                std::array::from_fn(|j| unsafe { _mm512_loadu_ps(d.add(j * LANES)) });
            for (b, row) in acc.iter_mut().enumerate() {
                let xv = _mm512_set1_ps(unsafe { *x0.add(planes[b] + x_row + ox) });
                for (a, dvj) in row.iter_mut().zip(&dv) {
                    *a = _mm512_fmadd_ps(*dvj, xv, *a);
                }
            }
        }
    }
    for (b, row) in acc.iter().enumerate() {
        for (j, a) in row.iter().enumerate() {
            unsafe { _mm512_storeu_ps(s.add(at + b * stride + j * LANES), *a) };
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[allow(clippy::too_many_arguments)]
unsafe fn weight_tile<const NV: usize>(
    _: &Geometry,
    _: Padded,
    _: &[f32],
    _: [usize; WG_CHANNELS],
    _: &[f32],
    _: usize,
    _: usize,
    _: &std::ops::Range<usize>,
    _: &mut [f32],
    _: usize,
    _: usize,
) {
    unreachable!("AVX-512 only: supports_weight_grad is false on this architecture")
}
