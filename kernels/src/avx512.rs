//! AVX-512 building blocks shared by the direct convolution ([`crate::direct_conv`]), its
//! strided input gradients ([`crate::strided_input_grad`]) and the FIR width pass's periodic
//! rows ([`crate::fir_simd`]): run-time detection, lane masks, and the even lanes of 32
//! consecutive floats (one column phase of a stride-2 row).

/// f32 lanes of one AVX-512 vector.
pub(crate) const LANES: usize = 16;

/// Whether this CPU has the AVX-512 foundation instructions the kernels use.
pub(crate) fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Mask of the first `n` lanes of a vector (all 16 from `n ≥ 16`).
pub(crate) fn lane_mask(n: usize) -> u16 {
    if n >= LANES {
        u16::MAX
    } else {
        (1u16 << n) - 1
    }
}

/// `at[0], at[2], …, at[2·(lanes − 1)]` in the first `lanes` (≤ 16) lanes, zeros after: two
/// masked loads of the `2·lanes − 1` floats needed and one two-source permute.
///
/// # Safety
/// AVX-512F is available and `at[0 .. 2·lanes − 1]` is readable.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
pub(crate) unsafe fn load_even_lanes(at: *const f32, lanes: usize) -> std::arch::x86_64::__m512 {
    use std::arch::x86_64::*;
    let even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
    let needed = 2 * lanes - 1;
    // SAFETY: the masked loads read only at[..needed] (the caller's contract).
    unsafe {
        let a = _mm512_maskz_loadu_ps(lane_mask(needed), at);
        let b = _mm512_maskz_loadu_ps(lane_mask(needed.saturating_sub(LANES)), at.add(LANES));
        _mm512_permutex2var_ps(a, even, b)
    }
}
