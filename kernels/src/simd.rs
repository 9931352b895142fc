//! The vector instruction families this crate's hand-written kernels are compiled for, and
//! which one runs.
//!
//! The direct convolutions ([`crate::direct_conv`], [`crate::strided_input_grad`],
//! [`crate::direct_weight_grad`]), the padded input copy ([`crate::padded_input`]) and the FIR
//! passes ([`crate::fir`], [`crate::fir_simd`]) are written once, over the `Simd` trait of
//! this module, and compiled for each family:
//!
//! - [`SimdFamily::Avx512`]: AVX-512F, 16 f32 lanes, 32 vector registers, lane masks;
//! - [`SimdFamily::Avx2`]: AVX2 with FMA, 8 lanes, 16 registers (most desktops, laptops and
//!   cloud VMs without AVX-512);
//! - [`SimdFamily::Scalar`]: no hand-written vector kernels (convolutions on im2col + `gemm`,
//!   the FIR passes' scalar loops), the path of other CPUs.
//!
//! A kernel is a `Kernel` whose `run::<S>()` is inlined into one function per family
//! compiled with that family's target features (`Simd::vectorize`): the same pattern as the
//! `pulp` crate's `WithSimd`, which `gemm` builds on. pulp itself is not used: its masked
//! loads and stores jump through an assembly table with fixed registers, and the tiles here
//! mask a row's last vector in their innermost loop.
//!
//! **Which family runs.** [`SimdFamily::active`]: the widest the CPU has, unless the
//! environment variable `PHOTOMAT_SIMD` (`avx512`, `avx2` or `scalar`, read once per process)
//! asks for a narrower one, or the calling thread is inside [`with_simd_family`] (tests that
//! run the AVX2 kernels on an AVX-512 machine). A family wider than the CPU's is never run:
//! the request is capped at [`SimdFamily::detected`]. Ops read the family once, on the
//! thread that applies them, and hand it to their rayon tasks. `gemm` (im2col's products, the
//! per-texel MLP, candle's matmul) chooses its own kernels, AVX-512 wherever the CPU has it,
//! and has no switch for that (`docs/benchmarks/cpu-kernels.md`).

use std::cell::Cell;
use std::sync::OnceLock;

/// A family of vector kernels, ordered from the narrowest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum SimdFamily {
    /// No hand-written vector kernels.
    Scalar,
    /// AVX2 + FMA, 8 f32 lanes.
    Avx2,
    /// AVX-512F, 16 f32 lanes.
    Avx512,
}

/// The environment variable that caps the family (read once per process).
pub const SIMD_VAR: &str = "PHOTOMAT_SIMD";

impl SimdFamily {
    /// Every family, narrowest first.
    pub const ALL: [SimdFamily; 3] = [SimdFamily::Scalar, SimdFamily::Avx2, SimdFamily::Avx512];

