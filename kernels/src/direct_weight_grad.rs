//! The direct weight gradient of f32 convolutions ([`crate::conv`]'s choice for weight
//! gradients over at least `WG_MIN_TEXELS` output texels): a reduction over texels whose
//! vector lanes run over output channels, `dy` copied channels-last one L1-sized band of rows
//! at a time, and a tile of `WG_VECTORS` vectors of output channels × `WG_CHANNELS` input
//! channels of one tap adding `dy` rows times broadcast input texels, its sums kept
//! channels-last between bands and transposed once (the scheme of Georganas et al., SC 2018,
//! for the weight-update pass). Written once over `Simd` (6 × 4 tiles on AVX-512, 5 × 2 on
//! AVX2); it reads the padded input of [`crate::padded_input`].

use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::conv_geometry::Geometry;
use crate::padded_input::{Padded, pad_rows};
use crate::simd::{Kernel, Simd, SimdFamily, on_family};

/// Input channels per weight-gradient tile of the widest family: the accumulators' array size
/// (a family with fewer, [`Simd::WG_CHANNELS`], leaves the last rows unused).
const MAX_WG_CHANNELS: usize = 6;

/// Bytes of `dy`'s channels-last copy per band of output rows: two thirds of a 48 KiB L1, so
/// that the band stays in L1 while every (tap, input channel) tile sweeps it.
const WG_BAND_BYTES: usize = 32 << 10;

/// Fewest output texels (over the batch) for the direct weight gradient: below, its fixed
/// costs per weight (the channels-last sums, zeroed, then transposed back) outweigh the
/// `2·texels` FLOP each weight takes, and im2col + `gemm` writes the weights in place (the
/// estimator's 4² and 8² layers; `docs/benchmarks/conv-kernels.md`, "A direct convolution kernel").
const WG_MIN_TEXELS: usize = 1024;

/// (c, tap) rows of the channels-last sums transposed back together: 16 floats, one 64-byte
/// cache line, of each dW row per pass.
const TRANSPOSE_ROWS: usize = 16;

/// Whether [`weight_grad`] computes this convolution's weight gradient on `family`: every
/// f32 geometry but a pointwise one, on a vector family.
pub(crate) fn supports(g: &Geometry, family: SimdFamily) -> bool {
    family != SimdFamily::Scalar && !g.is_pointwise()
}

/// Whether [`weight_grad`] is the faster way: [`supports`] with at least [`WG_MIN_TEXELS`]
/// output texels.
pub(crate) fn prefers(g: &Geometry, family: SimdFamily) -> bool {
    supports(g, family) && g.b * g.ho * g.wo >= WG_MIN_TEXELS
}

/// Weight gradient: writes every element of `dw` (C_out·C_in·kh·kw) from `x` (B·C_in·H·W)
/// and `dy` (B·C_out·H_out·W_out),
///
/// ```text
/// dW[o, c, ky, kx] = Σ_b Σ_(oy, ox) dy[b, o, oy, ox] · xpad[b, c, s·oy + ky, s·ox + kx]
/// ```
///
/// with the lanes of a vector over output channels: `dy` is copied channels-last one
/// L1-sized band of output rows at a time (row `(oy, ox)` of C_out floats, padded to whole
/// vectors), and a tile of `WG_VECTORS` vectors of output channels × `WG_CHANNELS` input
/// channels of one tap adds `dy` row × broadcast input texel over the band, its sums kept in
/// a channels-last gradient buffer between bands. Each task pads whole input images (weight
/// gradients run in training, on images of at most 256² here). Requires [`supports`]
/// (`family` is then one the CPU has). Tasks (ranges of images, or of one image's bands when
/// there are fewer images than threads) sum into their own buffers, added in task order, so
/// the result does not depend on thread timing.
pub(crate) fn weight_grad(
    g: &Geometry,
    x: &[f32],
    dy: &[f32],
    dw: &mut [f32],
    (threads, family): (usize, SimdFamily),
) {
    assert!(supports(g, family), "direct conv: unsupported geometry");
    assert_eq!(
        dw.len(),
        g.co * g.k(),
        "direct conv: weight gradient of the wrong size"
    );
    on_family!(family, S => weight_grad_on::<S>(g, x, dy, dw, threads));
}

/// [`weight_grad`] on `S`'s tiles.
fn weight_grad_on<S: Simd>(g: &Geometry, x: &[f32], dy: &[f32], dw: &mut [f32], threads: usize) {
    let (x_len, y_len) = (g.ci * g.h * g.w, g.co * g.ho * g.wo);
    let co_pad = g.co.next_multiple_of(S::LANES);
    let band = (WG_BAND_BYTES / (4 * g.wo * co_pad)).clamp(1, g.ho);
    let bands = g.ho.div_ceil(band);
    // The (image, band) units in order, cut into at most `threads` contiguous tasks: whole
    // images each when there are enough, else runs of one image's bands.
    let units = g.b * bands;
    let per = units.div_ceil(threads.max(1)).max(1);
    let layout = Padded::new(g, g.ho);
    let taps = g.kh * g.kw;
    let ci_pad = g.ci.next_multiple_of(S::WG_CHANNELS);
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
                    pad_rows::<S>(g, layout, xi, 0..layout.rows, &mut xp);
                    padded = Some(i);
                }
                let dyi = &dy[i * y_len..(i + 1) * y_len];
                let rows = j * band..((j + 1) * band).min(g.ho);
                channels_last(g, dyi, co_pad, rows.clone(), &mut dy_rows);
                let band = Band {
                    g,
                    layout,
                    xp: &xp,
                    dy_rows: &dy_rows,
                    co_pad,
                    rows,
                };
                band.add_to::<S>(&mut sums);
            }
            sums
        })
        .collect();
    // Back to dW's [o][c][tap] order, TRANSPOSE_ROWS (c, tap) rows of the sums at a time:
    // their reads run along o, the writes along (c, tap), both within a few cache lines.
    let row = g.ci * taps;
    for ct0 in (0..row).step_by(TRANSPOSE_ROWS) {
        let cts = ct0..(ct0 + TRANSPOSE_ROWS).min(row);
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

/// One band of output rows of one image: the padded input `xp` and the band's channels-last
/// `dy_rows` (rows of `co_pad` floats).
struct Band<'a> {
    g: &'a Geometry,
    layout: Padded,
    xp: &'a [f32],
    dy_rows: &'a [f32],
    co_pad: usize,
    rows: std::ops::Range<usize>,
}

