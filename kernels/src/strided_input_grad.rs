//! Input gradients of strided convolutions on the register tiles of [`crate::conv_tiles`], by
//! the polyphase decomposition of a transposed convolution.
//!
//! Along one axis, a convolution of stride `s`, kernel `k` and padding `p` reads input position
//! `i = s·o + a − p` with tap `a` for output `o`. Its input gradient at `i = s·q + r` (phase
//! `r < s`) therefore gathers only the taps `a ≡ r + p (mod s)`: `a = a₀ + s·t` with
//! `a₀ = (r + p) mod s`, `t = 0 … T_r − 1`, each reading `dy` at `o = q + d_r − t` where
//! `d_r = ⌊(r + p)/s⌋`:
//!
//! ```text
//! dx[s·q + r] = Σ_t W[a₀ + s·t] · dy[q + d_r − t]
//! ```
//!
//! a stride-1 correlation of `dy` with the phase's `T_r`-tap sub-kernel, flipped. In 2-D the
//! `s²` phases of `dx` are `s²` such correlations, together `kh·kw` taps per input channel
//! (the FLOP of the forward, where zero-insertion into `dy` would do `s²` times as many and
//! im2col + `gemm` + col2im copies every product through a `kh·kw`-row column matrix). Each
//! phase runs on `conv_tiles::run_tiles` over one padded copy of `dy` that every phase
//! reads at its own offset (`dy` positions outside the output wrap, for circular padding, or
//! are zeros), and its results are interleaved into `dx`. This is the decomposition of
//! transposed convolutions into stride-1 ones used by deconvolution layers (Shi et al., "Is
//! the deconvolution layer the same as a convolutional layer?", 2016) and by
//! [`crate::conv_grad`] on candle's own `conv2d`.
//!
//! Circular padding wraps `dy` with period `H_out`, which is the forward's wrap only when the
//! input is exactly `s` outputs per position (`H = s·H_out`, as in the estimator's 4×4 stride-2
//! encoder); other circular geometries, phases without a tap (`k < s`), and phase rows shorter
//! than one vector stay on im2col (`supports`).

use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::conv_geometry::Geometry;
use crate::conv_tiles::{self, MIN_BAND_ROWS, PAD_BAND_BYTES, TileGrid};
use crate::simd::{Simd, SimdFamily, on_family};

/// Bytes of the phases' results one task holds before merging them into `dx`: half of this
/// VM's 2 MiB L2, so that the merge reads them from cache, not memory.
const PHASE_BAND_BYTES: usize = 1 << 20;

/// Phase `r` of one axis: input positions `r, r + s, …` below the axis length.
#[derive(Clone, Copy, Debug, PartialEq)]
struct AxisPhase {
    /// Kernel index of the phase's first tap; its taps are `first, first + s, …` below `k`.
    first: usize,
    /// Taps of the phase, `T_r ≥ 1`.
    taps: usize,
    /// Input positions of the phase: `⌈(n − r)/s⌉`.
    len: usize,
    /// Padded `dy` position its flipped tap 0 (kernel index `first + s·(taps − 1)`) reads for
    /// phase position 0: `before + d_r − (T_r − 1)`.
    lead: usize,
}

/// The phases of one axis and the padded copy of `dy` they read.
#[derive(Clone, Debug, PartialEq)]
struct AxisPlan {
    /// Phases `0..s` (fewer when the axis is shorter than the stride).
    phases: Vec<AxisPhase>,
    /// `dy` positions padded before the first: padded position `j` holds `dy[j − before]`.
    before: usize,
    /// Padded positions some phase reads: `0..len`.
    len: usize,
    /// Output positions along the axis.
    n_out: usize,
}