    /// The name `PHOTOMAT_SIMD` takes and reports print.
    pub fn name(self) -> &'static str {
        match self {
            SimdFamily::Scalar => "scalar",
            SimdFamily::Avx2 => "avx2",
            SimdFamily::Avx512 => "avx512",
        }
    }

    /// The family of a name ([`SimdFamily::name`]), case-insensitive.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The widest family this CPU runs (detected once).
    pub fn detected() -> Self {
        static DETECTED: OnceLock<SimdFamily> = OnceLock::new();
        *DETECTED.get_or_init(|| {
            #[cfg(target_arch = "x86_64")]
            {
                if std::arch::is_x86_feature_detected!("avx512f") {
                    return SimdFamily::Avx512;
                }
                if std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
                {
                    return SimdFamily::Avx2;
                }
            }
            SimdFamily::Scalar
        })
    }

    /// The family of this process: `PHOTOMAT_SIMD` capped at [`SimdFamily::detected`], else
    /// the detected one. An unknown value is reported once on stderr and ignored.
    pub fn of_process() -> Self {
        static PROCESS: OnceLock<SimdFamily> = OnceLock::new();
        *PROCESS.get_or_init(|| {
            let detected = Self::detected();
            let Some(value) = std::env::var_os(SIMD_VAR) else {
                return detected;
            };
            let value = value.to_string_lossy();
            match Self::parse(&value) {
                Some(asked) => asked.min(detected),
                None => {
                    eprintln!(
                        "photomat: {SIMD_VAR}={value:?} is none of avx512, avx2, scalar; \
                         running the {} kernels",
                        detected.name()
                    );
                    detected
                }
            }
        })
    }

    /// The family ops applied on this thread use now: the thread's [`with_simd_family`]
    /// setting, else [`SimdFamily::of_process`].
    pub fn active() -> Self {
        OVERRIDE.with(Cell::get).unwrap_or_else(Self::of_process)
    }

    /// f32 lanes of one vector (1 for [`SimdFamily::Scalar`]).
    pub fn lanes(self) -> usize {
        match self {
            SimdFamily::Scalar => 1,
            SimdFamily::Avx2 => 8,
            SimdFamily::Avx512 => 16,
        }
    }
}

thread_local! {
    static OVERRIDE: Cell<Option<SimdFamily>> = const { Cell::new(None) };
}

/// Runs `f` with this crate's ops on `family` (capped at [`SimdFamily::detected`]) on this
/// thread, then restores the previous setting (also when `f` panics). Returns the family that
/// ran and `f`'s result.
pub fn with_simd_family<R>(family: SimdFamily, f: impl FnOnce() -> R) -> (SimdFamily, R) {
    struct Restore(Option<SimdFamily>);
    impl Drop for Restore {
        fn drop(&mut self) {
            OVERRIDE.with(|o| o.set(self.0));
        }
    }
    let ran = family.min(SimdFamily::detected());
    let _restore = Restore(OVERRIDE.with(|o| o.replace(Some(ran))));
    (ran, f())
}

/// A kernel written once over [`Simd`]: [`Simd::vectorize`] inlines `run` into a function
/// compiled for the family, so every impl marks `run` `#[inline(always)]`.
pub(crate) trait Kernel {
    type Output;
    /// # Safety
    /// The CPU has `S`'s target features (the caller's [`Simd::vectorize`]), and whatever the
    /// kernel's own contract asks.
    unsafe fn run<S: Simd>(self) -> Self::Output;
}

/// One family's f32 vector operations, for the kernels of this crate.
///
/// # Safety
/// Every method requires the family's target features; call them only inside a
/// [`Kernel::run`] that [`Simd::vectorize`] runs. Pointer arguments follow the intrinsics'
/// rules (unaligned access is fine; masked lanes are neither read nor written).
pub(crate) trait Simd: Copy + Send + Sync + 'static {
    /// f32 lanes of one vector.
    const LANES: usize;
    /// Output channels per register tile of the direct convolutions ([`crate::conv_tiles`]).
    const OC_BLOCK: usize;
    /// Vectors of output texels per register tile: `OC_BLOCK × TILE_VECTORS` accumulators,
    /// plus `TILE_VECTORS` input vectors and one broadcast weight, within the registers.
    const TILE_VECTORS: usize;
    /// Input channels per weight-gradient tile ([`crate::direct_weight_grad`]).
    const WG_CHANNELS: usize;
    /// Vectors of output channels per weight-gradient tile.
    const WG_VECTORS: usize;

    type V: Copy;
    type Mask: Copy;

    /// Runs `kernel` compiled with the family's target features.
    ///
    /// # Safety
    /// The CPU has them ([`SimdFamily::detected`] is at least [`Self::FAMILY`]).
    unsafe fn vectorize<K: Kernel>(kernel: K) -> K::Output;

    /// The mask of the first `lanes` lanes (all from `lanes ≥ LANES`).
    unsafe fn mask(lanes: usize) -> Self::Mask;
    unsafe fn zero() -> Self::V;
    unsafe fn splat(v: f32) -> Self::V;
    unsafe fn load(at: *const f32) -> Self::V;
    /// The masked lanes of `at`, zeros elsewhere.
    unsafe fn load_masked(mask: Self::Mask, at: *const f32) -> Self::V;
    unsafe fn store(at: *mut f32, v: Self::V);
    unsafe fn store_masked(mask: Self::Mask, at: *mut f32, v: Self::V);
    /// `a · b + c`, rounded once.
    unsafe fn fmadd(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    unsafe fn add(a: Self::V, b: Self::V) -> Self::V;
    unsafe fn mul(a: Self::V, b: Self::V) -> Self::V;
    /// `at[0], at[2], …, at[2·(lanes − 1)]` in the first `lanes` (≤ LANES) lanes, zeros
    /// after; reads only `at[..2·lanes − 1]`.
    unsafe fn load_even(at: *const f32, lanes: usize) -> Self::V;
    /// `(a₀ b₀ a₁ b₁ …)`: the first `LANES` values of the interleave of `a` and `b`, then the
    /// last `LANES`.
    unsafe fn interleave(a: Self::V, b: Self::V) -> (Self::V, Self::V);
}

