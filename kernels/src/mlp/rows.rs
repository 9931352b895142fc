//! Texel rows in blocks: where a texel's channels live in each operand ([`Plane`], [`Io`]),
//! the blocks of [`BLOCK_ROWS`] rows the passes run one at a time ([`Block`]), their gather
//! and scatter, the scratch slots of a block's layers, and the parameter-gradient sums that do
//! not depend on which thread took which block ([`sum_over_runs`]).

use candle_core::{CpuStorage, Layout, Result, Shape, WithDType, bail};
use rayon::prelude::*;

/// Texel rows per block. A block's working set backward is three activation buffers of
/// `BLOCK_ROWS × 64` values (192 KiB in f32) plus the weights, well inside the 1 MiB L2 per
/// core of the build machine, and `gemm` still sees 256-row operands.
pub const BLOCK_ROWS: usize = 256;

/// Where channel c of texel p of image b lives in one operand:
/// `b·batch_stride + c·channel_stride + p·pixel_stride`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plane {
    pub(super) channels: usize,
    pub(super) batch_stride: usize,
    pub(super) channel_stride: usize,
    pub(super) pixel_stride: usize,
}

impl Plane {
    pub(super) fn nchw(channels: usize, pixels: usize) -> Self {
        Self {
            channels,
            batch_stride: channels * pixels,
            channel_stride: pixels,
            pixel_stride: 1,
        }
    }

    pub(super) fn rows(channels: usize, n: usize) -> Self {
        Self {
            channels,
            batch_stride: channels * n,
            channel_stride: 1,
            pixel_stride: channels,
        }
    }
}

/// The op's operands: B images of `pixels` texels, the input planes whose channels make up a
/// row, the output plane.
#[derive(Debug, Clone)]
pub(super) struct Io {
    pub(super) batch: usize,
    pub(super) pixels: usize,
    pub(super) inputs: Vec<Plane>,
    pub(super) output: Plane,
    pub(super) output_shape: Shape,
}

/// A run of texels of one image, rows `row .. row + len` of the (B·pixels) rows.
#[derive(Debug, Clone, Copy)]
pub(super) struct Block {
    pub(super) image: usize,
    pub(super) first: usize,
    pub(super) len: usize,
    pub(super) row: usize,
}

impl Io {
    pub(super) fn rows(&self) -> usize {
        self.batch * self.pixels
    }

    pub(super) fn blocks(&self) -> Vec<Block> {
        let mut out = Vec::new();
        for image in 0..self.batch {
            for first in (0..self.pixels).step_by(BLOCK_ROWS) {
                let len = BLOCK_ROWS.min(self.pixels - first);
                out.push(Block {
                    image,
                    first,
                    len,
                    row: image * self.pixels + first,
                });
            }
        }
        out
    }

    /// Element count of every input plane (their packed gradients, in order).
    pub(super) fn input_lens(&self) -> Vec<usize> {
        self.inputs
            .iter()
            .map(|p| p.batch_stride * self.batch)
            .collect()
    }

    pub(super) fn output_len(&self) -> usize {
        self.output.batch_stride * self.batch
    }
}

/// Copies the block's rows of `planes` (channels concatenated) into `dst` (len × width).
pub(super) fn gather<T: Copy>(
    planes: &[Plane],
    data: &[&[T]],
    blk: Block,
    width: usize,
    dst: &mut [T],
) {
    let mut c0 = 0;
    for (p, d) in planes.iter().zip(data) {
        for c in 0..p.channels {
            let base = blk.image * p.batch_stride + c * p.channel_stride;
            for r in 0..blk.len {
                dst[r * width + c0 + c] = d[base + (blk.first + r) * p.pixel_stride];
            }
        }
        c0 += p.channels;
    }
}

/// A destination written from several rayon tasks, each task writing the elements of its own
/// texels only.
pub(super) struct Scatter<T> {
    ptr: *mut T,
    pub(super) len: usize,
}

unsafe impl<T: Send> Send for Scatter<T> {}

// SAFETY: as above.
unsafe impl<T: Send> Sync for Scatter<T> {}

impl<T: Copy> Scatter<T> {
    pub(super) fn new(v: &mut [T]) -> Self {
        Self {
            ptr: v.as_mut_ptr(),
            len: v.len(),
        }
    }

