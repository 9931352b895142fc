//! 2-D convolution on the CPU as candle custom ops: im2col + `gemm`, with zero or circular
//! padding, whose forward, input gradient and weight gradient are each a custom op whose own
//! backward is built from the other two — so the op is differentiable to any order (R1 in
//! the discriminator, `docs/neural-models.md`, "GAN training").
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
//!
//! The three ops are bilinear and close under differentiation. Writing `F(x, W)` (forward),
//! `Gx(dy, W)` (input gradient) and `Gw(x, dy)` (weight gradient), the adjoint identities
//! `⟨dy, F(x, W)⟩ = ⟨x, Gx(dy, W)⟩ = ⟨W, Gw(x, dy)⟩` give every backward:
//! `F: (Gx(g, W), Gw(x, g))`, `Gx(dy, W): (F(g, W), Gw(g, dy))`, `Gw(x, dy): (Gx(dy, g), F(x, g))`.
//!
//! On CPUs with AVX-512, f32 convolutions other than pointwise ones run on the direct kernels
//! of [`crate::direct_conv`] instead, which read a padded copy of the input in place rather
//! than `col(x)` (`docs/benchmarks/conv-kernels.md`, "A direct convolution kernel"): forwards whose
//! output rows are at least 16 texels wide, the input gradients of such stride-1 convolutions, and
//! weight gradients over at least 1024 output texels. Pointwise convolutions (whose `col(x)` is `x`
//! itself), strided input gradients, narrow layers and f64 stay here.
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices and dtypes fall back to
//! [`conv2d_reference`] (candle's `conv2d`, circular padding by `narrow` + `cat`), as does
//! every call inside [`crate::reference::with_reference_ops`].

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp2, DType, Layout, Result, Shape, Tensor, WithDType, bail};
use gemm::Parallelism;
use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::direct_conv;

/// Target size of one band of `col(x)`: half a core's L2 (1 MiB on the build machine), so that
/// the band is still in L2 when `gemm` packs it, while `gemm` still sees ≥ a few hundred
/// columns (≈ 227 for a 3×3 64-channel f32 layer). Measured against 256 KiB … 8 MiB on the
/// bench's steps and convs (`docs/benchmarks/conv-kernels.md`, "The band of `col(x)` sized to L2"):
/// it took 0.81–0.98× the time of the 2 MiB chosen before from the cache sizes alone.
pub const COL_TILE_BYTES: usize = 512 << 10;

/// How the border of the input is extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaddingMode {
    /// Zeros outside the image (candle's and PyTorch's default).
    Zeros,
    /// Wrap around: the image is one period of a tileable texture (the reference's
    /// `CircularConv2d`, PyTorch `padding_mode="circular"`).
    Circular,
}

/// Stride, padding and padding mode of a [`conv2d`]; dilation 1, one group.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Conv2dSpec {
    /// Step between output texels, in input texels (≥ 1).
    pub stride: usize,
    /// Texels added on each of the four sides.
    pub padding: usize,
    /// How the added texels are filled.
    pub mode: PaddingMode,
}

impl Conv2dSpec {
    /// Zero padding.
    pub fn zeros(stride: usize, padding: usize) -> Self {
        Self {
            stride,
            padding,
            mode: PaddingMode::Zeros,
        }
    }

    /// Circular (wrap-around) padding.
    pub fn circular(stride: usize, padding: usize) -> Self {
        Self {
            stride,
            padding,
            mode: PaddingMode::Circular,
        }
    }
}

/// Convolution (cross-correlation, as in candle and PyTorch) of `x` with `w`.
///
/// # Shapes
/// x (B, C_in, H, W), w (C_out, C_in, kh, kw) → (B, C_out, H_out, W_out) with
/// `H_out = (H + 2·padding − kh)/stride + 1` (floor), likewise `W_out`.
///
/// Circular padding must not exceed the image (`padding ≤ min(H, W)`), as in PyTorch.
pub fn conv2d(x: &Tensor, w: &Tensor, spec: Conv2dSpec) -> Result<Tensor> {
    let g = Geometry::new(x.dims4()?, w.dims4()?, spec)?;
    if !fast_path(x, w)? || crate::reference::reference_ops() {
        return conv2d_reference(x, w, spec);
    }
    apply_forward(g, x, w)
}

