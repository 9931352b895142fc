//! Separable FIR filtering and resampling of NCHW images as candle custom ops: each spatial
//! axis is multiplied by a constant sparse matrix ([`AxisMatrix`]), one 1-D pass per axis.
//!
//! StyleGAN2's `upfirdn2d` with the `[1, 3, 3, 1]` filter (Karras et al. 2020, Appendix B)
//! is, per axis, a banded matrix with 2 (×2 upsampling) or 4 (blur, ×2 downsampling) non-zeros
//! per row; zero padding drops the taps outside the axis, circular padding wraps them onto the
//! opposite edge (the caller builds the matrix, e.g. `photomat_generator::fir`). Stored as
//! compressed rows, a pass costs as many multiply-adds per output as the filter has taps,
//! where a dense product (`out = M · x`, the reference below) costs the axis length: 32–1024.
//!
//! Each pass `y = M ×_axis x` is linear in `x`, so its backward is the pass of `Mᵀ` on the
//! output gradient, and the backward of that is the pass of `M` again: the op is
//! differentiable to any order (R1 through the discriminator's blur and downsampling,
//! `docs/neural-models.md`, "GAN training"), with no derivative w.r.t. the constant matrix.
//!
//! CPU tensors of dtype f32 and f64 take the sparse path, split over rayon above 65,536
//! output elements; on a vector family ([`crate::simd`]) the rows of an f32 width pass that
//! repeat (the filters' interior, away from the edges) run a vector of outputs at a time
//! ([`crate::fir_simd`]). Other
//! devices and dtypes, and every call inside
//! [`crate::reference::with_reference_ops`], use [`separable_reference`]: dense matrices and
//! candle's `matmul`, whose first and second derivatives are exact in candle 0.11
//! (`docs/candle-notes.md`, "Gradients that were checked and are right").

use std::sync::Arc;

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, DType, Device, Layout, Result, Shape, Tensor, bail};
use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::fir_simd::Periodic;
use crate::simd::{Kernel, Simd, SimdFamily, on_family};

use crate::threads::ELEMENTWISE_CHUNK as PARALLEL_ELEMENTS;

/// A constant `n_out × n_in` matrix stored as compressed rows: row `r` holds the pairs
/// `(cols[t], weights[t])` for `t` in `starts[r]..starts[r + 1]`, columns increasing and
/// distinct.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisMatrix {
    n_in: usize,
    starts: Vec<usize>,
    cols: Vec<usize>,
    weights: Vec<f64>,
}

impl AxisMatrix {
    /// Builds the matrix from its rows of `(column, weight)` pairs in any order; entries of a
    /// row with the same column are summed (a wrapped tap landing on an existing one), exact
    /// zeros are dropped.
    pub fn from_rows(n_in: usize, rows: &[Vec<(usize, f64)>]) -> Result<Self> {
        if n_in == 0 || rows.is_empty() {
            bail!("axis matrix: {} × {n_in} has an empty axis", rows.len());
        }
        let mut starts = Vec::with_capacity(rows.len() + 1);
        let (mut cols, mut weights) = (Vec::new(), Vec::new());
        starts.push(0);
        for (r, row) in rows.iter().enumerate() {
            let mut row = row.clone();
            if let Some(&(c, _)) = row.iter().find(|(c, _)| *c >= n_in) {
                bail!("axis matrix: row {r} reads column {c} of an axis of length {n_in}");
            }
            if let Some(&(c, w)) = row.iter().find(|(_, w)| !w.is_finite()) {
                bail!("axis matrix: row {r} has a non-finite weight {w} at column {c}");
            }
            row.sort_by_key(|&(c, _)| c);
            let start = cols.len();
            for (c, w) in row {
                if cols.len() > start && cols.last() == Some(&c) {
                    *weights.last_mut().expect("a weight per column") += w;
                } else {
                    cols.push(c);
                    weights.push(w);
                }
            }
            // Drop exact zeros (e.g. taps that cancelled), keeping the columns increasing.
            let mut keep = start;
            for t in start..cols.len() {
                if weights[t] != 0.0 {
                    cols[keep] = cols[t];
                    weights[keep] = weights[t];
                    keep += 1;
                }
            }
            cols.truncate(keep);
            weights.truncate(keep);
            starts.push(cols.len());
        }
        Ok(Self {
            n_in,
            starts,
            cols,
            weights,
        })
    }

