//! Direct convolution of f32 images on AVX-512: the forward, input-gradient and
//! weight-gradient kernels of [`crate::conv`] for the layers that dominate the generator's,
//! discriminator's and estimator's steps (3×3 and 4×4, strides 1 and 2).
//!
//! im2col + `gemm` copies every input texel `kh·kw` times into `col(x)` and has `gemm` pack it
//! again; here the input is copied once, into a padded plane per channel (zeros or wrapped
//! texels, as the padding mode says; for stride `s` each padded row is stored as its `s`
//! column phases, so that output texels `ox..ox+16` read 16 consecutive floats for every
//! tap), and register-blocked kernels read it in place, the scheme of direct convolutions on
//! SIMD CPUs (Georganas et al., "Anatomy of high-performance deep learning convolutions on
//! SIMD architectures", SC 2018; oneDNN's direct kernels, which PyTorch CPU calls).
//!
//! **Forward.** With the activations kept in NCHW order, one AVX-512 vector holds 16
//! consecutive output texels of one channel; a tile of `OC_BLOCK` output channels ×
//! `TILE_VECTORS` vectors (24 accumulators of the 32 registers) is summed over every input
//! channel and kernel tap, one broadcast weight and one unaligned load per tile row and column:
//!
//! ```text
//! y[o, p..p+16] += W[o, c, ky, kx] · xpad[c, origin(p) + tap(ky, kx) .. +16]
//! ```
//!
//! The weights are repacked once per call so that the tile's `OC_BLOCK` weights of one
//! (c, ky, kx) are adjacent. Output rows must hold at least one vector (`W_out ≥ 16`); a
//! row's last, partial vector reads and writes only its lanes (masked loads and stores).
//!
//! **Input gradient.** That of a stride-1 convolution is itself such a convolution, of `dy`
//! with the kernel flipped in both axes and its two channel axes swapped, padded by
//! `k − 1 − p` (for circular padding only when `2p = k − 1`, where output and input planes
//! have the same size and the wrap-around has the same period). Strided ones are `s²` such
//! convolutions with sub-kernels, one per phase of the input grid
//! ([`crate::strided_input_grad`]).
//!
//! **Weight gradient.** A reduction over texels: the 16 lanes run over output channels instead,
//! `dy` copied channels-last one L1-sized band of rows at a time, and a tile of `WG_VECTORS`
//! × 16 output channels × `WG_CHANNELS` input channels of one tap adds `dy` rows times
//! broadcast input texels, its sums kept channels-last between bands and transposed once.
//!
//! Only f32 on CPUs with AVX-512F take this path, and not pointwise convolutions, which `gemm`
//! already reads in place (`supports_forward`, `supports_input_grad`, `supports_weight_grad`);
//! everything else stays on im2col + `gemm`, which the equivalence tests compare it with.
//! Measurements: `docs/benchmarks/conv-kernels.md`, "A direct convolution kernel".

use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::avx512::{LANES, has_avx512, lane_mask};
use crate::conv::{Conv2dSpec, Geometry, PaddingMode};
use crate::strided_input_grad;

/// Output channels per register tile.
const OC_BLOCK: usize = 6;
/// Vectors of 16 output texels per register tile: `OC_BLOCK × TILE_VECTORS` = 24
/// accumulators, plus `TILE_VECTORS` input vectors and one broadcast weight, of 32 registers.
const TILE_VECTORS: usize = 4;

/// Whether [`forward`] computes this convolution: any but a pointwise one with output rows of
/// at least one vector (a row's last, partial vector is masked).
pub(crate) fn supports_forward(g: &Geometry) -> bool {
    !g.is_pointwise() && g.wo >= LANES && has_avx512()
}

