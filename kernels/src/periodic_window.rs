//! A window of each sample's periodic extension, one origin per sample, as a candle custom op
//! that is differentiable to any order: how a tileable generator's output is rolled by a
//! random offset and cut to the training resolution (`docs/neural-models.md`, "GAN training";
//! the spatial generator's patches, `docs/conventions.md`).
//!
//! ```text
//! window(x, o, (h', w'))[b, c, y, x] = x[b, c, (y + o_b.0) mod H, (x + o_b.1) mod W]
//! ```
//!
//! for y < h', x < w'. Composed from candle ops this is a `narrow` per sample, two `roll`s
//! (each two `narrow`s and a `cat`), a `cat` over the batch and a `narrow` to the window: a
//! dozen copies forward, and backward a zero-filled, padded copy for every `narrow`. Here it
//! is one gather pass forward; the backward is its adjoint, one scatter-add of the gradient
//! into a zeroed map of the input's size (each window texel back onto the texel it read), and
//! the adjoint's own backward is the gather again, so second derivatives (path-length
//! regularisation through G) stay on these two ops.
//!
//! CPU tensors of dtype f32 and f64 take this path; other devices and dtypes, and calls inside
//! [`crate::reference::with_reference_ops`], use the candle composition
//! ([`periodic_window_reference`]).

use candle_core::{CpuStorage, CustomOp1, Layout, Result, Shape, Tensor, WithDType, bail};
use rayon::prelude::*;

use crate::alloc::output_buffer;
use crate::storage::contiguous;

use crate::threads::ELEMENTWISE_CHUNK as CHUNK;

/// The `(h', w')` window at `origins[b]` = (row, column) of each sample's periodic extension.
///
/// # Shapes
/// x (B, C, H, W), `origins.len()` = B with row < H and column < W → (B, C, h', w'), any
/// h', w' ≥ 1 (a window larger than the map repeats it).
pub fn periodic_window(
    x: &Tensor,
    origins: &[(usize, usize)],
    window: (usize, usize),
) -> Result<Tensor> {
    let geometry = WindowGeometry::new(x.dims4()?, origins, window)?;
    let fast = x.device().is_cpu()
        && matches!(x.dtype(), candle_core::DType::F32 | candle_core::DType::F64)
        && !crate::reference::reference_ops();
    if fast {
        x.contiguous()?.apply_op1(Gather(geometry))
    } else {
        periodic_window_reference(x, origins, window)
    }
}

/// The same window from candle ops: per sample, the map tiled 2×2 (or more, for a window
/// larger than the map) and cut at the origin.
///
/// # Shapes
/// As [`periodic_window`].
pub fn periodic_window_reference(
    x: &Tensor,
    origins: &[(usize, usize)],
    (wh, ww): (usize, usize),
) -> Result<Tensor> {
    let (b, _, h, w) = x.dims4()?;
    WindowGeometry::new((b, 0, h, w), origins, (wh, ww))?;
    let (reps_y, reps_x) = (wh.div_ceil(h) + 1, ww.div_ceil(w) + 1);
    let row = Tensor::cat(&vec![x; reps_x], 3)?;
    let tiled = Tensor::cat(&vec![&row; reps_y], 2)?;
    let parts = origins
        .iter()
        .enumerate()
        .map(|(i, &(oy, ox))| tiled.narrow(0, i, 1)?.narrow(2, oy, wh)?.narrow(3, ox, ww))
        .collect::<Result<Vec<_>>>()?;
    Tensor::cat(&parts, 0)
}

/// Shapes and origins of one window op.
#[derive(Debug, Clone)]
struct WindowGeometry {
    /// Input (B, C, H, W).
    input: (usize, usize, usize, usize),
    /// Window (h', w').
    window: (usize, usize),
    /// (row, column) of each sample's window in its input.
    origins: Vec<(usize, usize)>,
}

impl WindowGeometry {
    fn new(
        input: (usize, usize, usize, usize),
        origins: &[(usize, usize)],
        window: (usize, usize),
    ) -> Result<Self> {
        let (b, _, h, w) = input;
        if origins.len() != b {
            bail!(
                "periodic window: {} origins for a batch of {b}",
                origins.len()
            );
        }
        if window.0 == 0 || window.1 == 0 || h == 0 || w == 0 {
            bail!("periodic window: an empty map or window ({h}×{w} → {window:?})");
        }
        if let Some(&(oy, ox)) = origins.iter().find(|&&(oy, ox)| oy >= h || ox >= w) {
            bail!("periodic window: origin ({oy}, {ox}) outside the {h}×{w} map");
        }
        Ok(Self {
            input,
            window,
            origins: origins.to_vec(),
        })
    }