    /// Rows (output length).
    pub fn n_out(&self) -> usize {
        self.starts.len() - 1
    }

    /// Columns (input length).
    pub fn n_in(&self) -> usize {
        self.n_in
    }

    /// The `(column, weight)` pairs of row `r`.
    pub fn row(&self, r: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let span = self.starts[r]..self.starts[r + 1];
        self.cols[span.clone()]
            .iter()
            .copied()
            .zip(self.weights[span].iter().copied())
    }

    /// The transposed matrix `Mᵀ` (`n_in × n_out`).
    pub fn transpose(&self) -> Self {
        let mut rows = vec![Vec::new(); self.n_in];
        for r in 0..self.n_out() {
            for (c, w) in self.row(r) {
                rows[c].push((r, w));
            }
        }
        // n_out ≥ 1 and n_in ≥ 1 (checked by `from_rows`): the transpose is valid.
        Self::from_rows(self.n_out(), &rows).expect("the transpose of a valid matrix is valid")
    }

    /// The matrix as a dense `(n_out, n_in)` tensor.
    pub fn to_dense(&self, dtype: DType, device: &Device) -> Result<Tensor> {
        let mut m = vec![0f64; self.n_out() * self.n_in];
        for r in 0..self.n_out() {
            for (c, w) in self.row(r) {
                m[r * self.n_in + c] = w;
            }
        }
        Tensor::from_vec(m, (self.n_out(), self.n_in), device)?.to_dtype(dtype)
    }

    /// Row weights converted to `T` once per pass.
    fn weights_as<T: candle_core::WithDType>(&self) -> Vec<T> {
        self.weights.iter().map(|&w| T::from_f64(w)).collect()
    }
}

/// The spatial axis a pass runs along.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Axis {
    /// Dimension 2 (H): every column of every plane is multiplied by the matrix.
    Height,
    /// Dimension 3 (W): every row of every plane is multiplied by the matrix.
    Width,
}

/// `M_H · X · M_Wᵀ` for every plane X: the width pass, then the height pass.
///
/// # Shapes
/// x (B, C, H, W), m_h (H' × H), m_w (W' × W) → (B, C, H', W').
pub fn separable(x: &Tensor, m_h: &AxisMatrix, m_w: &AxisMatrix) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    if m_h.n_in() != h || m_w.n_in() != w {
        bail!(
            "separable FIR: matrices for {}×{} applied to a {h}×{w} image",
            m_h.n_in(),
            m_w.n_in()
        );
    }
    let fast = x.device().is_cpu()
        && matches!(x.dtype(), DType::F32 | DType::F64)
        && !crate::reference::reference_ops();
    if !fast {
        let dense_h = m_h.to_dense(x.dtype(), x.device())?;
        let dense_w = m_w.to_dense(x.dtype(), x.device())?;
        return separable_reference(x, &dense_h, &dense_w);
    }
    let y = axis_pass(x, Arc::new(m_w.clone()), Axis::Width)?;
    axis_pass(&y, Arc::new(m_h.clone()), Axis::Height)
}

/// One pass of a constant matrix along `axis` (sparse CPU path; see [`separable`]).
///
/// # Shapes
/// x (B, C, H, W) → (B, C, n_out, W) along [`Axis::Height`], (B, C, H, n_out) along
/// [`Axis::Width`]; the axis must have the matrix's `n_in` elements.
pub fn axis_pass(x: &Tensor, m: Arc<AxisMatrix>, axis: Axis) -> Result<Tensor> {
    let (_b, _c, h, w) = x.dims4()?;
    let n = if axis == Axis::Height { h } else { w };
    if m.n_in() != n {
        bail!(
            "FIR pass: matrix for an axis of {} applied along {axis:?} of length {n}",
            m.n_in()
        );
    }
    let mt = Arc::new(m.transpose());
    x.contiguous()?.apply_op1(AxisPass { m, mt, axis })
}