/// Evaluates `$body` with the type `$S` standing for `$family`'s [`Simd`] implementation
/// (panics for [`SimdFamily::Scalar`], which has none): how code generic over the family is
/// entered from a family chosen at run time.
macro_rules! on_family {
    ($family:expr, $S:ident => $body:expr) => {
        match $family {
            #[cfg(target_arch = "x86_64")]
            $crate::simd::SimdFamily::Avx512 => {
                type $S = $crate::simd::Avx512;
                $body
            }
            #[cfg(target_arch = "x86_64")]
            $crate::simd::SimdFamily::Avx2 => {
                type $S = $crate::simd::Avx2;
                $body
            }
            family => unreachable!("no vector kernels for the {family:?} family"),
        }
    };
}
pub(crate) use on_family;

/// The vector families this CPU runs, narrowest first: what tests run every kernel family on
/// (forced dispatch, so that an AVX-512 machine tests the AVX2 kernels too). Says on stderr
/// which families it leaves out.
#[cfg(test)]
pub(crate) fn vector_families() -> Vec<SimdFamily> {
    let (run, skip): (Vec<_>, Vec<_>) = [SimdFamily::Avx2, SimdFamily::Avx512]
        .into_iter()
        .partition(|&f| f <= SimdFamily::detected());
    if !skip.is_empty() {
        eprintln!("this CPU lacks {skip:?}: those kernels are not tested here");
    }
    run
}

#[cfg(target_arch = "x86_64")]
pub(crate) use x86::{Avx2, Avx512};

