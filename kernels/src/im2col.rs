//! The three maps of a 2-D convolution (forward, input gradient, weight gradient) lowered to
//! matrix products: the path of [`crate::conv`] for f64, pointwise convolutions and every
//! geometry the direct kernels do not take.
//!
//! Follows the standard lowering of a convolution to a matrix product (Chellapilla, Puri &
//! Simard, "High performance convolutional neural networks for document processing", 2006;
//! Caffe's `im2col`/`col2im`). For one image, with `K = C_in·kh·kw` and `N = H_out·W_out`:
//!
//! - forward: `y (C_out × N) = W (C_out × K) · col(x) (K × N)`;
//! - input gradient: `dx = col2im(Wᵀ (K × C_out) · dy (C_out × N))`, `col2im` the adjoint of
//!   `col` (scatter-add, wrap-around for circular padding) — candle's CPU path uses a slow
//!   direct-loop `conv_transpose2d` here (`docs/candle-notes.md`, "Speed");
//! - weight gradient: `dW (C_out × K) = Σ_images dy (C_out × N) · col(x)ᵀ (N × K)`.
//!
//! `col(x)` is never materialised whole: it is built for a band of output rows at a time
//! (≈ [`COL_TILE_BYTES`]), so that it is still in cache when `gemm` reads it. A 1×1 stride-1
//! unpadded convolution skips `col` (it is `x` itself). Work is split over the batch with
//! rayon when the batch has at least as many images as threads; otherwise images run one
//! after the other and `gemm` itself is multithreaded. Thread count: [`crate::alloc::thread_count`].

use rayon::prelude::*;

use candle_core::WithDType;

use crate::alloc::output_buffer;
use crate::conv_geometry::{Geometry, OUTSIDE};
use crate::matmul::{Mat, matmul, matmul_raw};

/// Target size of one band of `col(x)`: half a core's L2 (1 MiB on the build machine), so that
/// the band is still in L2 when `gemm` packs it, while `gemm` still sees ≥ a few hundred
/// columns (≈ 227 for a 3×3 64-channel f32 layer). Measured against 256 KiB … 8 MiB on the
/// bench's steps and convs (`docs/benchmarks/conv-kernels.md`, "The band of `col(x)` sized to L2"): it
/// took 0.81–0.98× the time of the 2 MiB chosen before from the cache sizes alone.
pub const COL_TILE_BYTES: usize = 512 << 10;

/// Output rows per band of `col(x)` for element size `elem` bytes.
pub(crate) fn band_rows(g: &Geometry, elem: usize) -> usize {
    (COL_TILE_BYTES / (elem * g.k() * g.wo)).clamp(1, g.ho)
}

/// Elements of the buffer that holds one band of `band` output rows of `col(x)`; none for
/// a pointwise conv, whose `col(x)` is `x`.
fn col_len(g: &Geometry, band: usize) -> usize {
    if g.is_pointwise() {
        0
    } else {
        g.k() * band * g.wo
    }
}

/// Where output column `ox` reads for kernel column `kx`: an input column, or
/// [`OUTSIDE`] (a zero-padded texel).
fn column_map(g: &Geometry, kx: usize) -> TapMap {
    let (s, p, w) = (g.stride, g.pad, g.w);
    let idx: Vec<usize> = (0..g.wo).map(|ox| g.source(ox * s + kx, p, w)).collect();
    // Interior: ox·s + kx − p ∈ [0, w) without wrapping.
    let lo = p.saturating_sub(kx).div_ceil(s).min(g.wo);
    let hi = if w + p > kx {
        ((w + p - kx - 1) / s + 1).clamp(lo, g.wo)
    } else {
        lo
    };
    TapMap { idx, lo, hi }
}

/// For one kernel column: the input column of every output column, and the range
/// `lo..hi` of output columns that read inside the image without wrapping.
struct TapMap {
    idx: Vec<usize>,
    lo: usize,
    hi: usize,
}