/// The dense reference: `M_H · X · M_Wᵀ` by candle `matmul`s (exact first and second
/// derivatives), the path of other devices and of [`crate::reference::with_reference_ops`].
///
/// # Shapes
/// x (B, C, H, W), m_h (H', H), m_w (W', W) → (B, C, H', W').
pub fn separable_reference(x: &Tensor, m_h: &Tensor, m_w: &Tensor) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    let (h2, _) = m_h.dims2()?;
    let (w2, _) = m_w.dims2()?;
    // Columns: one large (B·C·H, W) · (W, W') product over contiguous rows.
    let y = x.contiguous()?.reshape((b * c * h, w))?.matmul(&m_w.t()?)?;
    // Rows: (H', H) · (H, W') per plane, the matrix broadcast with batch stride 0.
    let y = y.reshape((b * c, h, w2))?;
    let y = m_h.broadcast_left(b * c)?.matmul(&y)?;
    y.reshape((b, c, h2, w2))
}

/// `x ↦ M ×_axis x`, its backward the same op with `Mᵀ` (module docs).
struct AxisPass {
    m: Arc<AxisMatrix>,
    mt: Arc<AxisMatrix>,
    axis: Axis,
}

/// Writes every element of `out` (planes of `n_out × w`): row `j` of a plane is
/// `Σ_t weight_t · row cols_t` of the input plane (`n_in × w`).
fn height_pass<T: candle_core::WithDType>(m: &AxisMatrix, x: &[T], w: usize, out: &mut [T]) {
    let weights = m.weights_as::<T>();
    let (n_in, n_out) = (m.n_in(), m.n_out());
    let family = SimdFamily::active();
    let plane = |(o, x): (&mut [T], &[T])| {
        if family == SimdFamily::Scalar {
            return height_plane(m, &weights, w, o, x);
        }
        let weights = &weights[..];
        // SAFETY: the family is one the CPU has (`SimdFamily::active`).
        on_family!(family, S => unsafe { S::vectorize(HeightPlane { m, weights, w, o, x }) });
    };
    let (in_len, out_len) = (n_in * w, n_out * w);
    if out.len() < PARALLEL_ELEMENTS {
        out.chunks_mut(out_len)
            .zip(x.chunks(in_len))
            .for_each(plane);
    } else {
        out.par_chunks_mut(out_len)
            .zip(x.par_chunks(in_len))
            .for_each(plane);
    }
}

/// One plane of [`height_pass`]: output row `j` (`w` values) = `Σ_t weight_t · row cols_t`
/// of the input plane, as multiply-adds of whole rows.
#[inline(always)]
fn height_plane<T: candle_core::WithDType>(
    m: &AxisMatrix,
    weights: &[T],
    w: usize,
    o: &mut [T],
    x: &[T],
) {
    for j in 0..m.n_out() {
        let dst = &mut o[j * w..(j + 1) * w];
        let span = m.starts[j]..m.starts[j + 1];
        if span.is_empty() {
            dst.fill(T::from_f64(0.0));
            continue;
        }
        let mut taps = m.cols[span.clone()].iter().zip(&weights[span]);
        let (&c0, &w0) = taps.next().expect("a non-empty row");
        for (d, &s) in dst.iter_mut().zip(&x[c0 * w..(c0 + 1) * w]) {
            *d = w0 * s;
        }
        for (&c, &wt) in taps {
            for (d, &s) in dst.iter_mut().zip(&x[c * w..(c + 1) * w]) {
                *d += wt * s;
            }
        }
    }
}

/// [`height_plane`] as a [`Kernel`]: compiled for a vector family, its row loops vectorise
/// 16 (AVX-512) or 8 (AVX2) floats wide rather than the baseline x86-64's 4, with no fused
/// multiply-adds (Rust does not contract `a * b + c`), so every family rounds alike.
struct HeightPlane<'a, T> {
    m: &'a AxisMatrix,
    weights: &'a [T],
    w: usize,
    o: &'a mut [T],
    x: &'a [T],
}

impl<T: candle_core::WithDType> Kernel for HeightPlane<'_, T> {
    type Output = ();

    #[inline(always)]
    unsafe fn run<S: Simd>(self) {
        height_plane(self.m, self.weights, self.w, self.o, self.x)
    }
}

/// Widest band [`width_pass`] runs as dense dot products: StyleGAN2's `[1, 3, 3, 1]`
/// filter spans at most 4 input columns per output (blur, ×2 down) and its transposes 2–4.
const MAX_BAND: usize = 8;