/// The same convolution from candle's own ops: circular padding by `narrow` + `cat`, then
/// candle's `conv2d` (zero padding by its `padding` argument). Exact and differentiable to any
/// order (`docs/candle-notes.md`, "Gradients that were checked and are right"); the reference the
/// tests compare against and the path for devices and dtypes [`conv2d`] does not handle.
///
/// # Shapes
/// As [`conv2d`].
pub fn conv2d_reference(x: &Tensor, w: &Tensor, spec: Conv2dSpec) -> Result<Tensor> {
    Geometry::new(x.dims4()?, w.dims4()?, spec)?;
    match spec.mode {
        PaddingMode::Zeros => x.conv2d(w, spec.padding, spec.stride, 1, 1),
        PaddingMode::Circular => {
            let p = spec.padding;
            let wrap = |t: &Tensor, dim: usize| -> Result<Tensor> {
                if p == 0 {
                    return Ok(t.clone());
                }
                let n = t.dim(dim)?;
                Tensor::cat(&[&t.narrow(dim, n - p, p)?, t, &t.narrow(dim, 0, p)?], dim)
            };
            wrap(&wrap(x, 2)?, 3)?.conv2d(w, 0, spec.stride, 1, 1)
        }
    }
}

/// Whether both operands can take the custom-op path (CPU, same dtype, f32 or f64).
pub(crate) fn fast_path(a: &Tensor, b: &Tensor) -> Result<bool> {
    if a.dtype() != b.dtype() {
        bail!("conv2d: dtypes differ ({:?}, {:?})", a.dtype(), b.dtype());
    }
    Ok(a.device().is_cpu() && b.device().is_cpu() && matches!(a.dtype(), DType::F32 | DType::F64))
}

/// Sizes of one convolution, checked once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Geometry {
    pub(crate) b: usize,
    pub(crate) ci: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) co: usize,
    pub(crate) kh: usize,
    pub(crate) kw: usize,
    pub(crate) stride: usize,
    pub(crate) pad: usize,
    pub(crate) circular: bool,
    pub(crate) ho: usize,
    pub(crate) wo: usize,
}

impl Geometry {
    pub(crate) fn new(
        (b, ci, h, w): (usize, usize, usize, usize),
        (co, ci_w, kh, kw): (usize, usize, usize, usize),
        spec: Conv2dSpec,
    ) -> Result<Self> {
        let Conv2dSpec {
            stride,
            padding: pad,
            mode,
        } = spec;
        if ci != ci_w {
            bail!("conv2d: input has {ci} channels, kernel expects {ci_w}");
        }
        if stride == 0 || kh == 0 || kw == 0 || ci == 0 || co == 0 {
            bail!("conv2d: stride, kernel size and channel counts must be ≥ 1");
        }
        let circular = mode == PaddingMode::Circular;
        if circular && (pad > h || pad > w) {
            bail!("conv2d: circular padding {pad} exceeds the {h}×{w} image");
        }
        if h + 2 * pad < kh || w + 2 * pad < kw {
            bail!("conv2d: kernel {kh}×{kw} is larger than the padded {h}×{w} input");
        }
        let ho = (h + 2 * pad - kh) / stride + 1;
        let wo = (w + 2 * pad - kw) / stride + 1;
        Ok(Self {
            b,
            ci,
            h,
            w,
            co,
            kh,
            kw,
            stride,
            pad,
            circular,
            ho,
            wo,
        })
    }

    pub(crate) fn x_shape(&self) -> Shape {
        (self.b, self.ci, self.h, self.w).into()
    }

    pub(crate) fn w_shape(&self) -> Shape {
        (self.co, self.ci, self.kh, self.kw).into()
    }

    pub(crate) fn y_shape(&self) -> Shape {
        (self.b, self.co, self.ho, self.wo).into()
    }

    /// Rows of the lowered matrix: C_in·kh·kw.
    pub(crate) fn k(&self) -> usize {
        self.ci * self.kh * self.kw
    }

    /// A 1×1 stride-1 unpadded convolution: `col(x)` is `x`.
    pub(crate) fn is_pointwise(&self) -> bool {
        self.kh == 1 && self.kw == 1 && self.stride == 1 && self.pad == 0
    }

    /// Output rows per band of `col(x)` for element size `elem` bytes.
    fn band_rows(&self, elem: usize) -> usize {
        (COL_TILE_BYTES / (elem * self.k() * self.wo)).clamp(1, self.ho)
    }

    /// Elements of the buffer that holds one band of `band` output rows of `col(x)`; none for
    /// a pointwise conv, whose `col(x)` is `x`.
    fn col_len(&self, band: usize) -> usize {
        if self.is_pointwise() {
            0
        } else {
            self.k() * band * self.wo
        }
    }