/// Rows `r0..r1` of `col(x)` for one image `x` (C_in·H·W): row `(c, ky, kx)`, column
/// `(oy − r0)·W_out + ox` holds `x[c, oy·s + ky − p, ox·s + kx − p]` (wrapped or zero).
fn im2col<T: WithDType>(
    g: &Geometry,
    maps: &[TapMap],
    x: &[T],
    (r0, r1): (usize, usize),
    col: &mut [T],
) {
    let (n, s) = ((r1 - r0) * g.wo, g.stride);
    let zero = T::from_f64(0.0);
    for c in 0..g.ci {
        let plane = &x[c * g.h * g.w..(c + 1) * g.h * g.w];
        for ky in 0..g.kh {
            for (kx, map) in maps.iter().enumerate() {
                let row = ((c * g.kh + ky) * g.kw + kx) * n;
                let dst = &mut col[row..row + n];
                for oy in r0..r1 {
                    let out = &mut dst[(oy - r0) * g.wo..(oy - r0 + 1) * g.wo];
                    let iy = g.source(oy * s + ky, g.pad, g.h);
                    if iy == OUTSIDE {
                        out.fill(zero);
                        continue;
                    }
                    let src = &plane[iy * g.w..(iy + 1) * g.w];
                    for ox in (0..map.lo).chain(map.hi..g.wo) {
                        let ix = map.idx[ox];
                        out[ox] = if ix == OUTSIDE { zero } else { src[ix] };
                    }
                    if map.lo == map.hi {
                        continue;
                    }
                    // In-bounds: lo·s + kx ≥ pad by the definition of `lo`.
                    let first = map.lo * s + kx - g.pad;
                    if s == 1 {
                        out[map.lo..map.hi].copy_from_slice(&src[first..first + map.hi - map.lo]);
                    } else {
                        for (o, i) in out[map.lo..map.hi].iter_mut().zip((first..).step_by(s)) {
                            *o = src[i];
                        }
                    }
                }
            }
        }
    }
}

/// The adjoint of [`im2col`]: adds rows `r0..r1` of a lowered gradient `col` into the image
/// gradient `dx` (C_in·H·W), wrapped taps onto the texels they read.
fn col2im_add<T: WithDType>(
    g: &Geometry,
    maps: &[TapMap],
    col: &[T],
    (r0, r1): (usize, usize),
    dx: &mut [T],
) {
    let (n, s) = ((r1 - r0) * g.wo, g.stride);
    for c in 0..g.ci {
        let plane = &mut dx[c * g.h * g.w..(c + 1) * g.h * g.w];
        for ky in 0..g.kh {
            for (kx, map) in maps.iter().enumerate() {
                let row = ((c * g.kh + ky) * g.kw + kx) * n;
                let src = &col[row..row + n];
                for oy in r0..r1 {
                    let iy = g.source(oy * s + ky, g.pad, g.h);
                    if iy == OUTSIDE {
                        continue;
                    }
                    let grad = &src[(oy - r0) * g.wo..(oy - r0 + 1) * g.wo];
                    let dst = &mut plane[iy * g.w..(iy + 1) * g.w];
                    for ox in (0..map.lo).chain(map.hi..g.wo) {
                        let ix = map.idx[ox];
                        if ix != OUTSIDE {
                            dst[ix] += grad[ox];
                        }
                    }
                    if map.lo == map.hi {
                        continue;
                    }
                    let first = map.lo * s + kx - g.pad;
                    let inner = &grad[map.lo..map.hi];
                    if s == 1 {
                        for (d, v) in dst[first..first + inner.len()].iter_mut().zip(inner) {
                            *d += *v;
                        }
                    } else {
                        for (v, i) in inner.iter().zip((first..).step_by(s)) {
                            dst[i] += *v;
                        }
                    }
                }
            }
        }
    }
}

/// Runs `f(first_image, images, gemm_threads)` over the batch: `threads` rayon tasks of whole
/// images with single-threaded `gemm` when the batch has ≥ `threads` images, else one call
/// over all images with multithreaded `gemm`. Returns the per-task results in batch order.
fn over_batch<R: Send>(
    batch: usize,
    threads: usize,
    f: impl Fn(usize, usize, usize) -> R + Sync,
) -> Vec<R> {
    if threads <= 1 || batch < threads {
        return vec![f(0, batch, threads)];
    }
    let per = batch.div_ceil(threads);
    (0..batch.div_ceil(per))
        .into_par_iter()
        .map(|t| f(t * per, per.min(batch - t * per), 1))
        .collect()
}