/// The forward convolution whose value is the input gradient of `g`, with its
/// flipped-and-transposed kernel's geometry; `None` when that is not a stride-1 convolution
/// [`forward`] handles (module docs).
pub(crate) fn input_grad_geometry(g: &Geometry) -> Option<Geometry> {
    if g.is_pointwise()
        || g.stride != 1
        || g.pad >= g.kh
        || g.pad >= g.kw
        || g.w < LANES
        || !has_avx512()
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

/// Whether [`input_grad`] computes this convolution's input gradient: stride 1 as the
/// adjoint forward, larger strides phase by phase ([`crate::strided_input_grad`]).
pub(crate) fn supports_input_grad(g: &Geometry) -> bool {
    input_grad_geometry(g).is_some() || strided_input_grad::supports(g)
}

/// Forward convolution: writes every element of `y` (B·C_out·H_out·W_out) from `x`
/// (B·C_in·H·W) and `w` (C_out·C_in·kh·kw). Requires [`supports_forward`].
pub(crate) fn forward(g: &Geometry, x: &[f32], w: &[f32], y: &mut [f32], threads: usize) {
    assert!(
        supports_forward(g),
        "direct conv: unsupported geometry {g:?}"
    );
    run(g, x, &pack_forward(g, w), y, threads);
}

/// The forward's weights (C_out·C_in·kh·kw) in tile order ([`pack_weights`]).
fn pack_forward(g: &Geometry, w: &[f32]) -> Vec<f32> {
    pack_weights(g.co, g.k(), |o, dst| {
        dst.copy_from_slice(&w[o * g.k()..][..g.k()])
    })
}

/// Input gradient: writes every element of `dx` (B·C_in·H·W) from `dy` (B·C_out·H_out·W_out)
/// and `w` (C_out·C_in·kh·kw), as the forward convolution of `dy` with the flipped,
/// transposed kernel (stride 1) or phase by phase (larger strides). Requires
/// [`supports_input_grad`].
pub(crate) fn input_grad(g: &Geometry, dy: &[f32], w: &[f32], dx: &mut [f32], threads: usize) {
    if g.stride > 1 {
        strided_input_grad::input_grad(g, dy, w, dx, threads);
        return;
    }
    let adjoint = input_grad_geometry(g).expect("direct conv: unsupported input gradient");
    let taps = g.kh * g.kw;
    // Adjoint kernel [c][o][ky'][kx'] = W[o][c][kh−1−ky'][kw−1−kx']: each (o, c) kernel
    // reversed.
    let packed = pack_weights(adjoint.co, adjoint.k(), |c, dst| {
        for (o, flipped) in dst.chunks_exact_mut(taps).enumerate() {
            let kernel = &w[(o * g.ci + c) * taps..][..taps];
            for (d, &v) in flipped.iter_mut().zip(kernel.iter().rev()) {
                *d = v;
            }
        }
    });
    run(&adjoint, dy, &packed, dx, threads);
}

/// Weights in tile order: block `b` of [`OC_BLOCK`] output channels, then lowered row
/// `k = (c·kh + ky)·kw + kx`, then the block's channels, zeros past `co`.
/// `row(o, dst)` writes row `o` (its `k` weights) of the `co × k` kernel matrix into `dst`.
pub(crate) fn pack_weights(co: usize, k: usize, row: impl Fn(usize, &mut [f32])) -> Vec<f32> {
    let mut packed = vec![0.0; co.div_ceil(OC_BLOCK) * k * OC_BLOCK];
    let mut scratch = vec![0.0; k];
    for o in 0..co {
        row(o, &mut scratch);
        let (b, j) = (o / OC_BLOCK, o % OC_BLOCK);
        let block = &mut packed[b * k * OC_BLOCK..(b + 1) * k * OC_BLOCK];
        for (dst, &v) in block[j..].iter_mut().step_by(OC_BLOCK).zip(&scratch) {
            *dst = v;
        }
    }
    packed
}

/// Bytes of the padded input copy one forward task holds: its band of output rows is as many
/// rows as fit (at least [`MIN_BAND_ROWS`]), so that a 2048² sample needs no whole padded
/// copy of each feature map beside the map itself.
pub(crate) const PAD_BAND_BYTES: usize = 4 << 20;
/// Fewest output rows per band: the `kh − 1` halo rows padded twice stay a small share.
pub(crate) const MIN_BAND_ROWS: usize = 8;

/// Layout of a padded copy of `rows` consecutive padded rows of one image (all `Hp = H + 2p`
/// or a band of them): per channel, each row the `s` phases of its `Wp = W + 2p` padded
/// columns one after the other (column `j` at `(j mod s)·phase + j / s`), so that output
/// texels `ox..ox+16` of a stride-`s` convolution read 16 consecutive floats for every tap.
#[derive(Clone, Copy)]
struct Padded {
    /// Floats per phase: ⌈Wp / s⌉.
    phase: usize,
    /// Floats per padded row: `s · phase`.
    row: usize,
    /// Padded rows held per channel.
    rows: usize,
    /// Floats per channel: `rows · row`.
    plane: usize,
}

impl Padded {
    /// The layout of padded rows enough for `out_rows` output rows.
    fn new(g: &Geometry, out_rows: usize) -> Self {
        let wp = g.w + 2 * g.pad;
        let phase = wp.div_ceil(g.stride);
        let row = g.stride * phase;
        let rows = (out_rows - 1) * g.stride + g.kh;
        Self {
            phase,
            row,
            rows,
            plane: rows * row,
        }
    }

    /// Offset of padded texel (row 0, column `kx`) + `ky` rows: where tap (ky, kx) reads for
    /// output texel (0, 0).
    fn tap(&self, g: &Geometry, ky: usize, kx: usize) -> usize {
        ky * self.row + (kx % g.stride) * self.phase + kx / g.stride
    }

    /// Offset of the padded texel tap (0, 0) reads for output texel (oy, ox), `oy` counted from
    /// the first output row of the copy.
    fn origin(&self, g: &Geometry, oy: usize, ox: usize) -> usize {
        g.stride * oy * self.row + ox
    }
}

/// Copies padded rows `rows` (at most [`Padded::rows`] of them) of image `x` (C_in·H·W) into
/// `xp` (C_in·[`Padded::plane`]), padded by zeros or wrapped. Floats of a row past its `Wp`
/// columns (the last phase's tail) are zeros.
fn pad_rows(g: &Geometry, layout: Padded, x: &[f32], rows: std::ops::Range<usize>, xp: &mut [f32]) {
    assert!(
        rows.len() <= layout.rows,
        "direct conv: band of {rows:?} too tall"
    );
    let (wp, p, s) = (g.w + 2 * g.pad, g.pad, g.stride);
    let cols: Vec<Option<usize>> = (0..wp).map(|j| g.source_index(j, p, g.w)).collect();
    for c in 0..g.ci {
        let plane = &x[c * g.h * g.w..(c + 1) * g.h * g.w];
        for (r, padded) in rows.clone().enumerate() {
            let dst = &mut xp[c * layout.plane + r * layout.row..][..layout.row];
            match g.source_index(padded, p, g.h) {
                None => dst.fill(0.0),
                Some(iy) => {
                    let src = &plane[iy * g.w..(iy + 1) * g.w];
                    if s == 1 {
                        dst[p..p + g.w].copy_from_slice(src);
                        for j in (0..p).chain(p + g.w..wp) {
                            dst[j] = cols[j].map_or(0.0, |ix| src[ix]);
                        }
                    } else {
                        // Phase by phase: the interior columns of a phase are every s-th texel
                        // of the source row, the rest wrapped or zero.
                        for q in 0..s {
                            let out = &mut dst[q * layout.phase..(q + 1) * layout.phase];
                            // Interior: p ≤ t·s + q < p + W.
                            let lo = p.saturating_sub(q).div_ceil(s).min(out.len());
                            let hi = (p + g.w).saturating_sub(q).div_ceil(s).clamp(lo, out.len());
                            if lo < hi {
                                let first = lo * s + q - p;
                                strided_copy(&src[first..], s, &mut out[lo..hi]);
                            }
                            for t in (0..lo).chain(hi..out.len()) {
                                out[t] = match cols.get(t * s + q) {
                                    Some(&Some(ix)) => src[ix],
                                    _ => 0.0,
                                };
                            }
                        }
                    }
                }
            }
        }
    }
}

/// `dst[i] = src[s·i]` for every element of `dst`: one column phase of a padded row. Stride
/// 2 (every strided layer here) takes the even lanes of 32 floats per vector on AVX-512; the
/// scalar loop of other strides gathers one float at a time.
fn strided_copy(src: &[f32], s: usize, dst: &mut [f32]) {
    assert!(
        dst.is_empty() || s * (dst.len() - 1) < src.len(),
        "direct conv: strided copy past its row"
    );
    #[cfg(target_arch = "x86_64")]
    if s == 2 && has_avx512() {
        // SAFETY: AVX-512F was detected; the assertion bounds every read.
        unsafe { even_lanes_avx512(src, dst) };
        return;
    }
    for (d, v) in dst.iter_mut().zip(src.iter().step_by(s)) {
        *d = *v;
    }
}

/// [`strided_copy`] with stride 2 on AVX-512.
///
/// # Safety
/// AVX-512F is available and `2·(dst.len() − 1) < src.len()`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn even_lanes_avx512(src: &[f32], dst: &mut [f32]) {
    use std::arch::x86_64::*;
    for i0 in (0..dst.len()).step_by(LANES) {
        let lanes = LANES.min(dst.len() - i0);
        // SAFETY: the loads read src[2·i0 ..][..2·lanes − 1], inside src by the contract; the
        // masked store writes dst[i0 ..][..lanes].
        unsafe {
            let v = crate::avx512::load_even_lanes(src.as_ptr().add(2 * i0), lanes);
            _mm512_mask_storeu_ps(dst.as_mut_ptr().add(i0), lane_mask(lanes), v);
        }
    }
}