    /// Where output column `ox` reads for kernel column `kx`: an input column, or
    /// [`OUTSIDE`] (a zero-padded texel).
    fn column_map(&self, kx: usize) -> TapMap {
        let (s, p, w) = (self.stride, self.pad, self.w);
        let idx: Vec<usize> = (0..self.wo)
            .map(|ox| self.source(ox * s + kx, p, w))
            .collect();
        // Interior: ox·s + kx − p ∈ [0, w) without wrapping.
        let lo = p.saturating_sub(kx).div_ceil(s).min(self.wo);
        let hi = if w + p > kx {
            ((w + p - kx - 1) / s + 1).clamp(lo, self.wo)
        } else {
            lo
        };
        TapMap { idx, lo, hi }
    }

    /// Input index for padded position `padded` (input index + `pad`) along an axis of
    /// length `n`: wrapped when circular, `None` when zero-padded.
    pub(crate) fn source_index(&self, padded: usize, pad: usize, n: usize) -> Option<usize> {
        Some(self.source(padded, pad, n)).filter(|&i| i != OUTSIDE)
    }

    /// Input index for padded position `padded` (input index + `pad`) along an axis of
    /// length `n`: wrapped when circular, [`OUTSIDE`] when zero-padded.
    fn source(&self, padded: usize, pad: usize, n: usize) -> usize {
        if padded >= pad && padded - pad < n {
            padded - pad
        } else if self.circular {
            (padded + n - pad) % n
        } else {
            OUTSIDE
        }
    }
}

/// Marks a tap that falls into zero padding.
const OUTSIDE: usize = usize::MAX;

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

/// A strided view of a matrix inside a slice: element (i, j) at `data[i·rs + j·cs]`.
#[derive(Clone, Copy)]
struct Mat<'a, T> {
    data: &'a [T],
    rs: usize,
    cs: usize,
}

impl<'a, T> Mat<'a, T> {
    fn new(data: &'a [T], rs: usize, cs: usize) -> Self {
        Self { data, rs, cs }
    }

    /// Panics unless an `rows × cols` matrix with these strides lies inside the slice.
    fn check(&self, rows: usize, cols: usize) {
        let last = (rows - 1) * self.rs + (cols - 1) * self.cs;
        assert!(last < self.data.len(), "matrix view out of bounds");
    }
}