/// The rows of a matrix as bands of `width` consecutive input columns: row `j` is the dot
/// product of `weights[j·width..(j + 1)·width]` with `x[first[j]..first[j] + width]`, zero
/// weights where the row has no tap. A row whose taps do not fit in `width` consecutive
/// columns (a tap wrapped onto the opposite edge of a circular axis) has `first[j] =`
/// [`Band::SPARSE`] and keeps the compressed-row path.
struct Band<T> {
    width: usize,
    first: Vec<usize>,
    weights: Vec<T>,
    /// f32 rows that repeat, run a vector of outputs at a time ([`crate::fir_simd`]).
    periodic: Option<Periodic>,
}

impl<T: candle_core::WithDType> Band<T> {
    const SPARSE: usize = usize::MAX;

    /// The band form of `m`, or `None` when no row is narrow enough to gain from it.
    fn new(m: &AxisMatrix) -> Option<Self> {
        let span = |j: usize| {
            let cols = &m.cols[m.starts[j]..m.starts[j + 1]];
            // Columns are increasing (`from_rows`): the span is last − first + 1.
            cols.first().map_or(0, |&c0| cols[cols.len() - 1] - c0 + 1)
        };
        let width = (0..m.n_out())
            .map(span)
            .filter(|&s| s <= MAX_BAND)
            .max()?
            .clamp(1, m.n_in());
        let mut first = vec![Self::SPARSE; m.n_out()];
        let mut weights = vec![T::from_f64(0.0); m.n_out() * width];
        for (j, f) in first.iter_mut().enumerate() {
            if span(j) > width {
                continue;
            }
            let cols = &m.cols[m.starts[j]..m.starts[j + 1]];
            // An empty row is a band of zeros; a band that would run past the last column
            // starts earlier, its weights shifted right by as much.
            let start = cols.first().copied().unwrap_or(0).min(m.n_in() - width);
            for (&c, &w) in cols.iter().zip(&m.weights[m.starts[j]..m.starts[j + 1]]) {
                weights[j * width + c - start] = T::from_f64(w);
            }
            *f = start;
        }
        let periodic = (T::DTYPE == DType::F32)
            .then(|| {
                let w32: Vec<f32> = weights.iter().map(|w| w.to_f64() as f32).collect();
                Periodic::find(&first, &w32, width, SimdFamily::active())
            })
            .flatten();
        Some(Self {
            width,
            first,
            weights,
            periodic,
        })
    }
}

/// Writes every element of `out` (rows of `n_out`): element `j` of a row is
/// `Σ_t weight_t · x[cols_t]` of the input row (`n_in`). Rows of the matrix that are bands
/// ([`Band`]) run as fixed-width dot products over contiguous input, which the compiler
/// unrolls; the others gather through the column list.
fn width_pass<T: candle_core::WithDType>(m: &AxisMatrix, x: &[T], out: &mut [T]) {
    let weights = m.weights_as::<T>();
    let band = Band::<T>::new(m);
    let (n_in, n_out) = (m.n_in(), m.n_out());
    let sparse = |j: usize, x: &[T]| {
        let span = m.starts[j]..m.starts[j + 1];
        let mut acc = T::from_f64(0.0);
        for (&c, &wt) in m.cols[span.clone()].iter().zip(&weights[span]) {
            acc += wt * x[c];
        }
        acc
    };
    let row = |(o, x): (&mut [T], &[T])| match &band {
        Some(b) => match b.width {
            1 => banded_row::<T, 1>(b, &sparse, x, o),
            2 => banded_row::<T, 2>(b, &sparse, x, o),
            3 => banded_row::<T, 3>(b, &sparse, x, o),
            4 => banded_row::<T, 4>(b, &sparse, x, o),
            5 => banded_row::<T, 5>(b, &sparse, x, o),
            6 => banded_row::<T, 6>(b, &sparse, x, o),
            7 => banded_row::<T, 7>(b, &sparse, x, o),
            _ => banded_row::<T, MAX_BAND>(b, &sparse, x, o),
        },
        None => {
            for (j, d) in o.iter_mut().enumerate() {
                *d = sparse(j, x);
            }
        }
    };
    if out.len() < PARALLEL_ELEMENTS {
        out.chunks_mut(n_out).zip(x.chunks(n_in)).for_each(row);
    } else {
        // Tasks of whole rows, ≈ 4096 outputs each, so that short rows are not one task each.
        let rows_per_task = (4096 / n_out.max(1)).max(1);
        out.par_chunks_mut(n_out * rows_per_task)
            .zip(x.par_chunks(n_in * rows_per_task))
            .for_each(|(o, x)| o.chunks_mut(n_out).zip(x.chunks(n_in)).for_each(row));
    }
}