/// Runs the forward tiles of every image, band of output rows by band of output rows: the
/// (image, band) pairs are the parallel tasks, each padding the input rows its band reads
/// into its own buffer. Bands hold [`PAD_BAND_BYTES`] of padded input, and are cut finer when
/// there are fewer images than threads, so that every thread has work.
fn run(g: &Geometry, x: &[f32], packed: &[f32], y: &mut [f32], threads: usize) {
    // Padded input bytes per output row: `s` padded rows of every channel.
    let row_bytes = 4 * g.ci * g.stride * Padded::new(g, 1).row;
    let mut band = (PAD_BAND_BYTES / row_bytes.max(1)).max(MIN_BAND_ROWS);
    if threads > 1 && g.b < threads {
        band = band.min(g.ho.div_ceil(2 * threads));
    }
    run_in_bands(g, x, packed, y, band.clamp(1, g.ho));
}

/// [`run`] with bands of `band` output rows (the last one shorter when they do not divide
/// `H_out`).
fn run_in_bands(g: &Geometry, x: &[f32], packed: &[f32], y: &mut [f32], band: usize) {
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
            pad_rows(
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
            // SAFETY: `y` outlives the tasks; task (i, band) writes only output rows r0..r1
            // of image i, which no other task writes; `xp` holds the padded rows they read.
            unsafe { run_tiles(&grid, xp, packed, yi) };
        },
    );
}