/// `dst (m × n, row stride dst_rs) = [dst +] lhs (m × k) · rhs (k × n)` with the `gemm` crate.
#[allow(clippy::too_many_arguments)]
fn matmul<T: WithDType>(
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
unsafe fn matmul_raw<T: WithDType>(
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

/// Whether the direct kernels of [`crate::direct_conv`] may run: yes unless the environment
/// variable `PHOTOMAT_NO_DIRECT_CONV` is set, which sends every convolution to im2col + `gemm`
/// (same-binary A/B measurements, `docs/benchmarks/conv-kernels.md`, "A direct convolution
/// kernel"). Read once per process.
fn direct_conv_enabled() -> bool {
    static ENABLED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ENABLED.get_or_init(|| std::env::var_os("PHOTOMAT_NO_DIRECT_CONV").is_none())
}

/// The three operands as f32 slices when `T` is f32 and the direct kernels are enabled.
fn as_f32<'a, T: WithDType>(
    a: &'a [T],
    b: &'a [T],
    out: &'a mut [T],
) -> Option<(&'a [f32], &'a [f32], &'a mut [f32])> {
    if T::DTYPE != DType::F32 || !direct_conv_enabled() {
        return None;
    }
    // SAFETY: `T` is f32 (its DTYPE says so), so the slices' elements are f32.
    unsafe {
        Some((
            std::slice::from_raw_parts(a.as_ptr() as *const f32, a.len()),
            std::slice::from_raw_parts(b.as_ptr() as *const f32, b.len()),
            std::slice::from_raw_parts_mut(out.as_mut_ptr() as *mut f32, out.len()),
        ))
    }
}

/// Forward: writes every element of `y` (B·C_out·H_out·W_out).
///
/// Bands of output rows write disjoint parts of `y`, so when the batch is smaller than the
/// thread count (sampling one material, E at full resolution) and there are enough bands, the
/// (image, band) pairs are the parallel tasks, each with single-threaded `gemm`: gemm's own
/// threading splits each band's small product and scales poorly (`docs/benchmarks/conv-kernels.md`,
/// "Bands as the parallel tasks of a one-image conv").
pub(crate) fn forward_into<T: WithDType>(
    g: &Geometry,
    x: &[T],
    w: &[T],
    y: &mut [T],
    threads: usize,
) {
    if let Some((x, w, y)) = as_f32(x, w, y).filter(|_| direct_conv::supports_forward(g)) {
        direct_conv::forward(g, x, w, y, threads);
        return;
    }
    let (x_len, y_len, k) = (g.ci * g.h * g.w, g.co * g.ho * g.wo, g.k());
    let n_out = g.ho * g.wo;
    let (y_addr, y_total) = (y.as_mut_ptr() as usize, y.len());
    let maps: Vec<TapMap> = (0..g.kw).map(|kx| g.column_map(kx)).collect();
    let band = g.band_rows(size_of::<T>());
    let col_len = g.col_len(band);
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
fn input_grad_into<T: WithDType>(g: &Geometry, dy: &[T], w: &[T], dx: &mut [T], threads: usize) {
    if let Some((dy, w, dx)) = as_f32(dy, w, dx).filter(|_| direct_conv::supports_input_grad(g)) {
        direct_conv::input_grad(g, dy, w, dx, threads);
        return;
    }
    let (x_len, y_len, k) = (g.ci * g.h * g.w, g.co * g.ho * g.wo, g.k());
    let n_out = g.ho * g.wo;
    let dx_addr = dx.as_mut_ptr() as usize;
    let maps: Vec<TapMap> = (0..g.kw).map(|kx| g.column_map(kx)).collect();
    let band = g.band_rows(size_of::<T>());
    over_batch(g.b, threads, |first, count, gemm_threads| {
        // SAFETY: the product into `col[..k·n]` (not accumulating) writes the part of `col` a
        // band uses before the scatter back into `dx` reads it.
        let mut col = unsafe { output_buffer(g.col_len(band)) };
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
fn weight_grad_into<T: WithDType>(g: &Geometry, x: &[T], dy: &[T], dw: &mut [T], threads: usize) {
    if let Some((x, dy, dw)) = as_f32(x, dy, dw).filter(|_| direct_conv::prefers_weight_grad(g)) {
        direct_conv::weight_grad(g, x, dy, dw, threads);
        return;
    }
    let (x_len, y_len, k) = (g.ci * g.h * g.w, g.co * g.ho * g.wo, g.k());
    let n_out = g.ho * g.wo;
    let maps: Vec<TapMap> = (0..g.kw).map(|kx| g.column_map(kx)).collect();
    let band = g.band_rows(size_of::<T>());
    let partials = over_batch(g.b, threads, |first, count, gemm_threads| {
        let mut acc = vec![T::from_f64(0.0); g.co * k];
        // SAFETY: `im2col` writes the part of `col` a band uses before the product reads it.
        let mut col = unsafe { output_buffer(g.col_len(band)) };
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

/// The contiguous slice of a storage, or an error naming the op.
pub(crate) fn contiguous<'a, T>(v: &'a [T], layout: &Layout, op: &str) -> Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&v[start..end]),
        None => bail!("{op}: expected a contiguous tensor"),
    }
}

/// Checks a CPU operand's shape against the geometry.
pub(crate) fn expect_shape(layout: &Layout, shape: &Shape, op: &str, what: &str) -> Result<()> {
    if layout.shape() != shape {
        bail!(
            "{op}: {what} has shape {:?}, expected {shape:?}",
            layout.shape()
        );
    }
    Ok(())
}

/// Which of the three bilinear maps an op computes.
#[derive(Clone, Copy)]
enum Kind {
    Forward,
    InputGrad,
    WeightGrad,
}

/// Runs one of the three kernels on CPU storages, allocating its output uninitialised
/// (`output_buffer`): each `_into` function writes all of it.
fn run(
    kind: Kind,
    g: &Geometry,
    name: &str,
    (a, la): (&CpuStorage, &Layout),
    (b, lb): (&CpuStorage, &Layout),
) -> Result<(CpuStorage, Shape)> {
    let (sa, sb, out) = match kind {
        Kind::Forward => (g.x_shape(), g.w_shape(), g.y_shape()),
        Kind::InputGrad => (g.y_shape(), g.w_shape(), g.x_shape()),
        Kind::WeightGrad => (g.x_shape(), g.y_shape(), g.w_shape()),
    };
    expect_shape(la, &sa, name, "first operand")?;
    expect_shape(lb, &sb, name, "second operand")?;
    let threads = crate::alloc::thread_count();
    fn go<T: WithDType>(
        kind: Kind,
        g: &Geometry,
        a: &[T],
        b: &[T],
        len: usize,
        threads: usize,
    ) -> Vec<T> {
        // SAFETY: each of the three `_into` functions writes every element of its output.
        let mut out = unsafe { output_buffer(len) };
        match kind {
            Kind::Forward => forward_into(g, a, b, &mut out, threads),
            Kind::InputGrad => input_grad_into(g, a, b, &mut out, threads),
            Kind::WeightGrad => weight_grad_into(g, a, b, &mut out, threads),
        }
        out
    }
    let n = out.elem_count();
    let storage = match (a, b) {
        (CpuStorage::F32(a), CpuStorage::F32(b)) => {
            let (a, b) = (contiguous(a, la, name)?, contiguous(b, lb, name)?);
            CpuStorage::F32(go(kind, g, a, b, n, threads))
        }
        (CpuStorage::F64(a), CpuStorage::F64(b)) => {
            let (a, b) = (contiguous(a, la, name)?, contiguous(b, lb, name)?);
            CpuStorage::F64(go(kind, g, a, b, n, threads))
        }
        (a, b) => bail!(
            "{name}: unsupported dtypes {:?}, {:?}",
            a.dtype(),
            b.dtype()
        ),
    };
    Ok((storage, out))
}

/// `F(x, w)`: the forward convolution.
struct Forward(Geometry);
/// `Gx(dy, w)`: the input gradient.
struct InputGrad(Geometry);
/// `Gw(x, dy)`: the weight gradient.
struct WeightGrad(Geometry);

fn apply_forward(g: Geometry, x: &Tensor, w: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&w.contiguous()?, Forward(g))
}

pub(crate) fn apply_input_grad(g: Geometry, dy: &Tensor, w: &Tensor) -> Result<Tensor> {
    dy.contiguous()?.apply_op2(&w.contiguous()?, InputGrad(g))
}

pub(crate) fn apply_weight_grad(g: Geometry, x: &Tensor, dy: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&dy.contiguous()?, WeightGrad(g))
}

/// The gradient with respect to `operand`, computed only when the backward pass will use it:
/// candle asks a custom op for both operands' gradients, and drops those of operands outside
/// the graph (a constant input such as the estimator's neural material, or a frozen layer's
/// weights), so each of those would be a convolution's worth of work thrown away.
pub(crate) fn needed(
    operand: &Tensor,
    grad: impl FnOnce() -> Result<Tensor>,
) -> Result<Option<Tensor>> {
    operand.track_op().then(grad).transpose()
}

impl CustomOp2 for Forward {
    fn name(&self) -> &'static str {
        "photomat-conv2d"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        w: &CpuStorage,
        lw: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        run(Kind::Forward, &self.0, self.name(), (x, lx), (w, lw))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _y: &Tensor,
        g: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((
            needed(x, || apply_input_grad(self.0, g, w))?,
            needed(w, || apply_weight_grad(self.0, x, g))?,
        ))
    }
}

impl CustomOp2 for InputGrad {
    fn name(&self) -> &'static str {
        "photomat-conv2d-input-grad"
    }

    fn cpu_fwd(
        &self,
        dy: &CpuStorage,
        ldy: &Layout,
        w: &CpuStorage,
        lw: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        run(Kind::InputGrad, &self.0, self.name(), (dy, ldy), (w, lw))
    }

    fn bwd(
        &self,
        dy: &Tensor,
        w: &Tensor,
        _dx: &Tensor,
        g: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((
            needed(dy, || apply_forward(self.0, g, w))?,
            needed(w, || apply_weight_grad(self.0, g, dy))?,
        ))
    }
}