impl Band<'_> {
    /// Adds the band's weight gradient into `sums` ([c][tap][o], C_in and C_out padded to
    /// whole tiles of `S`).
    fn add_to<S: Simd>(&self, sums: &mut [f32]) {
        let (g, co_pad) = (self.g, self.co_pad);
        let taps = g.kh * g.kw;
        let vectors = co_pad / S::LANES;
        assert_eq!(
            sums.len(),
            g.ci.next_multiple_of(S::WG_CHANNELS) * taps * co_pad,
            "direct conv: weight-gradient sums of the wrong size"
        );
        for t in 0..taps {
            let shift = self.layout.tap(g, t / g.kw, t % g.kw);
            for c0 in (0..g.ci).step_by(S::WG_CHANNELS) {
                // Channels past C_in repeat the last one; their sums land in the padding of
                // `sums`.
                let planes: [usize; MAX_WG_CHANNELS] =
                    std::array::from_fn(|b| (c0 + b).min(g.ci - 1) * self.layout.plane + shift);
                let sum_at = (c0 * taps + t) * co_pad;
                for v0 in (0..vectors).step_by(S::WG_VECTORS) {
                    let tile = WeightTile {
                        band: self,
                        planes,
                        v0,
                        sums: sums.as_mut_ptr(),
                        at: sum_at + v0 * S::LANES,
                        stride: taps * co_pad,
                    };
                    // SAFETY: the CPU has S's features (`weight_grad`'s contract); `dy_rows`
                    // holds the band's rows of `co_pad` floats, `xp` the padded texels every
                    // tap reads, and `sums` (its size asserted) the tile's WG_CHANNELS rows
                    // of `taps · co_pad` floats from `at`.
                    unsafe {
                        match S::WG_VECTORS.min(vectors - v0) {
                            4 => S::vectorize(WeightTileOf::<4>(tile)),
                            3 => S::vectorize(WeightTileOf::<3>(tile)),
                            2 => S::vectorize(WeightTileOf::<2>(tile)),
                            _ => S::vectorize(WeightTileOf::<1>(tile)),
                        }
                    }
                }
            }
        }
    }
}

/// One weight-gradient tile: vectors of output channels from `v0` × `WG_CHANNELS` input
/// channels (`planes`: each one's padded plane offset plus the tap's shift), summed over the
/// band's texels onto `sums[at + b·stride + LANES·j ..]`.
#[derive(Clone, Copy)]
struct WeightTile<'a> {
    band: &'a Band<'a>,
    planes: [usize; MAX_WG_CHANNELS],
    v0: usize,
    sums: *mut f32,
    at: usize,
    stride: usize,
}

/// [`WeightTile`] over `NV` vectors, as a [`Kernel`].
struct WeightTileOf<'a, const NV: usize>(WeightTile<'a>);

impl<const NV: usize> Kernel for WeightTileOf<'_, NV> {
    type Output = ();

    #[inline(always)]
    unsafe fn run<S: Simd>(self) {
        let WeightTile {
            band,
            planes,
            v0,
            sums,
            at,
            stride,
        } = self.0;
        let (g, co_pad, rows) = (band.g, band.co_pad, &band.rows);
        // SAFETY (every block below): the CPU has S's features and every access lies in
        // the operands (`Band::add_to`).
        let mut acc = [[unsafe { S::zero() }; NV]; MAX_WG_CHANNELS];
        for (b, row) in acc.iter_mut().enumerate().take(S::WG_CHANNELS) {
            for (j, a) in row.iter_mut().enumerate() {
                *a = unsafe { S::load(sums.add(at + b * stride + j * S::LANES)) };
            }
        }
        let (x0, d0) = (band.xp.as_ptr(), band.dy_rows.as_ptr());
        for oy in rows.clone() {
            let (x_row, d_row) = (band.layout.origin(g, oy, 0), (oy - rows.start) * g.wo);
            for ox in 0..g.wo {
                let d = unsafe { d0.add((d_row + ox) * co_pad + v0 * S::LANES) };
                let dv: [S::V; NV] =
                    std::array::from_fn(|j| unsafe { S::load(d.add(j * S::LANES)) });
                for (b, row) in acc.iter_mut().enumerate().take(S::WG_CHANNELS) {
                    let xv = unsafe { S::splat(*x0.add(planes[b] + x_row + ox)) };
                    for (a, dvj) in row.iter_mut().zip(&dv) {
                        *a = unsafe { S::fmadd(*dvj, xv, *a) };
                    }
                }
            }
        }
        for (b, row) in acc.iter().enumerate().take(S::WG_CHANNELS) {
            for (j, a) in row.iter().enumerate() {
                unsafe { S::store(sums.add(at + b * stride + j * S::LANES), *a) };
            }
        }
    }
}
