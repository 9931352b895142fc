//! The periodic interior of a FIR width pass: the rows of [`crate::fir`]'s band form that
//! repeat, computed a vector of outputs at a time (16 on AVX-512, 8 on AVX2) instead of one
//! dot product per output.
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
//! is, per tap, one multiply-add of a vector of consecutive `m` at a time: shift 1 reads
//! consecutive floats, shift 2 the even lanes of two vectors' worth, and period 2 interleaves
//! its two phases' vectors into twice as many consecutive outputs. Written once over
//! `Simd`. The rows
//! are short (17–65 outputs in the discriminator), so nothing is allocated per row and the
//! last vector is masked. Slice loops the compiler vectorised on its own were slower than
//! the scalar dot products (`docs/benchmarks/conv-kernels.md`, "Strided input gradients on the
//! direct kernels", tried and not adopted): the baseline x86-64 target vectorises only 4 wide, and
//! the per-row setup ate the rest.

use crate::simd::{Kernel, Simd, SimdFamily, on_family};

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
    /// The vector family [`Periodic::run`] runs on.
    family: SimdFamily,
}

impl Periodic {
    /// The longest periodic run around the middle row of a band (`first[j]`, the first column
    /// of row `j`, `usize::MAX` for a row outside the band form; `weights[j·taps..]`, its
    /// weights), to run on `family`, or `None` when there is none long enough, the band is
    /// wider than [`MAX_TAPS`], or `family` is [`SimdFamily::Scalar`].
    pub(crate) fn find(
        first: &[usize],
        weights: &[f32],
        taps: usize,
        family: SimdFamily,
    ) -> Option<Self> {
        if taps == 0 || taps > MAX_TAPS || family == SimdFamily::Scalar {
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
                family,
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
        // SAFETY: `find` returned Some only for a vector family, one the CPU has (the
        // caller's [`SimdFamily::active`]); the assertion keeps every read and write inside the
        // row (`Row`).
        on_family!(self.family, S => unsafe { S::vectorize(Row { p: self, x, out }) });
    }
}

/// [`Periodic::run`]'s vectors, as a [`Kernel`]: every phase's reads `x[first_r .. first_r +
/// shift·(count − 1) + taps]` and the writes `out[lo .. lo + period·count]` are inside the
/// slices.
struct Row<'a> {
    p: &'a Periodic,
    x: &'a [f32],
    out: &'a mut [f32],
}

impl Kernel for Row<'_> {
    type Output = ();

    #[inline(always)]
    unsafe fn run<S: Simd>(self) {
        let Row { p, x, out } = self;
        let xp = x.as_ptr();
        // SAFETY (every block below): the CPU has S's features; loads and stores touch only
        // masked lanes inside the slices (the contract).
        let op = unsafe { out.as_mut_ptr().add(p.lo) };
        for m0 in (0..p.count).step_by(S::LANES) {
            let lanes = S::LANES.min(p.count - m0);
            unsafe {
                if p.period == 1 {
                    S::store_masked(S::mask(lanes), op.add(m0), phase::<S>(p, xp, 0, m0, lanes));
                } else {
                    let (lo, hi) = S::interleave(
                        phase::<S>(p, xp, 0, m0, lanes),
                        phase::<S>(p, xp, 1, m0, lanes),
                    );
                    let n = 2 * lanes;
                    S::store_masked(S::mask(n), op.add(2 * m0), lo);
                    if n > S::LANES {
                        S::store_masked(S::mask(n - S::LANES), op.add(2 * m0 + S::LANES), hi);
                    }
                }
            }
        }
    }
}

/// Phase `r`'s sums of a run for `m = m0 … m0 + lanes − 1` (a function, not a closure, so
/// that it is inlined into [`Row::run`] and compiled with its family's features).
///
/// # Safety
/// As [`Row::run`]'s.
#[inline(always)]
unsafe fn phase<S: Simd>(p: &Periodic, xp: *const f32, r: usize, m0: usize, lanes: usize) -> S::V {
    // SAFETY (every block): the caller's.
    let mut acc = unsafe { S::zero() };
    for t in 0..p.taps {
        let w = unsafe { S::splat(p.weights[r][t]) };
        let at = p.first[r] + t + p.shift * m0;
        let v = unsafe {
            if p.shift == 1 {
                S::load_masked(S::mask(lanes), xp.add(at))
            } else {
                S::load_even(xp.add(at), lanes)
            }
        };
        // Multiply, then add: rounded as the scalar dot products of the edge rows, so that a
        // row's value does not depend on whether it falls in the run (rolling a tileable
        // generator's input by whole cells rolls its output exactly).
        acc = unsafe { S::add(S::mul(v, w), acc) };
    }
    acc
}