impl AxisPlan {
    /// The plan of an axis of `n` input and `n_out` output positions, kernel `k`, stride `s`,
    /// padding `p`; `None` when a phase has no tap.
    fn new(n: usize, n_out: usize, k: usize, s: usize, p: usize) -> Option<Self> {
        // (first tap, taps, positions, d_r) of each phase.
        let mut raw = Vec::with_capacity(s);
        for r in 0..s.min(n) {
            let first = (r + p) % s;
            if first >= k {
                return None;
            }
            raw.push((
                first,
                (k - 1 - first) / s + 1,
                (n - r).div_ceil(s),
                (r + p) / s,
            ));
        }
        // Phase r reads dy[d_r − (T_r − 1)] first (position 0) and dy[len_r − 1 + d_r] last.
        let before = raw
            .iter()
            .map(|&(_, t, _, d)| (t - 1).saturating_sub(d))
            .max()?;
        let len = before + raw.iter().map(|&(_, _, len, d)| len + d).max()?;
        let phases = raw
            .into_iter()
            .map(|(first, taps, len, d)| AxisPhase {
                first,
                taps,
                len,
                lead: before + d - (taps - 1),
            })
            .collect();
        Some(Self {
            phases,
            before,
            len,
            n_out,
        })
    }

    /// The `dy` position padded position `j` holds: wrapped when circular, `None` in zero
    /// padding.
    fn source(&self, j: usize, circular: bool) -> Option<usize> {
        let i = j as isize - self.before as isize;
        if (0..self.n_out as isize).contains(&i) {
            Some(i as usize)
        } else if circular {
            Some(i.rem_euclid(self.n_out as isize) as usize)
        } else {
            None
        }
    }
}

/// The row and column plans of `g`'s input gradient, when [`input_grad`] computes it.
fn plans(g: &Geometry, family: SimdFamily) -> Option<(AxisPlan, AxisPlan)> {
    let s = g.stride;
    if s < 2 || family == SimdFamily::Scalar {
        return None;
    }
    // dy's wrap has period H_out: the forward's only when H = s·H_out (module docs).
    if g.circular && (g.h != s * g.ho || g.w != s * g.wo) {
        return None;
    }
    let rows = AxisPlan::new(g.h, g.ho, g.kh, s, g.pad)?;
    let cols = AxisPlan::new(g.w, g.wo, g.kw, s, g.pad)?;
    // Every phase row of dx holds at least one vector, as the forward's output rows must.
    cols.phases
        .iter()
        .all(|ph| ph.len >= family.lanes())
        .then_some((rows, cols))
}

/// Whether [`input_grad`] computes this (strided) convolution's input gradient on `family`.
pub(crate) fn supports(g: &Geometry, family: SimdFamily) -> bool {
    plans(g, family).is_some()
}

/// Input gradient of a strided convolution: writes every element of `dx` (B·C_in·H·W) from
/// `dy` (B·C_out·H_out·W_out) and `w` (C_out·C_in·kh·kw), phase by phase (module docs).
/// Requires [`supports`].
pub(crate) fn input_grad(
    g: &Geometry,
    dy: &[f32],
    w: &[f32],
    dx: &mut [f32],
    on: (usize, SimdFamily),
) {
    // Threads, and the family the CPU has (the caller's [`SimdFamily::active`]).
    let (threads, family) = on;
    let (rows, cols) = plans(g, family).expect("direct conv: unsupported strided input gradient");
    // Padded dy bytes per phase row of dx.
    let row_bytes = 4 * g.co * cols.len;
    // Bytes of the s² phases' results per phase row, before they are merged into dx.
    let out_bytes = 4 * g.ci * cols.len * rows.phases.len() * cols.phases.len();
    let nq = rows.phases[0].len;
    let mut band = (PAD_BAND_BYTES / row_bytes.max(1))
        .min(PHASE_BAND_BYTES / out_bytes.max(1))
        .max(MIN_BAND_ROWS);
    if threads > 1 && g.b < threads {
        band = band.min(nq.div_ceil(2 * threads));
    }
    let plans = (&rows, &cols);
    on_family!(family, S => run_in_bands::<S>(g, plans, dy, w, dx, band.clamp(1, nq)));
}

