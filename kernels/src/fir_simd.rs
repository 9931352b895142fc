//! The periodic interior of a FIR width pass on AVX-512: the rows of [`crate::fir`]'s band form
//! that repeat, computed 16 outputs per vector instead of one dot product per output.
//!
//! StyleGAN2's `[1, 3, 3, 1]` filters (Karras et al. 2020, Appendix B) give axis matrices whose
//! rows, away from the edges, repeat with a period of 1 or 2 outputs and move 1 or 2 input
//! columns per period: the blur (period 1, shift 1), ×2 downsampling (1, 2) and the transposes
//! of ×2 down- and upsampling (2, 1), which the backward passes run. Row `lo + r + period·m`
//! of such a run has row `lo + r`'s weights and starts `shift·m` columns later, so that per
//! phase `r`
//!
//! ```text
//! out[lo + r + period·m] = Σ_t w_r[t] · x[first_r + t + shift·m]     (m = 0 … count − 1)
//! ```
//!
//! is, per tap, one multiply-add of 16 consecutive `m` at a time: shift 1 reads 16
//! consecutive floats, shift 2 the even lanes of 32 (one two-source permute), and period 2
//! interleaves its two phases' vectors into 32 consecutive outputs (two permutes). The rows
//! are short (17–65 outputs in the discriminator), so nothing is allocated per row and the
//! last vector is masked. Slice loops the compiler vectorised on its own were slower than
//! the scalar dot products (`docs/benchmarks/conv-kernels.md`, "Strided input gradients on the
//! direct kernels", tried and not adopted): the baseline x86-64 target vectorises only 4 wide, and
//! the per-row setup ate the rest.

use crate::avx512::{LANES, has_avx512, lane_mask};

/// Widest band the interior runs: the `[1, 3, 3, 1]` filter's 4 taps.
pub(crate) const MAX_TAPS: usize = 4;
/// Fewest outputs per phase for which the interior pays over per-output dot products.
const MIN_COUNT: usize = 8;

/// A run of rows that repeat (module docs), with its phases' first columns and weights
/// (zeros past the band's `taps`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Periodic {
    pub(crate) lo: usize,
    pub(crate) period: usize,
    pub(crate) shift: usize,
    pub(crate) count: usize,
    taps: usize,
    first: [usize; 2],
    weights: [[f32; MAX_TAPS]; 2],
}

impl Periodic {
    /// The longest periodic run around the middle row of a band (`first[j]`, the first column
    /// of row `j`, `usize::MAX` for a row outside the band form; `weights[j·taps..]`, its
    /// weights), or `None` when there is none long enough, the band is wider than
    /// [`MAX_TAPS`], or the CPU lacks AVX-512F.
    pub(crate) fn find(first: &[usize], weights: &[f32], taps: usize) -> Option<Self> {
        if taps == 0 || taps > MAX_TAPS || !has_avx512() {
            return None;
        }
        let n = first.len();
        let row = |j: usize| &weights[j * taps..(j + 1) * taps];
        let mid = n / 2;
        for period in [1, 2] {
            if mid + period >= n || first[mid] == usize::MAX || first[mid + period] == usize::MAX {
                continue;
            }
            let shift = first[mid + period].wrapping_sub(first[mid]);
            if !(1..=2).contains(&shift) {
                continue;
            }
            // Rows j and j + period of one phase: the same weights, `shift` columns apart.
            let regular = |j: usize| {
                first[j] != usize::MAX
                    && first[j + period] == first[j].wrapping_add(shift)
                    && row(j) == row(j + period)
            };
            if !regular(mid) {
                continue;
            }
            let (mut lo, mut end) = (mid, mid + 1);
            while lo > 0 && regular(lo - 1) {
                lo -= 1;
            }
            while end + period < n && regular(end) {
                end += 1;
            }
            // Rows lo .. end + period belong to the phases of rows lo .. lo + period.
            let count = (end + period - lo) / period;
            if count < MIN_COUNT {
                continue;
            }
            let mut w = [[0.0; MAX_TAPS]; 2];
            let mut f = [0; 2];
            for r in 0..period {
                w[r][..taps].copy_from_slice(row(lo + r));
                f[r] = first[lo + r];
            }
            return Some(Self {
                lo,
                period,
                shift,
                count,
                taps,
                first: f,
                weights: w,
            });
        }
        None
    }

