//! Matrix products on strided views, through the `gemm` crate: the one place this crate
//! calls it (the im2col convolutions of [`crate::im2col`], the per-texel MLP of
//! [`crate::mlp`]).

use candle_core::WithDType;
use gemm::Parallelism;

/// A strided view of a matrix inside a slice: element (i, j) at `data[i·rs + j·cs]`.
#[derive(Clone, Copy)]
pub(crate) struct Mat<'a, T> {
    data: &'a [T],
    rs: usize,
    cs: usize,
}

impl<'a, T> Mat<'a, T> {
    pub(crate) fn new(data: &'a [T], rs: usize, cs: usize) -> Self {
        Self { data, rs, cs }
    }

    /// Panics unless an `rows × cols` matrix with these strides lies inside the slice (an
    /// empty one always does).
    fn check(&self, rows: usize, cols: usize) {
        if rows == 0 || cols == 0 {
            return;
        }
        let last = (rows - 1) * self.rs + (cols - 1) * self.cs;
        assert!(last < self.data.len(), "matrix view out of bounds");
    }
}

/// `dst (m × n, row stride dst_rs) = [dst +] lhs (m × k) · rhs (k × n)` with the `gemm` crate.
#[allow(clippy::too_many_arguments)]
pub(crate) fn matmul<T: WithDType>(
    dims: (usize, usize, usize),
    dst: &mut [T],
    dst_rs: usize,
    accumulate: bool,
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    threads: usize,
) {
    // SAFETY: `dst` is a live, exclusively borrowed slice of `dst.len()` elements, so it
    // aliases neither operand and no other thread touches it.
    unsafe {
        matmul_raw(
            dims,
            (dst.as_mut_ptr(), dst.len()),
            dst_rs,
            accumulate,
            lhs,
            rhs,
            threads,
        )
    }
}

/// [`matmul`] into `dst_len` elements from a raw pointer: for tasks that write disjoint,
/// interleaved rows of one buffer at the same time (the band-parallel forward), where
/// slices of the buffer would overlap.
///
/// # Safety
/// `dst.0` is valid for reads and writes of `dst.1` elements; the elements this product writes
/// (rows `0..m` at stride `dst_rs`, columns `0..n`) are neither read nor written by any other
/// thread while it runs, and overlap neither operand.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn matmul_raw<T: WithDType>(
    (m, n, k): (usize, usize, usize),
    dst: (*mut T, usize),
    dst_rs: usize,
    accumulate: bool,
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
    threads: usize,
) {
    if m == 0 || n == 0 {
        return;
    }
    lhs.check(m, k);
    rhs.check(k, n);
    assert!(
        (m - 1) * dst_rs + n <= dst.1,
        "gemm destination out of bounds"
    );
    let parallelism = if threads > 1 {
        Parallelism::Rayon(threads)
    } else {
        Parallelism::None
    };
    let one = T::from_f64(1.0);
    // SAFETY: the three views were bounds-checked above; the caller guarantees that the
    // destination's written elements are exclusively this call's and alias neither operand.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.0,
            1,
            dst_rs as isize,
            accumulate,
            lhs.data.as_ptr(),
            lhs.cs as isize,
            lhs.rs as isize,
            rhs.data.as_ptr(),
            rhs.cs as isize,
            rhs.rs as isize,
            one,
            one,
            false,
            false,
            false,
            parallelism,
        )
    }
}

/// `dst (m × n, row-major) = [dst +] lhs (m × k) · rhs (k × n)` on the calling thread.
pub(crate) fn matmul_rows<T: WithDType>(
    dims: (usize, usize, usize),
    dst: &mut [T],
    accumulate: bool,
    lhs: Mat<'_, T>,
    rhs: Mat<'_, T>,
) {
    matmul(dims, dst, dims.1, accumulate, lhs, rhs, 1);
}