/// Where the register tiles of one band read and write: output texel (oy, ox) of the band
/// (oy counted from its first row) sums, over the `ci` input channels and the `taps`, the
/// floats of `xp` at `c·plane_in + in_base + oy·in_row + ox + tap`, and is stored at
/// `o·plane_out + out_base + oy·wo + ox` of the output's channel planes.
pub(crate) struct TileGrid<'a> {
    /// Input channels summed over, `plane_in` floats apart in `xp`.
    pub(crate) ci: usize,
    pub(crate) plane_in: usize,
    /// Offsets of the kernel taps in `xp`, in the packed weights' order.
    pub(crate) taps: &'a [usize],
    /// Offset in `xp` of tap offset 0 for output texel (0, 0), and between output rows.
    pub(crate) in_base: usize,
    pub(crate) in_row: usize,
    /// Output channels, `plane_out` floats apart.
    pub(crate) co: usize,
    pub(crate) plane_out: usize,
    /// Output rows of the band and texels per row.
    pub(crate) rows: usize,
    pub(crate) wo: usize,
    /// Offset of the band's first output row in every output plane.
    pub(crate) out_base: usize,
}

/// Computes every output channel of one band ([`TileGrid`]) from `xp` and the weights packed
/// in tile order ([`pack_weights`]: `OC_BLOCK` channels, then `ci · taps` rows), in tiles of
/// [`TILE_VECTORS`] output vectors in row-major order.
///
/// # Safety
/// `y_addr` is the address of the output planes; no other thread writes the band's rows
/// while this runs, and `xp` holds every float the taps read (module docs).
pub(crate) unsafe fn run_tiles(grid: &TileGrid, xp: &[f32], packed: &[f32], y_addr: usize) {
    let TileGrid {
        ci,
        plane_in,
        taps,
        in_base,
        in_row,
        co,
        plane_out,
        rows,
        wo,
        out_base,
    } = *grid;
    let k = ci * taps.len();
    // The band's vectors in row-major order, (input offset in `xp`, output offset in a plane,
    // lanes): each row's whole vectors, then its last, partial one masked.
    let mut vectors = Vec::with_capacity(rows * wo.div_ceil(LANES));
    for oy in 0..rows {
        for ox in (0..wo).step_by(LANES) {
            let mask = lane_mask(wo - ox);
            vectors.push((in_base + oy * in_row + ox, out_base + oy * wo + ox, mask));
        }
    }
    let y = y_addr as *mut f32;
    // Tiles of TILE_VECTORS consecutive vectors, the band's last tile of 1 to 3: a row's
    // partial vector shares a tile with its neighbours rather than taking one alone. Every
    // block of output channels runs on a group of vectors before the next group: the
    // group's input rows (C_in · 4 vectors per tap row) stay in L1 across the blocks, and
    // only the broadcast weights (6 floats per channel and tap) come from L2.
    for group in vectors.chunks(TILE_VECTORS) {
        for b in 0..co.div_ceil(OC_BLOCK) {
            let wb = &packed[b * k * OC_BLOCK..(b + 1) * k * OC_BLOCK];
            let channels = OC_BLOCK.min(co - b * OC_BLOCK);
            // SAFETY: block b's first channel plane lies inside the outputs.
            let out = (unsafe { y.add(b * OC_BLOCK * plane_out) }, plane_out);
            // SAFETY: AVX-512F was detected (the callers' gates); loads stay inside `xp`,
            // stores inside the tile's outputs, masked lanes past a row's end are neither
            // read nor written (caller's contract).
            unsafe {
                match group.len() {
                    4 => tile_of::<4>(xp, plane_in, ci, taps, group, wb, out, channels),
                    3 => tile_of::<3>(xp, plane_in, ci, taps, group, wb, out, channels),
                    2 => tile_of::<2>(xp, plane_in, ci, taps, group, wb, out, channels),
                    _ => tile_of::<1>(xp, plane_in, ci, taps, group, wb, out, channels),
                }
            }
        }
    }
}