    fn input_shape(&self) -> Shape {
        self.input.into()
    }

    fn window_shape(&self) -> Shape {
        let (b, c, _, _) = self.input;
        (b, c, self.window.0, self.window.1).into()
    }

    /// Calls `f(window row, input row, runs)` for each row of plane `p` (sample `p / C`) of the
    /// window, with the runs `(window column, input column, length)` that cover the window
    /// row without wrapping inside a run.
    fn rows(&self, p: usize, mut f: impl FnMut(usize, usize, &[(usize, usize, usize)])) {
        let (_, c, h, w) = self.input;
        let (wh, ww) = self.window;
        let (oy, ox) = self.origins[p / c];
        let mut runs = Vec::with_capacity(ww / w + 2);
        let mut x0 = 0;
        while x0 < ww {
            let sx = (x0 + ox) % w;
            let len = (ww - x0).min(w - sx);
            runs.push((x0, sx, len));
            x0 += len;
        }
        for y in 0..wh {
            f(y, (y + oy) % h, &runs);
        }
    }
}

/// x → its windows (module docs).
struct Gather(WindowGeometry);

impl Gather {
    fn run<T: WithDType>(&self, x: &[T]) -> Vec<T> {
        let g = &self.0;
        let (_, _, h, w) = g.input;
        let (wh, ww) = g.window;
        let len = g.window_shape().elem_count();
        // SAFETY: the runs of each row cover the whole window row, so every element is written.
        let mut out = unsafe { output_buffer(len) };
        let plane = |(p, o): (usize, &mut [T])| {
            let src = &x[p * h * w..(p + 1) * h * w];
            g.rows(p, |y, sy, runs| {
                for &(x0, sx, n) in runs {
                    o[y * ww + x0..y * ww + x0 + n].copy_from_slice(&src[sy * w + sx..][..n]);
                }
            });
        };
        if len <= CHUNK {
            out.chunks_mut(wh * ww).enumerate().for_each(plane);
        } else {
            out.par_chunks_mut(wh * ww).enumerate().for_each(plane);
        }
        out
    }
}

impl CustomOp1 for Gather {
    fn name(&self) -> &'static str {
        "periodic-window"
    }

    fn cpu_fwd(&self, x: &CpuStorage, lx: &Layout) -> Result<(CpuStorage, Shape)> {
        if lx.shape() != &self.0.input_shape() {
            bail!(
                "{}: input {:?}, expected {:?}",
                self.name(),
                lx.shape(),
                self.0.input
            );
        }
        let out = match x {
            CpuStorage::F32(x) => CpuStorage::F32(self.run(contiguous(x, lx, self.name())?)),
            CpuStorage::F64(x) => CpuStorage::F64(self.run(contiguous(x, lx, self.name())?)),
            _ => bail!("{}: expected f32 or f64", self.name()),
        };
        Ok((out, self.0.window_shape()))
    }

    fn bwd(&self, _x: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad.contiguous()?.apply_op1(Scatter(self.0.clone()))?))
    }
}

/// The adjoint of [`Gather`]: window gradients added back onto the texels they read.
struct Scatter(WindowGeometry);

impl Scatter {
    fn run<T: WithDType>(&self, grad: &[T]) -> Vec<T> {
        let g = &self.0;
        let (_, _, h, w) = g.input;
        let (wh, ww) = g.window;
        let len = g.input_shape().elem_count();
        // Zeroed: a window smaller than the map leaves texels no gradient reaches.
        let mut out = vec![T::from_f64(0.0); len];
        let plane = |(p, o): (usize, &mut [T])| {
            let src = &grad[p * wh * ww..(p + 1) * wh * ww];
            g.rows(p, |y, sy, runs| {
                for &(x0, sx, n) in runs {
                    let dst = &mut o[sy * w + sx..][..n];
                    for (d, &s) in dst.iter_mut().zip(&src[y * ww + x0..][..n]) {
                        *d += s;
                    }
                }
            });
        };
        if len <= CHUNK {
            out.chunks_mut(h * w).enumerate().for_each(plane);
        } else {
            out.par_chunks_mut(h * w).enumerate().for_each(plane);
        }
        out
    }
}