    /// The output columns the run writes.
    pub(crate) fn rows(&self) -> std::ops::Range<usize> {
        self.lo..self.lo + self.period * self.count
    }

    /// Writes `out[self.rows()]` of one row from its input row `x`.
    pub(crate) fn run(&self, x: &[f32], out: &mut [f32]) {
        let last = self.first[self.period - 1] + self.shift * (self.count - 1) + self.taps;
        assert!(
            last <= x.len() && self.rows().end <= out.len(),
            "periodic FIR run outside its row"
        );
        // SAFETY: `find` returned Some only with AVX-512F; the assertion keeps every read and
        // write inside the row (`row_avx512`).
        #[cfg(target_arch = "x86_64")]
        unsafe {
            row_avx512(self, x, out)
        }
        #[cfg(not(target_arch = "x86_64"))]
        unreachable!("AVX-512 only: Periodic::find returns None on this architecture")
    }
}

/// [`Periodic::run`]'s vectors.
///
/// # Safety
/// AVX-512F is available; every phase's reads `x[first_r .. first_r + shift·(count − 1) +
/// taps]` and the writes `out[lo .. lo + period·count]` are inside the slices.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn row_avx512(p: &Periodic, x: &[f32], out: &mut [f32]) {
    use std::arch::x86_64::*;
    let xp = x.as_ptr();
    let op = unsafe { out.as_mut_ptr().add(p.lo) };
    // The interleave of (a, b): a0 b0 a1 b1 …
    let low = _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
    let high = _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
    // Phase r's 16 sums for m = m0 … m0 + lanes − 1.
    let phase = |r: usize, m0: usize, lanes: usize| -> __m512 {
        let mut acc = _mm512_setzero_ps();
        for t in 0..p.taps {
            let w = _mm512_set1_ps(p.weights[r][t]);
            let at = p.first[r] + t + p.shift * m0;
            // SAFETY: the loads read only masked lanes, inside x (the caller's contract).
            let v = unsafe {
                if p.shift == 1 {
                    _mm512_maskz_loadu_ps(lane_mask(lanes), xp.add(at))
                } else {
                    crate::avx512::load_even_lanes(xp.add(at), lanes)
                }
            };
            // Multiply, then add: rounded as the scalar dot products of the edge rows, so that
            // a row's value does not depend on whether it falls in the run (rolling a tileable
            // generator's input by whole cells rolls its output exactly).
            acc = _mm512_add_ps(_mm512_mul_ps(v, w), acc);
        }
        acc
    };
    for m0 in (0..p.count).step_by(LANES) {
        let lanes = LANES.min(p.count - m0);
        // SAFETY: the stores write only masked lanes, inside out (the caller's contract).
        unsafe {
            if p.period == 1 {
                _mm512_mask_storeu_ps(op.add(m0), lane_mask(lanes), phase(0, m0, lanes));
            } else {
                let (a, b) = (phase(0, m0, lanes), phase(1, m0, lanes));
                let n = 2 * lanes;
                _mm512_mask_storeu_ps(
                    op.add(2 * m0),
                    lane_mask(n),
                    _mm512_permutex2var_ps(a, low, b),
                );
                if n > LANES {
                    let hi = _mm512_permutex2var_ps(a, high, b);
                    _mm512_mask_storeu_ps(op.add(2 * m0 + LANES), lane_mask(n - LANES), hi);
                }
            }
        }
    }
}
