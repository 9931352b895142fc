//! The register tiles of the direct convolutions ([`crate::direct_conv`]'s forward and
//! stride-1 input gradient, [`crate::strided_input_grad`]'s phases): weights packed in tile
//! order, the bands of output rows a task computes, and the AVX-512 tile that sums one block
//! of output channels × a few vectors of output texels over every input channel and tap,
//!
//! ```text
//! y[o, p..p+16] += W[o, c, ky, kx] · xp[c, origin(p) + tap(ky, kx) .. +16]
//! ```
//!
//! one broadcast weight and one unaligned load per tile row and column (Georganas et al.,
//! "Anatomy of high-performance deep learning convolutions on SIMD architectures", SC 2018).
//! A tile of `OC_BLOCK` output channels × `TILE_VECTORS` vectors keeps 24 accumulators of the
//! 32 registers; a row's last, partial vector reads and writes only its lanes.

use crate::avx512::{LANES, lane_mask};

/// Output channels per register tile.
pub(crate) const OC_BLOCK: usize = 6;

/// Vectors of 16 output texels per register tile: `OC_BLOCK × TILE_VECTORS` = 24
/// accumulators, plus `TILE_VECTORS` input vectors and one broadcast weight, of 32 registers.
const TILE_VECTORS: usize = 4;

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