#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;

    use super::{Kernel, Simd};

    /// AVX-512F.
    #[derive(Clone, Copy)]
    pub(crate) struct Avx512;

    /// AVX2 + FMA.
    #[derive(Clone, Copy)]
    pub(crate) struct Avx2;

    impl Simd for Avx512 {
        const LANES: usize = 16;
        // 6 × 4 = 24 accumulators + 4 inputs + 1 weight of 32 registers.
        const OC_BLOCK: usize = 6;
        const TILE_VECTORS: usize = 4;
        const WG_CHANNELS: usize = 6;
        const WG_VECTORS: usize = 4;
        type V = __m512;
        type Mask = __mmask16;

        #[inline(always)]
        unsafe fn vectorize<K: Kernel>(kernel: K) -> K::Output {
            #[target_feature(enable = "avx512f")]
            unsafe fn compiled<K: Kernel>(kernel: K) -> K::Output {
                // SAFETY: the features are enabled; the kernel's contract is the caller's.
                unsafe { kernel.run::<Avx512>() }
            }
            // SAFETY: the caller's.
            unsafe { compiled(kernel) }
        }

        #[inline(always)]
        unsafe fn mask(lanes: usize) -> __mmask16 {
            if lanes >= 16 {
                u16::MAX
            } else {
                (1u16 << lanes) - 1
            }
        }
        #[inline(always)]
        unsafe fn zero() -> __m512 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm512_setzero_ps() }
        }
        #[inline(always)]
        unsafe fn splat(v: f32) -> __m512 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm512_set1_ps(v) }
        }
        #[inline(always)]
        unsafe fn load(at: *const f32) -> __m512 {
            unsafe { _mm512_loadu_ps(at) }
        }
        #[inline(always)]
        unsafe fn load_masked(mask: __mmask16, at: *const f32) -> __m512 {
            unsafe { _mm512_maskz_loadu_ps(mask, at) }
        }
        #[inline(always)]
        unsafe fn store(at: *mut f32, v: __m512) {
            unsafe { _mm512_storeu_ps(at, v) }
        }
        #[inline(always)]
        unsafe fn store_masked(mask: __mmask16, at: *mut f32, v: __m512) {
            unsafe { _mm512_mask_storeu_ps(at, mask, v) }
        }
        #[inline(always)]
        unsafe fn fmadd(a: __m512, b: __m512, c: __m512) -> __m512 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm512_fmadd_ps(a, b, c) }
        }
        #[inline(always)]
        unsafe fn add(a: __m512, b: __m512) -> __m512 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm512_add_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn mul(a: __m512, b: __m512) -> __m512 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm512_mul_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn load_even(at: *const f32, lanes: usize) -> __m512 {
            let needed = 2 * lanes - 1;
            // SAFETY: the family's features; the masked loads read only at[..needed] (the
            // caller's contract).
            unsafe {
                let even =
                    _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
                let a = Self::load_masked(Self::mask(needed), at);
                let b = Self::load_masked(Self::mask(needed.saturating_sub(16)), at.add(16));
                _mm512_permutex2var_ps(a, even, b)
            }
        }
        #[inline(always)]
        unsafe fn interleave(a: __m512, b: __m512) -> (__m512, __m512) {
            // SAFETY: the family's features (the trait's contract).
            unsafe {
                let low = _mm512_setr_epi32(0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23);
                let high =
                    _mm512_setr_epi32(8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31);
                (
                    _mm512_permutex2var_ps(a, low, b),
                    _mm512_permutex2var_ps(a, high, b),
                )
            }
        }
    }

    /// `MASKS[8 − n ..][..8]`: the first `n` lanes set (all bits), the others clear.
    static MASKS: [i32; 16] = [-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0];

    impl Simd for Avx2 {
        const LANES: usize = 8;
        // 5 × 2 = 10 accumulators + 2 inputs + 2 broadcast weights of 16 registers. 4 × 3
        // (12 + 3 + 1, all 16) spilled an accumulator to the stack in every iteration: the
        // compiler alternates two broadcast registers (docs/benchmarks/cpu-kernels.md).
        const OC_BLOCK: usize = 5;
        const TILE_VECTORS: usize = 2;
        const WG_CHANNELS: usize = 5;
        const WG_VECTORS: usize = 2;
        type V = __m256;
        type Mask = __m256i;

        #[inline(always)]
        unsafe fn vectorize<K: Kernel>(kernel: K) -> K::Output {
            #[target_feature(enable = "avx2,fma")]
            unsafe fn compiled<K: Kernel>(kernel: K) -> K::Output {
                // SAFETY: the features are enabled; the kernel's contract is the caller's.
                unsafe { kernel.run::<Avx2>() }
            }
            // SAFETY: the caller's.
            unsafe { compiled(kernel) }
        }

        #[inline(always)]
        unsafe fn mask(lanes: usize) -> __m256i {
            // SAFETY: 8 − min(lanes, 8) ∈ 0..=8, so the 8 values read lie in MASKS.
            unsafe { _mm256_loadu_si256(MASKS.as_ptr().add(8 - lanes.min(8)) as *const __m256i) }
        }
        #[inline(always)]
        unsafe fn zero() -> __m256 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm256_setzero_ps() }
        }
        #[inline(always)]
        unsafe fn splat(v: f32) -> __m256 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm256_set1_ps(v) }
        }
        #[inline(always)]
        unsafe fn load(at: *const f32) -> __m256 {
            unsafe { _mm256_loadu_ps(at) }
        }
        #[inline(always)]
        unsafe fn load_masked(mask: __m256i, at: *const f32) -> __m256 {
            unsafe { _mm256_maskload_ps(at, mask) }
        }
        #[inline(always)]
        unsafe fn store(at: *mut f32, v: __m256) {
            unsafe { _mm256_storeu_ps(at, v) }
        }
        #[inline(always)]
        unsafe fn store_masked(mask: __m256i, at: *mut f32, v: __m256) {
            unsafe { _mm256_maskstore_ps(at, mask, v) }
        }
        #[inline(always)]
        unsafe fn fmadd(a: __m256, b: __m256, c: __m256) -> __m256 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm256_fmadd_ps(a, b, c) }
        }
        #[inline(always)]
        unsafe fn add(a: __m256, b: __m256) -> __m256 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm256_add_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn mul(a: __m256, b: __m256) -> __m256 {
            // SAFETY: the family's features (the trait's contract).
            unsafe { _mm256_mul_ps(a, b) }
        }
        #[inline(always)]
        unsafe fn load_even(at: *const f32, lanes: usize) -> __m256 {
            let needed = 2 * lanes - 1;
            // SAFETY: the masked loads read only at[..needed] (the caller's contract).
            unsafe {
                let a = Self::load_masked(Self::mask(needed), at);
                let b = Self::load_masked(Self::mask(needed.saturating_sub(8)), at.add(8));
                // a0 a2 b0 b2 | a4 a6 b4 b6, then the 64-bit pairs in the order 0 2 1 3.
                let pairs = _mm256_shuffle_ps::<0b10_00_10_00>(a, b);
                _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(_mm256_castps_pd(
                    pairs,
                )))
            }
        }
        #[inline(always)]
        unsafe fn interleave(a: __m256, b: __m256) -> (__m256, __m256) {
            // a0 b0 a1 b1 | a4 b4 a5 b5 and a2 b2 a3 b3 | a6 b6 a7 b7, then their halves.
            // SAFETY: the family's features (the trait's contract).
            unsafe {
                let (lo, hi) = (_mm256_unpacklo_ps(a, b), _mm256_unpackhi_ps(a, b));
                (
                    _mm256_permute2f128_ps::<0x20>(lo, hi),
                    _mm256_permute2f128_ps::<0x31>(lo, hi),
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_requests_are_capped_at_the_cpu() {
        for f in SimdFamily::ALL {
            assert_eq!(SimdFamily::parse(f.name()), Some(f));
        }
        assert_eq!(SimdFamily::parse(" AVX2 "), Some(SimdFamily::Avx2));
        assert_eq!(SimdFamily::parse("sse"), None);
        let detected = SimdFamily::detected();
        assert!(SimdFamily::of_process() <= detected);
        for f in SimdFamily::ALL {
            let (ran, active) = with_simd_family(f, SimdFamily::active);
            assert_eq!(ran, f.min(detected));
            assert_eq!(active, ran);
        }
    }

    #[test]
    fn the_family_switch_is_scoped_and_per_thread() {
        let outer = SimdFamily::active();
        with_simd_family(SimdFamily::Scalar, || {
            assert_eq!(SimdFamily::active(), SimdFamily::Scalar);
            let other = std::thread::spawn(SimdFamily::active)
                .join()
                .expect("thread");
            assert_eq!(other, SimdFamily::of_process());
            with_simd_family(SimdFamily::Avx2, || {
                assert_eq!(
                    SimdFamily::active(),
                    SimdFamily::Avx2.min(SimdFamily::detected())
                );
            });
            assert_eq!(
                SimdFamily::active(),
                SimdFamily::Scalar,
                "nested scope restored"
            );
        });
        assert_eq!(SimdFamily::active(), outer);
        let caught = std::panic::catch_unwind(|| {
            with_simd_family(SimdFamily::Scalar, || panic!("inside"));
        });
        assert!(caught.is_err());
        assert_eq!(SimdFamily::active(), outer, "restored after a panic");
    }

    /// Each family's lane operations against their scalar definitions, on the families this
    /// CPU runs.
    #[test]
    fn lane_operations_match_their_definitions() {
        struct Check;
        impl Kernel for Check {
            type Output = ();
            #[inline(always)]
            unsafe fn run<S: Simd>(self) {
                let n = S::LANES;
                let src: Vec<f32> = (0..3 * n).map(|i| i as f32 + 0.5).collect();
                let read = |v: S::V| {
                    let mut out = vec![f32::NAN; n];
                    // SAFETY: `out` holds one vector.
                    unsafe { S::store(out.as_mut_ptr(), v) };
                    out
                };
                for lanes in 1..=n {
                    // SAFETY: every read lies in `src` (2·lanes − 1 ≤ 2n − 1 floats).
                    let (even, masked) = unsafe {
                        (
                            S::load_even(src.as_ptr(), lanes),
                            S::load_masked(S::mask(lanes), src.as_ptr()),
                        )
                    };
                    let want: Vec<f32> = (0..n)
                        .map(|i| if i < lanes { src[2 * i] } else { 0.0 })
                        .collect();
                    assert_eq!(
                        read(even),
                        want,
                        "{} lanes: even lanes of {lanes}",
                        S::LANES
                    );
                    let want: Vec<f32> = (0..n)
                        .map(|i| if i < lanes { src[i] } else { 0.0 })
                        .collect();
                    assert_eq!(
                        read(masked),
                        want,
                        "{} lanes: masked load {lanes}",
                        S::LANES
                    );
                    let mut out = vec![-1.0; n];
                    // SAFETY: `out` holds one vector; the store writes its first lanes.
                    unsafe {
                        let v = S::load(src.as_ptr());
                        S::store_masked(S::mask(lanes), out.as_mut_ptr(), v);
                    }
                    let want: Vec<f32> = (0..n)
                        .map(|i| if i < lanes { src[i] } else { -1.0 })
                        .collect();
                    assert_eq!(out, want, "{} lanes: masked store {lanes}", S::LANES);
                }
                // SAFETY: both loads lie in `src`.
                let (lo, hi) =
                    unsafe { S::interleave(S::load(src.as_ptr()), S::load(src.as_ptr().add(n))) };
                let both = [read(lo), read(hi)].concat();
                let want: Vec<f32> = (0..2 * n).map(|i| src[(i % 2) * n + i / 2]).collect();
                assert_eq!(both, want, "{} lanes: interleave", S::LANES);
                // SAFETY: as above.
                let fma = unsafe {
                    let (a, b) = (S::load(src.as_ptr()), S::splat(2.0));
                    S::fmadd(a, b, S::add(S::mul(a, b), S::zero()))
                };
                let want: Vec<f32> = src[..n].iter().map(|v| 4.0 * v).collect();
                assert_eq!(read(fma), want, "{} lanes: fmadd", S::LANES);
            }
        }
        for f in [SimdFamily::Avx2, SimdFamily::Avx512] {
            if f <= SimdFamily::detected() {
                // SAFETY: the CPU has the family.
                on_family!(f, S => unsafe { S::vectorize(Check) });
            }
        }
    }
}
