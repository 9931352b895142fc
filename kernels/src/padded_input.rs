//! The padded copy of an input the direct kernels read in place ([`crate::direct_conv`]'s
//! forward, [`crate::direct_weight_grad`]): per channel, padded rows (zeros or wrapped texels,
//! as the padding mode says), each stored as its `s` column phases for stride `s`, so that
//! the output texels of one vector read consecutive floats for every tap.

use crate::conv_geometry::Geometry;
use crate::simd::{Kernel, Simd};

/// Layout of a padded copy of `rows` consecutive padded rows of one image (all `Hp = H + 2p`
/// or a band of them): per channel, each row the `s` phases of its `Wp = W + 2p` padded
/// columns one after the other (column `j` at `(j mod s)·phase + j / s`), so that output
/// texels `ox..ox+L` of a stride-`s` convolution read `L` consecutive floats for every tap.
#[derive(Clone, Copy)]
pub(crate) struct Padded {
    /// Floats per phase: ⌈Wp / s⌉.
    pub(crate) phase: usize,
    /// Floats per padded row: `s · phase`.
    pub(crate) row: usize,
    /// Padded rows held per channel.
    pub(crate) rows: usize,
    /// Floats per channel: `rows · row`.
    pub(crate) plane: usize,
}

impl Padded {
    /// The layout of padded rows enough for `out_rows` output rows.
    pub(crate) fn new(g: &Geometry, out_rows: usize) -> Self {
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
    pub(crate) fn tap(&self, g: &Geometry, ky: usize, kx: usize) -> usize {
        ky * self.row + (kx % g.stride) * self.phase + kx / g.stride
    }

    /// Offset of the padded texel tap (0, 0) reads for output texel (oy, ox), `oy` counted from
    /// the first output row of the copy.
    pub(crate) fn origin(&self, g: &Geometry, oy: usize, ox: usize) -> usize {
        g.stride * oy * self.row + ox
    }
}

/// Copies padded rows `rows` (at most [`Padded::rows`] of them) of image `x` (C_in·H·W) into
/// `xp` (C_in·[`Padded::plane`]), padded by zeros or wrapped. Floats of a row past its `Wp`
/// columns (the last phase's tail) are zeros.
pub(crate) fn pad_rows<S: Simd>(
    g: &Geometry,
    layout: Padded,
    x: &[f32],
    rows: std::ops::Range<usize>,
    xp: &mut [f32],
) {
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
                                strided_copy::<S>(&src[first..], s, &mut out[lo..hi]);
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
/// 2 (every strided layer here) takes the even lanes of two vectors' floats per vector; the
/// scalar loop of other strides gathers one float at a time.
fn strided_copy<S: Simd>(src: &[f32], s: usize, dst: &mut [f32]) {
    assert!(
        dst.is_empty() || s * (dst.len() - 1) < src.len(),
        "direct conv: strided copy past its row"
    );
    if s == 2 {
        // SAFETY: the CPU has S's features (the direct kernels' gate); the assertion bounds
        // every read.
        unsafe { S::vectorize(EvenLanes { src, dst }) };
        return;
    }
    for (d, v) in dst.iter_mut().zip(src.iter().step_by(s)) {
        *d = *v;
    }
}

/// [`strided_copy`] with stride 2, as a [`Kernel`]: `2·(dst.len() − 1) < src.len()`.
struct EvenLanes<'a> {
    src: &'a [f32],
    dst: &'a mut [f32],
}

impl Kernel for EvenLanes<'_> {
    type Output = ();

    #[inline(always)]
    unsafe fn run<S: Simd>(self) {
        let Self { src, dst } = self;
        for i0 in (0..dst.len()).step_by(S::LANES) {
            let lanes = S::LANES.min(dst.len() - i0);
            // SAFETY: the CPU has S's features; the loads read src[2·i0 ..][..2·lanes − 1],
            // inside src by the contract; the store writes dst[i0 ..][..lanes].
            unsafe {
                let v = S::load_even(src.as_ptr().add(2 * i0), lanes);
                let at = dst.as_mut_ptr().add(i0);
                if lanes == S::LANES {
                    S::store(at, v);
                } else {
                    S::store_masked(S::mask(lanes), at, v);
                }
            }
        }
    }
}