    /// Writes the block's rows `src` (len × width, channels of `planes` concatenated), plus
    /// `bias` per channel when given, into their planes, plane k starting at `offsets[k]`.
    pub(super) fn put(
        &self,
        planes: &[Plane],
        offsets: &[usize],
        blk: Block,
        width: usize,
        src: &[T],
        bias: Option<&[T]>,
    ) where
        T: std::ops::Add<Output = T>,
    {
        let mut c0 = 0;
        for (p, &off) in planes.iter().zip(offsets) {
            for c in 0..p.channels {
                let base = off + blk.image * p.batch_stride + c * p.channel_stride;
                let b = bias.map(|b| b[c0 + c]);
                for r in 0..blk.len {
                    let i = base + (blk.first + r) * p.pixel_stride;
                    assert!(i < self.len, "per-texel mlp: write out of bounds");
                    let v = src[r * width + c0 + c];
                    let v = match b {
                        Some(b) => v + b,
                        None => v,
                    };
                    // SAFETY: in bounds (checked); disjoint across tasks (see `Send`).
                    unsafe { *self.ptr.add(i) = v };
                }
            }
            c0 += p.channels;
        }
    }
}

/// Slot `read` for reading and slot `write` (≠ `read`) for writing, slots of `len` values.
pub(super) fn two_slots<T>(
    buf: &mut [T],
    len: usize,
    read: usize,
    write: usize,
) -> (&[T], &mut [T]) {
    debug_assert_ne!(read, write);
    if read < write {
        let (a, b) = buf.split_at_mut(write * len);
        (&a[read * len..(read + 1) * len], &mut b[..len])
    } else {
        let (a, b) = buf.split_at_mut(read * len);
        (&b[..len], &mut a[write * len..(write + 1) * len])
    }
}

/// Splits `buf` into one chunk of `block.len · per_row` values per block, in order.
pub(super) fn split_blocks<'a, T>(
    mut buf: &'a mut [T],
    blocks: &[Block],
    per_row: usize,
) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(blocks.len());
    for b in blocks {
        let (head, tail) = buf.split_at_mut(b.len * per_row);
        out.push(head);
        buf = tail;
    }
    out
}

/// Folds `items` in order into one task state per fixed run of consecutive items (as many runs
/// as rayon has threads), then adds the runs' sums (`sums` of each state) in run order. The
/// parameter gradients then depend on the thread count only, not on which thread took which
/// block: with rayon's `fold` + `reduce` the grouping followed work stealing, and two training
/// runs with the same seed drifted apart in the last bits from their fourth step on.
pub(super) fn sum_over_runs<I: Send, S, T: WithDType>(
    items: Vec<I>,
    new_state: impl Fn() -> S + Sync + Send,
    fold: impl Fn(S, I) -> S + Sync + Send,
    sums: impl Fn(S) -> Vec<T> + Sync + Send,
) -> Vec<T> {
    let per = items.len().div_ceil(rayon::current_num_threads()).max(1);
    // At least one run, so that no items still give the state's zero sums.
    let mut runs: Vec<Vec<I>> = vec![Vec::new()];
    for item in items {
        if runs[runs.len() - 1].len() == per {
            runs.push(Vec::new());
        }
        let last = runs.len() - 1;
        runs[last].push(item);
    }
    let partials: Vec<Vec<T>> = runs
        .into_par_iter()
        .map(|run| sums(run.into_iter().fold(new_state(), &fold)))
        .collect();
    let mut partials = partials.into_iter();
    let mut total = partials.next().unwrap_or_default();
    for part in partials {
        for (a, b) in total.iter_mut().zip(part) {
            *a += b;
        }
    }
    total
}

/// Runs `f` over the blocks with their chunks of `saved`, on rayon's pool.
pub(super) fn for_blocks<T: Send, S: Send>(
    items: Vec<(Block, &mut [T])>,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, Block, &mut [T]) + Sync + Send,
) {
    items
        .into_par_iter()
        .for_each_init(init, |s, (blk, chunk)| f(s, blk, chunk));
}

/// Input slices of the operands, checked contiguous and sized.
pub(super) fn operand<'a, T: WithDType>(
    s: &'a CpuStorage,
    l: &Layout,
    len: usize,
    what: &str,
) -> Result<&'a [T]> {
    let v = T::cpu_storage_as_slice(s)?;
    let Some((start, end)) = l.contiguous_offsets() else {
        bail!("per-texel mlp: {what} is not contiguous");
    };
    if end - start != len {
        bail!(
            "per-texel mlp: {what} has {} elements, expected {len}",
            end - start
        );
    }
    Ok(&v[start..end])
}