impl CustomOp1 for Scatter {
    fn name(&self) -> &'static str {
        "periodic-window-adjoint"
    }

    fn cpu_fwd(&self, g: &CpuStorage, lg: &Layout) -> Result<(CpuStorage, Shape)> {
        if lg.shape() != &self.0.window_shape() {
            bail!(
                "{}: gradient {:?}, expected {:?}",
                self.name(),
                lg.shape(),
                self.0.window_shape()
            );
        }
        let out = match g {
            CpuStorage::F32(g) => CpuStorage::F32(self.run(contiguous(g, lg, self.name())?)),
            CpuStorage::F64(g) => CpuStorage::F64(self.run(contiguous(g, lg, self.name())?)),
            _ => bail!("{}: expected f32 or f64", self.name()),
        };
        Ok((out, self.0.input_shape()))
    }

    fn bwd(&self, _g: &Tensor, _y: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(grad.contiguous()?.apply_op1(Gather(self.0.clone()))?))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::reference::with_reference_ops;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    /// (input shape, origins, window): a window inside the map, the map itself rolled, one
    /// larger than the map (texels read twice), and a map large enough for the rayon split.
    type Case = (
        (usize, usize, usize, usize),
        Vec<(usize, usize)>,
        (usize, usize),
    );

    fn cases() -> Vec<Case> {
        vec![
            ((2, 3, 7, 9), vec![(3, 5), (6, 0)], (4, 5)),
            ((2, 2, 5, 6), vec![(1, 2), (4, 5)], (5, 6)),
            ((1, 2, 3, 4), vec![(2, 1)], (7, 9)),
            ((2, 8, 68, 68), vec![(10, 60), (67, 3)], (64, 64)),
        ]
    }

    #[test]
    fn window_reads_the_periodic_extension() -> Result<()> {
        // Values equal to their flat index: the window's texel (y, x) of sample b must hold
        // the index of ((y + oy) mod H, (x + ox) mod W).
        let (h, w) = (3, 4);
        let x = Tensor::arange(0f32, (2 * h * w) as f32, &Device::Cpu)?.reshape((2, 1, h, w))?;
        let origins = [(0, 0), (2, 3)];
        let y = periodic_window(&x, &origins, (5, 6))?;
        assert_eq!(y.dims(), [2, 1, 5, 6]);
        let v = y.flatten_all()?.to_vec1::<f32>()?;
        for (b, &(oy, ox)) in origins.iter().enumerate() {
            for r in 0..5 {
                for c in 0..6 {
                    let expected = (b * h * w + ((r + oy) % h) * w + (c + ox) % w) as f32;
                    assert_eq!(v[(b * 5 + r) * 6 + c], expected, "sample {b} at ({r}, {c})");
                }
            }
        }
        Ok(())
    }

    #[test]
    fn window_and_its_adjoint_match_the_candle_composition() -> Result<()> {
        let dev = Device::Cpu;
        for (i, (shape, origins, window)) in cases().into_iter().enumerate() {
            let seed = 30 * i as u64;
            let x = Var::from_tensor(&pseudo_random(shape, seed, DType::F64, &dev)?)?;
            let (b, c, _, _) = shape;
            let g = pseudo_random((b, c, window.0, window.1), seed + 1, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = periodic_window(x.as_tensor(), &origins, window)?;
                let dx = (&y * &g)?.sum_all()?.backward()?;
                Ok(vec![y, dx.get(x.as_tensor()).expect("dx").clone()])
            };
            let fast = run()?;
            let reference = with_reference_ops(run)?;
            for (j, (a, r)) in fast.iter().zip(&reference).enumerate() {
                assert_eq!(a.dims(), r.dims());
                // Copies, and sums of at most four of the same values in another order.
                assert!(max_abs_diff(a, r)? < 1e-12, "case {i}, output {j}");
            }
        }
        Ok(())
    }

    #[test]
    fn window_rejects_bad_origins_and_empty_windows() -> Result<()> {
        let x = Tensor::zeros((2, 1, 3, 4), DType::F32, &Device::Cpu)?;
        let err = periodic_window(&x, &[(0, 0)], (2, 2)).expect_err("one origin for two");
        assert!(
            err.to_string().contains("1 origins for a batch of 2"),
            "{err}"
        );
        let err = periodic_window(&x, &[(0, 0), (3, 0)], (2, 2)).expect_err("row 3 of 3");
        assert!(err.to_string().contains("outside the 3×4 map"), "{err}");
        assert!(periodic_window(&x, &[(0, 0), (0, 0)], (0, 2)).is_err());
        Ok(())
    }
}