/// Forward: writes every element of `y` (B·C_out·H_out·W_out).
///
/// Bands of output rows write disjoint parts of `y`, so when the batch is smaller than the
/// thread count (sampling one material, E at full resolution) and there are enough bands, the
/// (image, band) pairs are the parallel tasks, each with single-threaded `gemm`: gemm's own
/// threading splits each band's small product and scales poorly (`docs/benchmarks/conv-kernels.md`,
/// "Bands as the parallel tasks of a one-image conv").
pub(crate) fn forward<T: WithDType>(g: &Geometry, x: &[T], w: &[T], y: &mut [T], threads: usize) {
    let (x_len, y_len, k) = (g.ci * g.h * g.w, g.co * g.ho * g.wo, g.k());
    let n_out = g.ho * g.wo;
    let (y_addr, y_total) = (y.as_mut_ptr() as usize, y.len());
    let maps: Vec<TapMap> = (0..g.kw).map(|kx| column_map(g, kx)).collect();
    let band = band_rows(g, size_of::<T>());
    let col_len = col_len(g, band);
    // Output rows r0..r0 + band of image i; `col` holds at least one band.
    let run_band = |i: usize, r0: usize, col: &mut [T], gemm_threads: usize| {
        let xi = &x[i * x_len..(i + 1) * x_len];
        let r1 = (r0 + band).min(g.ho);
        let n = (r1 - r0) * g.wo;
        let rhs = if g.is_pointwise() {
            Mat::new(&xi[r0 * g.wo..], n_out, 1)
        } else {
            im2col(g, &maps, xi, (r0, r1), &mut col[..k * n]);
            Mat::new(&col[..k * n], n, 1)
        };
        // Output rows r0..r1 of every channel of image i: element r0·W_out of the image's
        // output onward, channel rows `n_out` apart.
        let offset = i * y_len + r0 * g.wo;
        // SAFETY: `y` (`y_total` = B·y_len elements at `y_addr`) outlives every call, and
        // `offset` lies in it. A call writes columns r0·W_out .. r1·W_out of each channel row
        // of image i; calls running at the same time have distinct (image, band) pairs, so the
        // elements they write are disjoint, and `y` is no operand. No slice of `y` is formed
        // here, since those of concurrent bands would overlap.
        unsafe {
            matmul_raw(
                (g.co, n, k),
                ((y_addr as *mut T).add(offset), y_total - offset),
                n_out,
                false,
                Mat::new(w, k, 1),
                rhs,
                gemm_threads,
            );
        }
    };
    let bands = g.ho.div_ceil(band);
    if threads > 1 && g.b < threads && g.b * bands >= 2 * threads {
        let jobs: Vec<(usize, usize)> = (0..g.b)
            .flat_map(|i| (0..bands).map(move |j| (i, j * band)))
            .collect();
        jobs.into_par_iter().for_each_init(
            // SAFETY: `im2col` writes the part of `col` a band uses before the product reads it.
            || unsafe { output_buffer::<T>(col_len) },
            |col, (i, r0)| run_band(i, r0, col, 1),
        );
        return;
    }
    over_batch(g.b, threads, |first, count, gemm_threads| {
        // SAFETY: `im2col` writes the part of `col` a band uses before the product reads it.
        let mut col = unsafe { output_buffer(col_len) };
        for i in first..first + count {
            for r0 in (0..g.ho).step_by(band) {
                run_band(i, r0, &mut col, gemm_threads);
            }
        }
    });
}