/// One row of [`width_pass`] through a band of width `W` (`band.width == W`).
fn banded_row<T: candle_core::WithDType, const W: usize>(
    band: &Band<T>,
    sparse: &impl Fn(usize, &[T]) -> T,
    x: &[T],
    out: &mut [T],
) {
    debug_assert_eq!(band.width, W);
    let skip = match &band.periodic {
        Some(p) => {
            // SAFETY: `periodic` is only set for f32 bands (`Band::new`), so T is f32.
            let (x32, out32) = unsafe {
                (
                    std::slice::from_raw_parts(x.as_ptr() as *const f32, x.len()),
                    std::slice::from_raw_parts_mut(out.as_mut_ptr() as *mut f32, out.len()),
                )
            };
            p.run(x32, out32);
            p.rows()
        }
        None => 0..0,
    };
    // The rows before and after the periodic run, one dot product each.
    for j in (0..skip.start).chain(skip.end.max(skip.start)..out.len()) {
        let (d, w) = (&mut out[j], &band.weights[j * W..(j + 1) * W]);
        let f = band.first[j];
        if f == Band::<T>::SPARSE {
            *d = sparse(j, x);
            continue;
        }
        let xs: &[T; W] = x[f..f + W].try_into().expect("a band of W columns");
        let mut acc = T::from_f64(0.0);
        for t in 0..W {
            acc += w[t] * xs[t];
        }
        *d = acc;
    }
}

impl AxisPass {
    fn out_shape(&self, dims: &[usize]) -> Result<Shape> {
        let [b, c, h, w] = dims else {
            bail!("FIR pass: expected an NCHW tensor, got {dims:?}");
        };
        let n = if self.axis == Axis::Height { *h } else { *w };
        if n != self.m.n_in() {
            bail!("FIR pass: axis of length {n}, matrix for {}", self.m.n_in());
        }
        Ok(match self.axis {
            Axis::Height => (*b, *c, self.m.n_out(), *w).into(),
            Axis::Width => (*b, *c, *h, self.m.n_out()).into(),
        })
    }

    fn run<T: candle_core::WithDType>(&self, x: &[T], dims: &[usize], len: usize) -> Vec<T> {
        // SAFETY: both passes write every element (an empty row as zeros).
        let mut out = unsafe { output_buffer(len) };
        match self.axis {
            Axis::Height => height_pass(&self.m, x, dims[3], &mut out),
            Axis::Width => width_pass(&self.m, x, &mut out),
        }
        out
    }
}