/// One phase's sub-kernel, flipped, packed in tile order for [`conv_tiles::run_tiles`]:
/// `OC_BLOCK` input channels of the forward (the phase's outputs), then rows
/// `(o·T_y + t')·T_x + u'` holding `W[o, c, first_y + s·(T_y − 1 − t'), first_x + s·(T_x − 1 − u')]`.
fn pack_phase<S: Simd>(g: &Geometry, w: &[f32], ry: AxisPhase, rx: AxisPhase) -> Vec<f32> {
    let s = g.stride;
    let taps = ry.taps * rx.taps;
    conv_tiles::pack_weights::<S>(g.ci, g.co * taps, |c, dst| {
        let mut dst = dst.iter_mut();
        for o in 0..g.co {
            let kernel = &w[(o * g.ci + c) * g.kh * g.kw..][..g.kh * g.kw];
            for t in (0..ry.taps).rev() {
                for u in (0..rx.taps).rev() {
                    let (ky, kx) = (ry.first + s * t, rx.first + s * u);
                    *dst.next().expect("a row of C_out · taps") = kernel[ky * g.kw + kx];
                }
            }
        }
    })
}

/// [`input_grad`] in bands of `band` phase rows `q` (dx rows `s·q .. s·q + s`): the (image,
/// band) pairs are the parallel tasks, each padding the `dy` rows its band reads once for
/// all `s²` phases.
fn run_in_bands<S: Simd>(
    g: &Geometry,
    (rows, cols): (&AxisPlan, &AxisPlan),
    dy: &[f32],
    w: &[f32],
    dx: &mut [f32],
    band: usize,
) {
    let s = g.stride;
    let (x_len, y_len) = (g.ci * g.h * g.w, g.co * g.ho * g.wo);
    // The tasks write through raw pointers: the gradient must be exactly the batch's.
    assert_eq!(dx.len(), g.b * x_len, "direct conv: dx of the wrong size");
    assert_eq!(dy.len(), g.b * y_len, "direct conv: dy of the wrong size");
    let row = cols.len;
    // (row phase, column phase, packed sub-kernel, tap offsets in the padded dy rows) of the
    // s² phases, phase (r_y, r_x) at r_y · s + r_x.
    type Phase = (AxisPhase, AxisPhase, Vec<f32>, Vec<usize>);
    let phases: Vec<Phase> = rows
        .phases
        .iter()
        .flat_map(|&ry| cols.phases.iter().map(move |&rx| (ry, rx)))
        .map(|(ry, rx)| {
            let taps = (0..ry.taps)
                .flat_map(|t| (0..rx.taps).map(move |u| t * row + u))
                .collect();
            (ry, rx, pack_phase::<S>(g, w, ry, rx), taps)
        })
        .collect();
    // A band of q rows reads padded dy rows q0 + lo .. q1 − 1 + hi.
    let lo = rows.phases.iter().map(|ph| ph.lead).min().unwrap_or(0);
    let hi = rows
        .phases
        .iter()
        .map(|ph| ph.lead + ph.taps)
        .max()
        .unwrap_or(0);
    let padded_rows = band - 1 + hi - lo;
    let plane_in = padded_rows * cols.len;
    let nq = rows.phases[0].len;
    let bands = nq.div_ceil(band);
    let dx_addr = dx.as_mut_ptr() as usize;
    // Floats of one phase's results: C_in planes of `band` rows of `row`.
    let phase_len = g.ci * band * row;
    let sx = cols.phases.len();
    (0..g.b * bands).into_par_iter().for_each_init(
        // SAFETY: `pad_band` writes every padded row a band reads, the tiles every phase
        // texel the merge reads (module docs), before they are read.
        || unsafe {
            (
                output_buffer::<f32>(g.co * plane_in),
                output_buffer::<f32>(phases.len() * phase_len),
            )
        },
        |(dyp, out), job| {
            let (i, q0) = (job / bands, (job % bands) * band);
            let q1 = (q0 + band).min(nq);
            let dyi = &dy[i * y_len..(i + 1) * y_len];
            pad_band(g, (rows, cols), dyi, q0 + lo..q1 - 1 + hi, padded_rows, dyp);
            for (p, (ry, rx, packed, taps)) in phases.iter().enumerate() {
                let count = q1.min(ry.len).saturating_sub(q0);
                if count == 0 {
                    continue;
                }
                // The band's phase rows as one flat row with the padded rows' stride: texel
                // qq·row + qx reads at the same offsets as (qq, qx), and the row − len_x
                // texels after each row are computed and dropped. Phase rows of 17 or 33
                // texels then cost 18 or 35 lanes, not 32 or 48 (a partial vector per row).
                let grid = TileGrid {
                    ci: g.co,
                    plane_in,
                    taps,
                    in_base: (ry.lead - lo) * row + rx.lead,
                    in_row: 0,
                    co: g.ci,
                    plane_out: band * row,
                    rows: 1,
                    wo: (count - 1) * row + rx.len,
                    out_base: 0,
                };
                let out_p = out[p * phase_len..].as_mut_ptr() as usize;
                // SAFETY: `out` holds phase p's C_in planes of `band · row` floats, written only
                // by this task; `dyp` holds every padded row and column the phase reads
                // (`AxisPlan`), and a dropped texel reads at most `row − len_x` floats past
                // its row, inside the next padded row.
                unsafe { conv_tiles::run_tiles::<S>(&grid, dyp, packed, out_p) };
            }
            // dx rows s·q0 .. s·q1 of image i, each interleaving the lines of its row phase's
            // column phases: row by row, so that every dx row is written once, whole.
            let rows_end = (q1 * s).min(g.h);
            for c in 0..g.ci {
                for dx_row in q0 * s..rows_end {
                    let (qq, r_y) = (dx_row / s - q0, dx_row % s);
                    let line = |r_x: usize| {
                        let p = r_y * sx + r_x;
                        &out[p * phase_len + (c * band + qq) * row..][..cols.phases[r_x].len]
                    };
                    let start = i * x_len + (c * g.h + dx_row) * g.w;
                    // SAFETY: dx outlives the tasks; task (i, band) writes only rows
                    // s·q0 .. s·q1 of image i, which no other task writes.
                    let dst = unsafe {
                        std::slice::from_raw_parts_mut((dx_addr as *mut f32).add(start), g.w)
                    };
                    interleave(dst, s, line);
                }
            }
        },
    );
}