/// Input gradient: writes every element of `dx` (B·C_in·H·W) from `dy` and `w`.
pub(crate) fn input_grad<T: WithDType>(
    g: &Geometry,
    dy: &[T],
    w: &[T],
    dx: &mut [T],
    threads: usize,
) {
    let (x_len, y_len, k) = (g.ci * g.h * g.w, g.co * g.ho * g.wo, g.k());
    let n_out = g.ho * g.wo;
    let dx_addr = dx.as_mut_ptr() as usize;
    let maps: Vec<TapMap> = (0..g.kw).map(|kx| column_map(g, kx)).collect();
    let band = band_rows(g, size_of::<T>());
    over_batch(g.b, threads, |first, count, gemm_threads| {
        // SAFETY: the product into `col[..k·n]` (not accumulating) writes the part of `col` a
        // band uses before the scatter back into `dx` reads it.
        let mut col = unsafe { output_buffer(col_len(g, band)) };
        for i in first..first + count {
            let dyi = &dy[i * y_len..(i + 1) * y_len];
            // SAFETY: as in `forward_into`, tasks write disjoint images.
            let dxi = unsafe {
                std::slice::from_raw_parts_mut((dx_addr as *mut T).add(i * x_len), x_len)
            };
            if g.is_pointwise() {
                // dx (C_in × HW) = Wᵀ · dy, written whole by one product.
                matmul(
                    (g.ci, n_out, g.co),
                    dxi,
                    n_out,
                    false,
                    Mat::new(w, 1, g.ci),
                    Mat::new(dyi, n_out, 1),
                    gemm_threads,
                );
                continue;
            }
            dxi.fill(T::from_f64(0.0));
            for r0 in (0..g.ho).step_by(band) {
                let r1 = (r0 + band).min(g.ho);
                let n = (r1 - r0) * g.wo;
                matmul(
                    (k, n, g.co),
                    &mut col[..k * n],
                    n,
                    false,
                    Mat::new(w, 1, k),
                    Mat::new(&dyi[r0 * g.wo..], n_out, 1),
                    gemm_threads,
                );
                col2im_add(g, &maps, &col[..k * n], (r0, r1), dxi);
            }
        }
    });
}

/// Weight gradient: writes every element of `dw` (C_out·C_in·kh·kw) from `x` and `dy`.
pub(crate) fn weight_grad<T: WithDType>(
    g: &Geometry,
    x: &[T],
    dy: &[T],
    dw: &mut [T],
    threads: usize,
) {
    let (x_len, y_len, k) = (g.ci * g.h * g.w, g.co * g.ho * g.wo, g.k());
    let n_out = g.ho * g.wo;
    let maps: Vec<TapMap> = (0..g.kw).map(|kx| column_map(g, kx)).collect();
    let band = band_rows(g, size_of::<T>());
    let partials = over_batch(g.b, threads, |first, count, gemm_threads| {
        let mut acc = vec![T::from_f64(0.0); g.co * k];
        // SAFETY: `im2col` writes the part of `col` a band uses before the product reads it.
        let mut col = unsafe { output_buffer(col_len(g, band)) };
        for i in first..first + count {
            let xi = &x[i * x_len..(i + 1) * x_len];
            let dyi = &dy[i * y_len..(i + 1) * y_len];
            for r0 in (0..g.ho).step_by(band) {
                let r1 = (r0 + band).min(g.ho);
                let n = (r1 - r0) * g.wo;
                let rhs = if g.is_pointwise() {
                    // col(x)ᵀ: element (pixel, channel) of x at channel·HW + pixel.
                    Mat::new(&xi[r0 * g.wo..], 1, n_out)
                } else {
                    im2col(g, &maps, xi, (r0, r1), &mut col[..k * n]);
                    Mat::new(&col[..k * n], 1, n)
                };
                matmul(
                    (g.co, k, n),
                    &mut acc,
                    k,
                    true,
                    Mat::new(&dyi[r0 * g.wo..], n_out, 1),
                    rhs,
                    gemm_threads,
                );
            }
        }
        acc
    });
    // Partial sums in batch order: the result does not depend on thread timing.
    dw.fill(T::from_f64(0.0));
    for part in partials {
        for (d, p) in dw.iter_mut().zip(&part) {
            *d += *p;
        }
    }
}