impl CustomOp1 for AxisPass {
    fn name(&self) -> &'static str {
        "fir-axis-pass"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let dims = l.shape().dims();
        let shape = self.out_shape(dims)?;
        let Some((start, end)) = l.contiguous_offsets() else {
            bail!("fir-axis-pass: expected a contiguous tensor");
        };
        let len = shape.elem_count();
        let out = match s {
            CpuStorage::F32(v) => CpuStorage::F32(self.run(&v[start..end], dims, len)),
            CpuStorage::F64(v) => CpuStorage::F64(self.run(&v[start..end], dims, len)),
            other => bail!("fir-axis-pass: unsupported dtype {:?}", other.dtype()),
        };
        Ok((out, shape))
    }

    fn bwd(&self, _x: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let transposed = AxisPass {
            m: self.mt.clone(),
            mt: self.m.clone(),
            axis: self.axis,
        };
        Ok(Some(grad.contiguous()?.apply_op1(transposed)?))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::Var;

    use super::*;
    use crate::simd::with_simd_family;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    /// A banded matrix with `taps` weights per row starting at `r·step − offset`, wrapped
    /// (circular) or dropped (zero padding): the shapes of StyleGAN2's filters, with
    /// irregular weights so that a transposed or shifted tap cannot go unnoticed.
    fn banded(n_out: usize, n_in: usize, step: f64, taps: usize, wrap: bool) -> AxisMatrix {
        let rows: Vec<Vec<(usize, f64)>> = (0..n_out)
            .map(|r| {
                (0..taps)
                    .filter_map(|t| {
                        let c = (r as f64 * step).floor() as isize + t as isize - 1;
                        let w = 0.3 + 0.17 * t as f64 + 0.01 * r as f64;
                        if (0..n_in as isize).contains(&c) {
                            Some((c as usize, w))
                        } else if wrap {
                            Some((c.rem_euclid(n_in as isize) as usize, w))
                        } else {
                            None
                        }
                    })
                    .collect()
            })
            .collect();
        AxisMatrix::from_rows(n_in, &rows).expect("valid rows")
    }

    /// (B, C, H, W, H', W', taps, wrap).
    type Case = (usize, usize, usize, usize, usize, usize, usize, bool);

    /// Up, down, blur-like and odd sizes, batch 1.
    const CASES: &[Case] = &[
        (2, 3, 4, 5, 8, 10, 2, false),
        (1, 2, 8, 6, 4, 3, 4, true),
        (3, 1, 7, 9, 8, 10, 4, false),
        (1, 4, 5, 5, 10, 10, 2, true),
        // Large enough for the rayon split (≥ 65,536 outputs per pass).
        (2, 16, 32, 32, 64, 64, 2, true),
        // Rows wider than `MAX_BAND` (the width pass's compressed-row path only), and
        // bands cut short at the last column (shifted left in `Band`).
        (1, 2, 12, 12, 12, 12, 10, false),
        (1, 3, 6, 6, 6, 6, 5, false),
    ];

    fn value_and_grad(
        f: impl Fn(&Tensor) -> Result<Tensor>,
        x: &Var,
        g: &Tensor,
    ) -> Result<(Tensor, Tensor)> {
        let y = f(x.as_tensor())?;
        let grad = (&y * g)?.sum_all()?.backward()?;
        Ok((y, grad.get(x.as_tensor()).cloned().expect("a gradient")))
    }

    #[test]
    fn separable_matches_dense_matmul_and_its_gradient() -> Result<()> {
        let dev = Device::Cpu;
        for (i, &(b, c, h, w, h2, w2, taps, wrap)) in CASES.iter().enumerate() {
            let m_h = banded(h2, h, h as f64 / h2 as f64, taps, wrap);
            let m_w = banded(w2, w, w as f64 / w2 as f64, taps, wrap);
            let seed = 5 * i as u64;
            let x = Var::from_tensor(&pseudo_random((b, c, h, w), seed, DType::F64, &dev)?)?;
            let g = pseudo_random((b, c, h2, w2), seed + 1, DType::F64, &dev)?;
            let (dh, dw) = (
                m_h.to_dense(DType::F64, &dev)?,
                m_w.to_dense(DType::F64, &dev)?,
            );
            let (y, dx) = value_and_grad(|x| separable(x, &m_h, &m_w), &x, &g)?;
            let (ry, rdx) = value_and_grad(|x| separable_reference(x, &dh, &dw), &x, &g)?;
            assert_eq!(y.dims(), ry.dims());
            // f64 sums of ≤ 16 O(1) products vs dense sums with exact zeros: ≲ 1e-15.
            assert!(max_abs_diff(&y, &ry)? < 1e-12, "forward case {i}");
            assert!(max_abs_diff(&dx, &rdx)? < 1e-12, "gradient case {i}");
            // f32: ≤ 16-term sums of O(1) values, ε = 6e-8.
            let x32 = x.as_tensor().to_dtype(DType::F32)?;
            let y32 = separable(&x32, &m_h, &m_w)?.to_dtype(DType::F64)?;
            assert!(max_abs_diff(&y32, &ry)? < 1e-5, "f32 case {i}");
        }
        Ok(())
    }

    #[test]
    fn periodic_rows_match_the_dense_product() -> Result<()> {
        // StyleGAN2's [1, 3, 3, 1] / 8 with its real, equal weights in every row: blur
        // (period 1, shift 1), ×2 down (1, 2) and its transpose (2, 1), zero-padded and
        // wrapped, on even and odd lengths, rows of 9 to 65 outputs (a partial last vector,
        // one and several vectors), on every kernel family this CPU runs (forced, so that an
        // AVX-512 machine tests the AVX2 rows too). On a vector family the periodic run must
        // be found (else this tests nothing new); on every family the f32 pass must equal
        // the dense f64 product, and the scalar dot products to the bit.
        let dev = Device::Cpu;
        let taps = [1.0, 3.0, 3.0, 1.0].map(|t| t / 8.0);
        let filter = |n_out: usize, n_in: usize, step: usize, wrap: bool| {
            let rows: Vec<Vec<(usize, f64)>> = (0..n_out)
                .map(|r| {
                    (0..4)
                        .filter_map(|t| {
                            let c = (r * step + t) as isize - 2;
                            if (0..n_in as isize).contains(&c) {
                                Some((c as usize, taps[t]))
                            } else {
                                wrap.then(|| (c.rem_euclid(n_in as isize) as usize, taps[t]))
                            }
                        })
                        .collect()
                })
                .collect();
            AxisMatrix::from_rows(n_in, &rows).expect("valid rows")
        };
        for family in SimdFamily::ALL
            .into_iter()
            .filter(|&f| f <= SimdFamily::detected())
        {
            with_simd_family(family, || periodic_case(family, &dev, &filter)).1?;
        }
        Ok(())
    }

    /// [`periodic_rows_match_the_dense_product`] on one kernel family.
    fn periodic_case(
        family: SimdFamily,
        dev: &Device,
        filter: &dyn Fn(usize, usize, usize, bool) -> AxisMatrix,
    ) -> Result<()> {
        for n in [64, 40, 33, 20] {
            for wrap in [false, true] {
                let blur = filter(n + 1, n, 1, wrap);
                let down = filter(n / 2, n, 2, wrap);
                for (m, period, shift) in
                    [(blur, 1, 1), (down.clone(), 1, 2), (down.transpose(), 2, 1)]
                {
                    let case = format!("n {n} wrap {wrap} ({period}, {shift})");
                    let band = Band::<f32>::new(&m).expect("a band");
                    let case = format!("{family:?} {case}");
                    match band.periodic {
                        Some(p) => assert_eq!((p.period, p.shift), (period, shift), "{case}"),
                        None => assert_eq!(family, SimdFamily::Scalar, "{case}: no periodic run"),
                    }
                    let x = pseudo_random((2, 3, 5, m.n_in()), n as u64, DType::F64, dev)?;
                    let got =
                        axis_pass(&x.to_dtype(DType::F32)?, Arc::new(m.clone()), Axis::Width)?;
                    let dense = m.to_dense(DType::F64, dev)?;
                    let want = x
                        .reshape((30, m.n_in()))?
                        .matmul(&dense.t()?)?
                        .reshape(got.shape())?;
                    // f32 sums of 4 products of values in [−1, 1]: rounding ≲ 4·6e-8.
                    let err = max_abs_diff(&got.to_dtype(DType::F64)?, &want)?;
                    assert!(err < 1e-6, "{case}: {err}");
                    // And to the bit the f32 dot products of the scalar rows (taps in column
                    // order, multiply then add): a value must not depend on the path its row
                    // takes, or rolling a tileable generator's input would not roll its output.
                    let xs = x.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
                    let weights = m.weights_as::<f32>();
                    let scalar: Vec<f32> = xs
                        .chunks(m.n_in())
                        .flat_map(|row| {
                            (0..m.n_out()).map(|j| {
                                let span = m.starts[j]..m.starts[j + 1];
                                let mut acc = 0.0f32;
                                for (&c, &w) in m.cols[span.clone()].iter().zip(&weights[span]) {
                                    acc += w * row[c];
                                }
                                acc
                            })
                        })
                        .collect();
                    assert_eq!(got.flatten_all()?.to_vec1::<f32>()?, scalar, "{case}");
                }
            }
        }
        Ok(())
    }

    #[test]
    fn backward_of_the_backward_is_the_forward_pass() -> Result<()> {
        // The gradient op is the pass of Mᵀ; differentiating *it* must give the pass of M
        // (what a double backward through D's blur runs): L = Σ g ⊙ (Mᵀ ×_axis u), ∂L/∂u =
        // M ×_axis g, checked against the dense product.
        let dev = Device::Cpu;
        let m = banded(6, 9, 1.5, 4, true);
        for axis in [Axis::Height, Axis::Width] {
            let (shape_u, shape_x) = match axis {
                Axis::Height => ((2, 3, 6, 5), (2, 3, 9, 5)),
                Axis::Width => ((2, 3, 5, 6), (2, 3, 5, 9)),
            };
            let u = Var::from_tensor(&pseudo_random(shape_u, 1, DType::F64, &dev)?)?;
            let g = pseudo_random(shape_x, 2, DType::F64, &dev)?;
            let op = AxisPass {
                m: Arc::new(m.transpose()),
                mt: Arc::new(m.clone()),
                axis,
            };
            let (_, du) = value_and_grad(|u| u.apply_op1(op.clone_op()), &u, &g)?;
            let reference = axis_pass(&g, Arc::new(m.clone()), axis)?;
            let dense = m.to_dense(DType::F64, &dev)?;
            let expected = match axis {
                Axis::Height => dense.broadcast_left(6)?.matmul(&g.reshape((6, 9, 5))?)?,
                Axis::Width => g.reshape((30, 9))?.matmul(&dense.t()?)?,
            }
            .reshape(shape_u)?;
            assert!(max_abs_diff(&du, &expected)? < 1e-12, "{axis:?}");
            assert!(max_abs_diff(&reference, &expected)? < 1e-12, "{axis:?}");
        }
        Ok(())
    }

    impl AxisPass {
        fn clone_op(&self) -> AxisPass {
            AxisPass {
                m: self.m.clone(),
                mt: self.mt.clone(),
                axis: self.axis,
            }
        }
    }

    #[test]
    fn passes_write_every_output_element() {
        // Poison the outputs with NaN; every element must be overwritten, including rows of
        // the matrix that have no taps (zero padding can leave a row empty).
        let mut rows = vec![vec![(0usize, 1.0f64), (2, 0.5)], vec![], vec![(1, 2.0)]];
        rows.push(vec![(2, 1.0), (0, 1.0), (2, 1.0)]);
        let m = AxisMatrix::from_rows(3, &rows).expect("valid");
        let x: Vec<f64> = (0..2 * 3 * 4).map(|i| i as f64 * 0.25 - 1.0).collect();
        let mut out = vec![f64::NAN; 2 * 4 * 4];
        height_pass(&m, &x, 4, &mut out);
        assert!(out.iter().all(|v| v.is_finite()));
        // Plane 0, row 3 = 2·x[2] + x[0]: duplicate columns were summed.
        for k in 0..4 {
            assert_eq!(out[3 * 4 + k], 2.0 * x[2 * 4 + k] + x[k]);
            assert_eq!(out[4 + k], 0.0);
        }
        let mut out = vec![f64::NAN; 8 * 4];
        width_pass(&m, &x, &mut out);
        assert!(out.iter().all(|v| v.is_finite()));
        assert_eq!(out[3], 2.0 * x[2] + x[0]);
        assert_eq!(out[1], 0.0);
    }

    #[test]
    fn axis_matrix_transpose_and_errors() -> Result<()> {
        let m = banded(5, 4, 0.8, 3, true);
        let dev = Device::Cpu;
        let d = m.to_dense(DType::F64, &dev)?;
        let dt = m.transpose().to_dense(DType::F64, &dev)?;
        assert_eq!(max_abs_diff(&d.t()?.contiguous()?, &dt)?, 0.0);
        assert_eq!(m.transpose().transpose(), m);
        assert!(AxisMatrix::from_rows(3, &[vec![(3, 1.0)]]).is_err());
        assert!(AxisMatrix::from_rows(3, &[vec![(0, f64::NAN)]]).is_err());
        assert!(AxisMatrix::from_rows(0, &[]).is_err());
        let x = Tensor::zeros((1, 1, 4, 5), DType::F32, &dev)?;
        let err = separable(&x, &m, &m).expect_err("wrong size").to_string();
        assert!(err.contains("4×5"), "{err}");
        Ok(())
    }

    #[test]
    fn reference_mode_gives_the_same_values() -> Result<()> {
        let dev = Device::Cpu;
        let m = banded(8, 4, 0.5, 2, false);
        let x = pseudo_random((1, 2, 4, 4), 3, DType::F64, &dev)?;
        let fast = separable(&x, &m, &m)?;
        let reference = crate::reference::with_reference_ops(|| separable(&x, &m, &m))?;
        assert!(max_abs_diff(&fast, &reference)? < 1e-12);
        Ok(())
    }
}