/// [`tile`] over `NV` vectors given as (input offset, output offset, lanes) triples.
///
/// # Safety
/// As [`tile`]'s.
#[allow(clippy::too_many_arguments)]
unsafe fn tile_of<const NV: usize>(
    xp: &[f32],
    plane_in: usize,
    ci: usize,
    taps: &[usize],
    group: &[(usize, usize, u16)],
    wb: &[f32],
    out: (*mut f32, usize),
    channels: usize,
) {
    let ins: [usize; NV] = std::array::from_fn(|j| group[j].0);
    let outs: [usize; NV] = std::array::from_fn(|j| group[j].1);
    let masks: [u16; NV] = std::array::from_fn(|j| group[j].2);
    // SAFETY: the caller's.
    unsafe { tile::<NV>(xp, plane_in, ci, taps, ins, wb, out, outs, masks, channels) }
}

/// One register tile: `rows` (≤ [`OC_BLOCK`]) output channels × `NV` vectors, summed over
/// `ci` channels and the taps, stored at `y.0 + o·y.1 + outs[j]`. Vector `j` reads and writes
/// only the lanes of `masks[j]` (all 16 but in a row's last, partial vector).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[allow(clippy::too_many_arguments)]
unsafe fn tile<const NV: usize>(
    xp: &[f32],
    plane_in: usize,
    ci: usize,
    taps: &[usize],
    ins: [usize; NV],
    wb: &[f32],
    (y, plane_out): (*mut f32, usize),
    outs: [usize; NV],
    masks: [u16; NV],
    rows: usize,
) {
    use std::arch::x86_64::*;
    let mut acc = [[_mm512_setzero_ps(); NV]; OC_BLOCK];
    let mut w = wb.as_ptr();
    let x0 = xp.as_ptr();
    let partial = masks.iter().any(|&m| m != u16::MAX);
    for c in 0..ci {
        let xc = unsafe { x0.add(c * plane_in) };
        for &t in taps {
            let mut xv = [_mm512_setzero_ps(); NV];
            for j in 0..NV {
                let at = unsafe { xc.add(ins[j] + t) };
                xv[j] = if partial {
                    unsafe { _mm512_maskz_loadu_ps(masks[j], at) }
                } else {
                    unsafe { _mm512_loadu_ps(at) }
                };
            }
            for (o, row) in acc.iter_mut().enumerate() {
                let wv = _mm512_set1_ps(unsafe { *w.add(o) });
                for j in 0..NV {
                    row[j] = _mm512_fmadd_ps(xv[j], wv, row[j]);
                }
            }
            w = unsafe { w.add(OC_BLOCK) };
        }
    }
    for (o, row) in acc.iter().enumerate().take(rows) {
        for j in 0..NV {
            unsafe { _mm512_mask_storeu_ps(y.add(o * plane_out + outs[j]), masks[j], row[j]) };
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[allow(clippy::too_many_arguments)]
unsafe fn tile<const NV: usize>(
    _: &[f32],
    _: usize,
    _: usize,
    _: &[usize],
    _: [usize; NV],
    _: &[f32],
    _: (*mut f32, usize),
    _: [usize; NV],
    _: [u16; NV],
    _: usize,
) {
    unreachable!("AVX-512 only: supports_forward is false on this architecture")
}

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
/// estimator's 4² and 8² layers; `docs/benchmarks/conv-kernels.md`, "A direct convolution kernel").
const WG_MIN_TEXELS: usize = 1024;

/// Whether [`weight_grad`] computes this convolution's weight gradient: every f32 geometry
/// but a pointwise one, on AVX-512.
pub(crate) fn supports_weight_grad(g: &Geometry) -> bool {
    !g.is_pointwise() && has_avx512()
}

/// Whether [`weight_grad`] is the faster way: [`supports_weight_grad`] with at least
/// [`WG_MIN_TEXELS`] output texels.
pub(crate) fn prefers_weight_grad(g: &Geometry) -> bool {
    supports_weight_grad(g) && g.b * g.ho * g.wo >= WG_MIN_TEXELS
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
    assert!(supports_weight_grad(g), "direct conv: unsupported geometry");
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

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Result, Tensor};

    use super::*;
    use crate::conv::{apply_input_grad, apply_weight_grad, conv2d_reference};
    use crate::testing::max_abs_diff;
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
    fn direct_conv_matches_the_f64_reference_and_its_gradients() -> Result<()> {
        if !has_avx512() {
            eprintln!("no AVX-512 on this CPU: the direct kernels are never used");
            return Ok(());
        }
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
                let case = format!("{mode:?} x{:?} co {co} k{k} s{stride} p{p}", (b, ci, h, w));
                // f32 sums of ≤ 70·9 = 630 products of values in [−1, 1]: rounding ≲ 630·6e-8;
                // a wrong tap or channel is off by O(0.1).
                // Weight gradients sum over B·H_out·W_out ≤ 768 texels: rounding ≲ 5e-5.
                let tol = 1e-4;
                for threads in [1, 2, 3] {
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
                    if supports_forward(&g) {
                        direct.0 += 1;
                        check("forward", &y_ref, &|y| forward(&g, &xv, &wv, y, threads))?;
                    }
                    if supports_input_grad(&g) {
                        direct.1 += 1;
                        let run = |dx: &mut [f32]| input_grad(&g, &dyv, &wv, dx, threads);
                        check("input gradient", &dx_ref, &run)?;
                    }
                    if supports_weight_grad(&g) {
                        direct.2 += 1;
                        let run = |dw: &mut [f32]| weight_grad(&g, &xv, &dyv, dw, threads);
                        check("weight gradient", &dw_ref, &run)?;
                    }
                }
            }
        }
        // Of the 34 (case, mode) pairs, 30 forwards are direct (not the pointwise one, left to
        // gemm, nor the unpadded one at W 16, 14 output columns: narrower than a vector), 28
        // input gradients (nor the unpadded circular 3×3s, whose adjoint needs a padding of 2
        // that wraps another way, nor the circular stride-2 ones of 9 rows, not 2·H_out) and
        // 32 weight gradients (all but the pointwise one), at 3 thread counts: the gates did
        // not silently turn a kernel off.
        assert_eq!(direct, (3 * 30, 3 * 28, 3 * 32));
        Ok(())
    }

    #[test]
    fn direct_forward_in_bands_of_rows_equals_the_whole_image() -> Result<()> {
        if !has_avx512() {
            eprintln!("no AVX-512 on this CPU: the direct kernels are never used");
            return Ok(());
        }
        // 16 output rows in bands of 3 (the last of 1), stride 1 and 2: each band pads its own
        // halo rows, zero or wrapped, and writes only its rows.
        let dev = Device::Cpu;
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
                let packed = pack_forward(&g, &wv);
                let mut whole = vec![f32::NAN; g.y_shape().elem_count()];
                run_in_bands(&g, &xv, &packed, &mut whole, 16);
                let mut banded = vec![f32::NAN; g.y_shape().elem_count()];
                run_in_bands(&g, &xv, &packed, &mut banded, 3);
                // Same sums in the same order: equal to the bit.
                assert_eq!(whole, banded, "{spec:?}");
                let reference = conv2d_reference(&x, &wt, spec)?;
                let banded = Tensor::from_vec(banded, g.y_shape(), &dev)?;
                assert!(max_abs_diff(&banded, &reference)? < 1e-4, "{spec:?}");
            }
        }
        Ok(())
    }

    #[test]
    fn direct_conv_declines_what_it_does_not_compute() -> Result<()> {
        let g = |x, w, spec| Geometry::new(x, w, spec);
        // Strided input gradients with a phase row of 8 texels, a phase without a tap (1×1
        // stride 2), a circular wrap of another period (H 9 ≠ 2·H_out); a row of 8 texels;
        // circular padding that is not "same".
        let strided = g((1, 2, 16, 16), (2, 2, 4, 4), Conv2dSpec::zeros(2, 1))?;
        assert!(!supports_input_grad(&strided));
        let tapless = g((1, 2, 16, 64), (2, 2, 1, 1), Conv2dSpec::zeros(2, 0))?;
        assert!(!supports_input_grad(&tapless));
        let odd_wrap = g((1, 2, 9, 64), (2, 2, 3, 3), Conv2dSpec::circular(2, 0))?;
        assert!(!supports_input_grad(&odd_wrap));
        let narrow = g((1, 2, 8, 8), (2, 2, 3, 3), Conv2dSpec::circular(1, 1))?;
        assert!(!supports_forward(&narrow) && !supports_input_grad(&narrow));
        let wrapped = g((1, 2, 16, 16), (2, 2, 3, 3), Conv2dSpec::circular(1, 2))?;
        assert!(input_grad_geometry(&wrapped).is_none());
        // Pointwise: gemm reads x in place, nothing to gain.
        let pointwise = g((1, 2, 16, 16), (2, 2, 1, 1), Conv2dSpec::zeros(1, 0))?;
        assert!(
            !supports_forward(&pointwise)
                && !supports_input_grad(&pointwise)
                && !supports_weight_grad(&pointwise)
        );
        Ok(())
    }
}
