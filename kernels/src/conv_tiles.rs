//! The register tiles of the direct convolutions ([`crate::direct_conv`]'s forward and
//! stride-1 input gradient, [`crate::strided_input_grad`]'s phases): weights packed in tile
//! order, the bands of output rows a task computes, and the tile that sums one block of output
//! channels × a few vectors of output texels over every input channel and tap,
//!
//! ```text
//! y[o, p..p+L] += W[o, c, ky, kx] · xp[c, origin(p) + tap(ky, kx) .. +L]
//! ```
//!
//! (`L` lanes per vector) with one broadcast weight and one unaligned load per tile row and
//! column (Georganas et al., "Anatomy of high-performance deep learning convolutions on SIMD
//! architectures", SC 2018). Written once over `Simd` ([`crate::simd`]): a tile of `OC_BLOCK` output channels
//! × `TILE_VECTORS` vectors fills the family's registers (6 × 4 of AVX-512's 32, 5 × 2 of
//! AVX2's 16, with the input vectors and the weight); a row's last, partial vector reads and
//! writes only its lanes.

use crate::simd::{Kernel, Simd};

/// Output channels per tile of the widest family: the accumulators' array size (a family
/// with fewer, [`Simd::OC_BLOCK`], leaves the last rows unused, which the compiler drops).
const MAX_OC_BLOCK: usize = 6;

/// Weights in tile order for family `S`: block `b` of [`Simd::OC_BLOCK`] output channels,
/// then lowered row `k = (c·kh + ky)·kw + kx`, then the block's channels, zeros past `co`.
/// `row(o, dst)` writes row `o` (its `k` weights) of the `co × k` kernel matrix into `dst`.
pub(crate) fn pack_weights<S: Simd>(
    co: usize,
    k: usize,
    row: impl Fn(usize, &mut [f32]),
) -> Vec<f32> {
    let block_len = S::OC_BLOCK;
    let mut packed = vec![0.0; co.div_ceil(block_len) * k * block_len];
    let mut scratch = vec![0.0; k];
    for o in 0..co {
        row(o, &mut scratch);
        let (b, j) = (o / block_len, o % block_len);
        let block = &mut packed[b * k * block_len..(b + 1) * k * block_len];
        for (dst, &v) in block[j..].iter_mut().step_by(block_len).zip(&scratch) {
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
/// in tile order for `S` ([`pack_weights`]: `OC_BLOCK` channels, then `ci · taps` rows), in
/// tiles of `TILE_VECTORS` output vectors in row-major order.
///
/// # Safety
/// The CPU has `S`'s features; `y_addr` is the address of the output planes; no other thread
/// writes the band's rows while this runs, and `xp` holds every float the taps read (module
/// docs).
pub(crate) unsafe fn run_tiles<S: Simd>(
    grid: &TileGrid,
    xp: &[f32],
    packed: &[f32],
    y_addr: usize,
) {
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
    let mut vectors = Vec::with_capacity(rows * wo.div_ceil(S::LANES));
    for oy in 0..rows {
        for ox in (0..wo).step_by(S::LANES) {
            let lanes = S::LANES.min(wo - ox);
            vectors.push((in_base + oy * in_row + ox, out_base + oy * wo + ox, lanes));
        }
    }
    let y = y_addr as *mut f32;
    let block_len = S::OC_BLOCK;
    // Tiles of TILE_VECTORS consecutive vectors, the band's last tile shorter: a row's
    // partial vector shares a tile with its neighbours rather than taking one alone. Every
    // block of output channels runs on a group of vectors before the next group: the
    // group's input rows (C_in · TILE_VECTORS vectors per tap row) stay in L1 across the
    // blocks, and only the broadcast weights (OC_BLOCK floats per channel and tap) come from
    // L2.
    for group in vectors.chunks(S::TILE_VECTORS) {
        for b in 0..co.div_ceil(block_len) {
            let weights = &packed[b * k * block_len..(b + 1) * k * block_len];
            let tile = Tile {
                xp,
                plane_in,
                ci,
                taps,
                group,
                weights,
                // Block b's first channel plane lies inside the outputs.
                y: y.wrapping_add(b * block_len * plane_out),
                plane_out,
                channels: block_len.min(co - b * block_len),
            };
            // SAFETY: the CPU has S's features (the caller's); loads stay inside `xp`, stores
            // inside the tile's outputs, masked lanes past a row's end are neither read nor
            // written (the caller's contract).
            unsafe {
                match group.len() {
                    4 => S::vectorize(TileOf::<4>(tile)),
                    3 => S::vectorize(TileOf::<3>(tile)),
                    2 => S::vectorize(TileOf::<2>(tile)),
                    _ => S::vectorize(TileOf::<1>(tile)),
                }
            }
        }
    }
}

/// One register tile's operands: `channels` (≤ `OC_BLOCK`) output channels from `y` (planes
/// `plane_out` apart) × the vectors of `group` ((input offset, output offset, lanes)),
/// summed over `ci` channels of `xp` (`plane_in` apart) and the `taps`.
#[derive(Clone, Copy)]
struct Tile<'a> {
    xp: &'a [f32],
    plane_in: usize,
    ci: usize,
    taps: &'a [usize],
    group: &'a [(usize, usize, usize)],
    weights: &'a [f32],
    y: *mut f32,
    plane_out: usize,
    channels: usize,
}

/// [`Tile`] over `NV` vectors, as a [`Kernel`].
struct TileOf<'a, const NV: usize>(Tile<'a>);

impl<const NV: usize> Kernel for TileOf<'_, NV> {
    type Output = ();

    /// Vector `j` reads and writes only its first `lanes` lanes (all but in a row's last,
    /// partial vector).
    #[inline(always)]
    unsafe fn run<S: Simd>(self) {
        let t = self.0;
        let ins: [usize; NV] = std::array::from_fn(|j| t.group[j].0);
        let outs: [usize; NV] = std::array::from_fn(|j| t.group[j].1);
        let partial = t.group.iter().any(|v| v.2 < S::LANES);
        // SAFETY (every block below): the CPU has S's features and every access stays inside
        // the operands (`run_tiles`'s contract).
        let masks: [S::Mask; NV] = std::array::from_fn(|j| unsafe { S::mask(t.group[j].2) });
        let mut acc = [[unsafe { S::zero() }; NV]; MAX_OC_BLOCK];
        let mut w = t.weights.as_ptr();
        let x0 = t.xp.as_ptr();
        for c in 0..t.ci {
            let xc = unsafe { x0.add(c * t.plane_in) };
            for &tap in t.taps {
                let mut xv = [unsafe { S::zero() }; NV];
                for j in 0..NV {
                    let at = unsafe { xc.add(ins[j] + tap) };
                    xv[j] = if partial {
                        unsafe { S::load_masked(masks[j], at) }
                    } else {
                        unsafe { S::load(at) }
                    };
                }
                for (o, row) in acc.iter_mut().enumerate().take(S::OC_BLOCK) {
                    let wv = unsafe { S::splat(*w.add(o)) };
                    for j in 0..NV {
                        row[j] = unsafe { S::fmadd(xv[j], wv, row[j]) };
                    }
                }
                w = unsafe { w.add(S::OC_BLOCK) };
            }
        }
        for (o, row) in acc.iter().enumerate().take(t.channels) {
            for j in 0..NV {
                let at = unsafe { t.y.add(o * t.plane_out + outs[j]) };
                if partial {
                    unsafe { S::store_masked(masks[j], at, row[j]) };
                } else {
                    unsafe { S::store(at, row[j]) };
                }
            }
        }
    }
}