/// Writes `dst[s·q + r] = line(r)[q]` for every element of `dst`: the `s` column phases of
/// one dx row merged (`line(r)` holds `⌈(W − r)/s⌉` floats). Stride 2, every strided layer
/// here, pairs the two lines so that the compiler can vectorise the merge.
fn interleave<'a>(dst: &mut [f32], s: usize, line: impl Fn(usize) -> &'a [f32]) {
    if s == 2 {
        let (even, odd) = (line(0), line(1));
        for (pair, (&a, &b)) in dst.chunks_exact_mut(2).zip(even.iter().zip(odd)) {
            pair[0] = a;
            pair[1] = b;
        }
        if dst.len() % 2 == 1 {
            dst[dst.len() - 1] = even[even.len() - 1];
        }
        return;
    }
    for r in 0..s {
        for (d, &v) in dst[r..].iter_mut().step_by(s).zip(line(r)) {
            *d = v;
        }
    }
}

/// Copies padded `dy` rows `padded` (of one image's `dy`, C_out·H_out·W_out) into `dyp`,
/// `held` rows of [`AxisPlan::len`] floats per channel, wrapped or zero-filled as `g`'s padding
/// says.
fn pad_band(
    g: &Geometry,
    (rows, cols): (&AxisPlan, &AxisPlan),
    dy: &[f32],
    padded: std::ops::Range<usize>,
    held: usize,
    dyp: &mut [f32],
) {
    let row = cols.len;
    let col_source: Vec<Option<usize>> = (0..row).map(|j| cols.source(j, g.circular)).collect();
    // The padded columns holding dy's own columns in order, copied as one slice.
    let inner = cols.before.min(row)..(cols.before + g.wo).min(row);
    for o in 0..g.co {
        let plane = &dy[o * g.ho * g.wo..(o + 1) * g.ho * g.wo];
        for (r, j) in padded.clone().enumerate() {
            let dst = &mut dyp[(o * held + r) * row..][..row];
            match rows.source(j, g.circular) {
                None => dst.fill(0.0),
                Some(iy) => {
                    let src = &plane[iy * g.wo..(iy + 1) * g.wo];
                    dst[inner.clone()].copy_from_slice(&src[..inner.len()]);
                    for jx in (0..inner.start).chain(inner.end..row) {
                        dst[jx] = col_source[jx].map_or(0.0, |ix| src[ix]);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Result, Tensor};

    use super::*;
    use crate::conv::apply_input_grad;
    use crate::conv_geometry::{Conv2dSpec, PaddingMode};
    use crate::simd::vector_families;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    #[test]
    fn axis_plans_read_the_taps_of_each_phase() {
        // The discriminator's 3×3 stride 2 after its blur, 33 → 16: even inputs 2q take taps
        // 0 and 2 (dy[q] and dy[q − 1]), odd ones tap 1 (dy[q]); dy[−1] is padding.
        let d = AxisPlan::new(33, 16, 3, 2, 0).unwrap();
        assert_eq!((d.before, d.len), (1, 18));
        let even = AxisPhase {
            first: 0,
            taps: 2,
            len: 17,
            lead: 0,
        };
        let odd = AxisPhase {
            first: 1,
            taps: 1,
            len: 16,
            lead: 1,
        };
        assert_eq!(d.phases, vec![even, odd]);
        // The estimator's 4×4 stride 2 padding 1, 32 → 16: every phase has 2 taps, reading
        // dy[q − 1], dy[q] (even) and dy[q], dy[q + 1] (odd), wrapped when circular.
        let e = AxisPlan::new(32, 16, 4, 2, 1).unwrap();
        assert_eq!((e.before, e.len), (1, 18));
        assert_eq!(
            e.phases
                .iter()
                .map(|p| (p.first, p.taps, p.lead))
                .collect::<Vec<_>>(),
            [(1, 2, 0), (0, 2, 1)]
        );
        assert_eq!((e.source(0, true), e.source(17, true)), (Some(15), Some(0)));
        assert_eq!((e.source(0, false), e.source(1, false)), (None, Some(0)));
        // A 1×1 kernel of stride 2 never reaches odd inputs.
        assert!(AxisPlan::new(32, 16, 1, 2, 0).is_none());
    }

    #[test]
    fn strided_input_gradient_in_bands_equals_the_whole_image() -> Result<()> {
        // 17 phase rows (33 input rows) in bands of 3, the last of 2: each band pads its own
        // dy rows, zero or wrapped, and writes only its s rows per phase row.
        let dev = Device::Cpu;
        for family in vector_families() {
            for (h, pad, k) in [(33, 0, 3), (32, 1, 4)] {
                for spec in [Conv2dSpec::zeros(2, pad), Conv2dSpec::circular(2, pad)] {
                    let g = Geometry::new((2, 3, h, 40), (5, 3, k, k), spec)?;
                    let Some(plans) = plans(&g, family) else {
                        assert!(spec.mode == PaddingMode::Circular && h == 33);
                        continue;
                    };
                    let dy = pseudo_random(g.y_shape(), 21, DType::F32, &dev)?;
                    let wt = pseudo_random((5, 3, k, k), 22, DType::F32, &dev)?;
                    let (dyv, wv) = (
                        dy.flatten_all()?.to_vec1::<f32>()?,
                        wt.flatten_all()?.to_vec1::<f32>()?,
                    );
                    let run = |band: usize| {
                        let mut dx = vec![f32::NAN; 2 * 3 * h * 40];
                        let plans = (&plans.0, &plans.1);
                        on_family!(family, S => {
                            run_in_bands::<S>(&g, plans, &dyv, &wv, &mut dx, band)
                        });
                        dx
                    };
                    let (whole, banded) = (run(17), run(3));
                    // Same sums in the same order: equal to the bit.
                    assert_eq!(whole, banded, "{family:?} {spec:?} {h}");
                    let reference =
                        apply_input_grad(g, &dy.to_dtype(DType::F64)?, &wt.to_dtype(DType::F64)?)?;
                    let banded =
                        Tensor::from_vec(banded, (2, 3, h, 40), &dev)?.to_dtype(DType::F64)?;
                    let err = max_abs_diff(&banded, &reference)?;
                    assert!(err < 1e-4, "{family:?} {spec:?} {h}: {err}");
                }
            }
        }
        Ok(())
    }
}