impl CustomOp2 for WeightGrad {
    fn name(&self) -> &'static str {
        "photomat-conv2d-weight-grad"
    }

    fn cpu_fwd(
        &self,
        x: &CpuStorage,
        lx: &Layout,
        dy: &CpuStorage,
        ldy: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        run(Kind::WeightGrad, &self.0, self.name(), (x, lx), (dy, ldy))
    }

    fn bwd(
        &self,
        x: &Tensor,
        dy: &Tensor,
        _dw: &Tensor,
        g: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        Ok((
            needed(x, || apply_input_grad(self.0, dy, g))?,
            needed(dy, || apply_forward(self.0, x, g))?,
        ))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    /// (B, C_in, H, W, C_out, k, stride, padding).
    type Case = (usize, usize, usize, usize, usize, usize, usize, usize);

    /// The project's kernels (1×1, 3×3, 4×4), strides 1 and 2, odd sizes, batch 1,
    /// non-square images, padding 0–2.
    const CASES: &[Case] = &[
        (2, 3, 8, 8, 4, 3, 1, 1),
        (1, 2, 7, 9, 3, 3, 1, 1),
        (3, 4, 9, 7, 5, 3, 2, 1),
        (2, 3, 8, 10, 4, 4, 2, 1),
        (1, 5, 11, 9, 2, 4, 2, 1),
        (2, 6, 5, 7, 3, 1, 1, 0),
        (1, 3, 7, 5, 4, 1, 2, 0),
        (2, 2, 6, 6, 3, 3, 1, 2),
        (1, 2, 5, 6, 2, 4, 1, 0),
        (4, 2, 4, 4, 3, 3, 1, 1),
    ];

    /// y and the gradients of L = Σ g ⊙ y w.r.t. x and w, through `conv`.
    fn value_and_grads(
        conv: fn(&Tensor, &Tensor, Conv2dSpec) -> Result<Tensor>,
        x: &Var,
        w: &Var,
        g: &Tensor,
        spec: Conv2dSpec,
    ) -> Result<(Tensor, Tensor, Tensor)> {
        let y = conv(x.as_tensor(), w.as_tensor(), spec)?;
        let store = (&y * g)?.sum_all()?.backward()?;
        let get = |v: &Var| store.get(v.as_tensor()).cloned().expect("a gradient");
        Ok((y, get(x), get(w)))
    }

    fn check_against_reference(mode: PaddingMode, dtype: DType, tol: f64) -> Result<()> {
        let dev = Device::Cpu;
        for (seed, &(b, ci, h, w, co, k, s, p)) in CASES.iter().enumerate() {
            let spec = Conv2dSpec {
                stride: s,
                padding: p,
                mode,
            };
            let seed = 10 * seed as u64;
            let x = Var::from_tensor(&pseudo_random((b, ci, h, w), seed, dtype, &dev)?)?;
            let wt = Var::from_tensor(&pseudo_random((co, ci, k, k), seed + 1, dtype, &dev)?)?;
            let reference = conv2d_reference(x.as_tensor(), wt.as_tensor(), spec)?;
            let g = pseudo_random(reference.shape(), seed + 2, dtype, &dev)?;
            let (y, dx, dw) = value_and_grads(conv2d, &x, &wt, &g, spec)?;
            let (ry, rdx, rdw) = value_and_grads(conv2d_reference, &x, &wt, &g, spec)?;
            let case = format!("{mode:?} {dtype:?} x{:?} k{k} s{s} p{p}", (b, ci, h, w));
            assert_eq!(y.dims(), ry.dims(), "{case}");
            assert!(max_abs_diff(&y, &ry)? < tol, "forward {case}");
            assert!(max_abs_diff(&dx, &rdx)? < tol, "input gradient {case}");
            assert!(max_abs_diff(&dw, &rdw)? < tol, "weight gradient {case}");
        }
        Ok(())
    }

    #[test]
    fn conv_zero_padding_matches_candle_conv2d_and_its_gradients() -> Result<()> {
        // f64 sums of ≤ 2·5·16·(B·H·W ≤ 300) O(1) products in another order: rounding
        // ≈ 1e-13 at most; 1e-10 leaves margin and still catches any wrong tap (O(0.1)).
        check_against_reference(PaddingMode::Zeros, DType::F64, 1e-10)
    }

    /// With one operand a constant, the backward pass computes only the other's gradient
    /// (`needed`): it must still be the reference's, and of the right operand.
    #[test]
    fn a_constant_operand_gets_no_gradient_and_the_other_the_right_one() -> Result<()> {
        let dev = Device::Cpu;
        let spec = Conv2dSpec::zeros(1, 1);
        let x = Var::from_tensor(&pseudo_random((2, 3, 6, 5), 1, DType::F64, &dev)?)?;
        let w = Var::from_tensor(&pseudo_random((4, 3, 3, 3), 2, DType::F64, &dev)?)?;
        let g = pseudo_random((2, 4, 6, 5), 3, DType::F64, &dev)?;
        let (_, rdx, rdw) = value_and_grads(conv2d_reference, &x, &w, &g, spec)?;
        let grads = |x: &Tensor, w: &Tensor| -> Result<_> {
            (&conv2d(x, w, spec)? * &g)?.sum_all()?.backward()
        };
        let store = grads(&x.as_tensor().detach(), w.as_tensor())?;
        assert!(max_abs_diff(store.get(w.as_tensor()).expect("dw"), &rdw)? < 1e-10);
        let store = grads(x.as_tensor(), &w.as_tensor().detach())?;
        assert!(max_abs_diff(store.get(x.as_tensor()).expect("dx"), &rdx)? < 1e-10);
        assert!(store.get(w.as_tensor()).is_none());
        Ok(())
    }

    #[test]
    fn conv_circular_padding_matches_narrow_cat_reference() -> Result<()> {
        check_against_reference(PaddingMode::Circular, DType::F64, 1e-10)
    }

    #[test]
    fn conv_f32_matches_candle_conv2d() -> Result<()> {
        // f32: sums of ≤ 300 terms of magnitude ≤ 1, ε = 6e-8 ⇒ ≲ 300·6e-8 ≈ 2e-5 worst case.
        check_against_reference(PaddingMode::Zeros, DType::F32, 1e-4)?;
        check_against_reference(PaddingMode::Circular, DType::F32, 1e-4)
    }

    #[test]
    fn conv_circular_padding_of_a_whole_period_wraps_exactly() -> Result<()> {
        // padding = H = W: every tap wraps; still the narrow+cat reference.
        let dev = Device::Cpu;
        let x = pseudo_random((1, 2, 3, 3), 1, DType::F64, &dev)?;
        let w = pseudo_random((2, 2, 3, 3), 2, DType::F64, &dev)?;
        let spec = Conv2dSpec::circular(1, 3);
        let y = conv2d(&x, &w, spec)?;
        assert_eq!(y.dims4()?, (1, 2, 7, 7));
        assert!(max_abs_diff(&y, &conv2d_reference(&x, &w, spec)?)? < 1e-12);
        Ok(())
    }

    #[test]
    fn conv_gradients_match_finite_differences() -> Result<()> {
        // Independent of candle's backward. L = Σ g ⊙ conv(x, w) is linear in x and w, so
        // central differences are exact up to rounding ≈ 1e-16·|L|/δ ≈ 1e-13 (δ = 1e-3).
        // The second case is one where candle 0.11.1's own conv2d backward fails (1×1 stride
        // 2 with an unread last row: "shape mismatch in add" in its conv_transpose2d path).
        let dev = Device::Cpu;
        let cases = [
            ((1, 2, 5, 6), (3, 2, 4, 4), Conv2dSpec::circular(2, 1)),
            ((2, 3, 6, 5), (2, 3, 1, 1), Conv2dSpec::zeros(2, 0)),
        ];
        for (seed, (xs, ws, spec)) in cases.into_iter().enumerate() {
            let seed = 3 * seed as u64;
            let x0 = pseudo_random(xs, seed, DType::F64, &dev)?;
            let w0 = pseudo_random(ws, seed + 1, DType::F64, &dev)?;
            let ys = Geometry::new(xs, ws, spec)?.y_shape();
            let g = pseudo_random(ys, seed + 2, DType::F64, &dev)?;
            let (x, w) = (Var::from_tensor(&x0)?, Var::from_tensor(&w0)?);
            let (_, dx, dw) = value_and_grads(conv2d, &x, &w, &g, spec)?;
            let loss = |x: &Tensor, w: &Tensor| -> Result<f64> {
                (conv2d(x, w, spec)? * &g)?.sum_all()?.to_scalar::<f64>()
            };
            let delta = 1e-3;
            for (t0, grad, is_x) in [(&x0, &dx, true), (&w0, &dw, false)] {
                let base = t0.flatten_all()?.to_vec1::<f64>()?;
                let analytic = grad.flatten_all()?.to_vec1::<f64>()?;
                for (i, a) in analytic.iter().enumerate() {
                    let shifted = |d: f64| -> Result<f64> {
                        let mut v = base.clone();
                        v[i] += d;
                        let t = Tensor::from_vec(v, t0.shape(), &dev)?;
                        if is_x { loss(&t, &w0) } else { loss(&x0, &t) }
                    };
                    let fd = (shifted(delta)? - shifted(-delta)?) / (2.0 * delta);
                    assert!(
                        (a - fd).abs() < 1e-9,
                        "{spec:?} element {i} (x: {is_x}): {a} vs {fd}"
                    );
                }
            }
        }
        Ok(())
    }

    #[test]
    fn conv_kernels_write_every_output_element() -> Result<()> {
        // Poison the output buffers with NaN, run each kernel on every batch split (1 thread,
        // gemm-parallel batch < threads, rayon over images), and require finite values equal
        // to the reference.
        let dev = Device::Cpu;
        for (seed, &(b, ci, h, w, co, k, s, p)) in CASES.iter().enumerate() {
            for mode in [PaddingMode::Zeros, PaddingMode::Circular] {
                let spec = Conv2dSpec {
                    stride: s,
                    padding: p,
                    mode,
                };
                let seed = 7 * seed as u64;
                let x = pseudo_random((b, ci, h, w), seed, DType::F64, &dev)?;
                let wt = pseudo_random((co, ci, k, k), seed + 1, DType::F64, &dev)?;
                let g = Geometry::new(x.dims4()?, wt.dims4()?, spec)?;
                let dy = pseudo_random(g.y_shape(), seed + 2, DType::F64, &dev)?;
                let (xv, wv, dyv) = (
                    x.flatten_all()?.to_vec1::<f64>()?,
                    wt.flatten_all()?.to_vec1::<f64>()?,
                    dy.flatten_all()?.to_vec1::<f64>()?,
                );
                let reference = [
                    conv2d_reference(&x, &wt, spec)?,
                    apply_input_grad(g, &dy, &wt)?,
                    apply_weight_grad(g, &x, &dy)?,
                ];
                for threads in [1, 2, 3, 5] {
                    let mut y = vec![f64::NAN; g.y_shape().elem_count()];
                    forward_into(&g, &xv, &wv, &mut y, threads);
                    let mut dx = vec![f64::NAN; g.x_shape().elem_count()];
                    input_grad_into(&g, &dyv, &wv, &mut dx, threads);
                    let mut dw = vec![f64::NAN; g.w_shape().elem_count()];
                    weight_grad_into(&g, &xv, &dyv, &mut dw, threads);
                    for (out, r) in [(y, &reference[0]), (dx, &reference[1]), (dw, &reference[2])] {
                        assert!(out.iter().all(|v| v.is_finite()), "{g:?} threads {threads}");
                        let out = Tensor::from_vec(out, r.shape(), &dev)?;
                        // Same sums, other split: rounding only (see the tests above).
                        assert!(max_abs_diff(&out, r)? < 1e-10, "{g:?} threads {threads}");
                    }
                }
            }
        }
        Ok(())
    }

    #[test]
    fn conv_band_split_does_not_change_the_result() -> Result<()> {
        // 64 channels × 9 taps × 36 columns × 8 B = 162 KiB per output row: a 512 KiB band
        // holds 3 rows, so 16 rows take 6 bands, the last one partial.
        let dev = Device::Cpu;
        let x = pseudo_random((1, 64, 16, 36), 1, DType::F64, &dev)?;
        let w = pseudo_random((2, 64, 3, 3), 2, DType::F64, &dev)?;
        let spec = Conv2dSpec::circular(1, 1);
        let g = Geometry::new(x.dims4()?, w.dims4()?, spec)?;
        assert_eq!(g.band_rows(8), 3);
        let reference = conv2d_reference(&x, &w, spec)?;
        let y = conv2d(&x, &w, spec)?;
        // 576-term f64 dot products of O(1) values: rounding ≲ 1e-13.
        assert!(max_abs_diff(&y, &reference)? < 1e-10);
        // One image, six bands: with 2 or 3 threads the bands are the parallel tasks.
        let (xv, wv) = (x.flatten_all()?.to_vec1()?, w.flatten_all()?.to_vec1()?);
        for threads in [1, 2, 3] {
            let mut y = vec![f64::NAN; g.y_shape().elem_count()];
            forward_into(&g, &xv, &wv, &mut y, threads);
            let y = Tensor::from_vec(y, g.y_shape(), &dev)?;
            assert!(max_abs_diff(&y, &reference)? < 1e-10, "threads {threads}");
        }
        Ok(())
    }

    #[test]
    fn conv_rejects_inconsistent_arguments() -> Result<()> {
        let dev = Device::Cpu;
        let x = Tensor::zeros((1, 3, 4, 4), DType::F32, &dev)?;
        let err = |w: &Tensor, spec| conv2d(&x, w, spec).expect_err("invalid").to_string();
        let w = Tensor::zeros((2, 2, 3, 3), DType::F32, &dev)?;
        assert!(err(&w, Conv2dSpec::zeros(1, 1)).contains("channels"));
        let w = Tensor::zeros((2, 3, 3, 3), DType::F32, &dev)?;
        assert!(err(&w, Conv2dSpec::circular(1, 5)).contains("circular padding"));
        assert!(err(&w, Conv2dSpec::zeros(0, 1)).contains("stride"));
        let w = Tensor::zeros((2, 3, 7, 7), DType::F32, &dev)?;
        assert!(err(&w, Conv2dSpec::zeros(1, 1)).contains("larger"));
        let w64 = Tensor::zeros((2, 3, 3, 3), DType::F64, &dev)?;
        assert!(err(&w64, Conv2dSpec::zeros(1, 1)).contains("dtypes differ"));
        Ok(())
    }
}
