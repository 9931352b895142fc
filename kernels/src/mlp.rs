//! A per-texel MLP (PhotoMat's relighting network M, paper §3 "Relightable generator" and §4
//! "Implementation") as one fused CPU op with its backward pass.
//!
//! Every texel is one row of a chain of fully connected layers
//!
//! ```text
//! h₋₁ = x (the texel's input channels),  zᵢ = hᵢ₋₁·Ŵᵢᵀ + b̂ᵢ,
//! hᵢ = gain · LeakyReLU(zᵢ, slope) for i < L − 1,  y = z_{L−1},
//! ```
//!
//! with effective weights `Ŵᵢ = weight_gainᵢ · Wᵢ` and biases `b̂ᵢ = bias_gainᵢ · bᵢ` (the
//! equalised learning rate of Karras et al. 2018 §4.1). Composed from candle ops this is one
//! transpose and concatenation of the NCHW inputs into rows, per layer a scaled weight, its
//! transpose, a matrix product, a bias and an activation pass, and a transpose back — with as
//! many passes again backward (`docs/benchmarks.md` measured it at 2.7–4.3× PyTorch's CPU
//! time). Here the rows are processed in blocks of [`BLOCK_ROWS`] texels, each block running
//! the whole chain while its activations are in L2: the block's inputs are gathered straight
//! from the NCHW tensors (the `F ‖ ω` concatenation exists only block by block), every layer
//! is one `gemm` call on row-major activations against the weights arranged once per call,
//! bias and activation run on the cache-hot block right after it, and the last layer writes
//! the NCHW output. Blocks run in parallel on rayon's pool.
//!
//! The forward keeps the hidden activations (only when an input is tracked, so inference
//! keeps none) for the backward, which runs the chain in reverse per block: input gradients
//! of both inputs written in their NCHW layout, weight and bias gradients accumulated per
//! rayon task.
//!
//! # Higher derivatives
//! Path-length regularisation (StyleGAN2 §3.2) differentiates the input gradient of M again
//! with respect to M's weights (and, through F, G's). The input gradient
//! `dx = dy·Ŵ_{L−1}·D_{L−2}·Ŵ_{L−2} ⋯ D₀·Ŵ₀` (Dᵢ the diagonal LeakyReLU derivatives, piecewise
//! constant, so of zero derivative wherever it exists) is multilinear in `dy` and the
//! weights; its second-order op runs the masked chain forward on the incoming gradient and
//! forms the weight products from the backward's saved `dzᵢ`: exact, as the candle
//! composition's double backward. The second derivative of the *weight* gradients (which
//! depend on the activations) is not implemented: a second backward that reaches them fails
//! with an error instead of returning a wrong value, and so does any third derivative. Use
//! [`crate::with_reference_ops`] for those.
//!
//! CPU tensors of dtype f32 or f64 take this path; other devices and dtypes, and calls inside
//! [`crate::reference::with_reference_ops`], use [`per_texel_mlp_reference`].

use std::sync::{Arc, Mutex};

use candle_core::backend::BackendStorage;
use candle_core::{
    CpuStorage, CustomOp2, CustomOp3, DType, Layout, Result, Shape, Storage, Tensor, WithDType,
    bail,
};
use gemm::Parallelism;
use rayon::prelude::*;

use crate::alloc::output_buffer;

/// Texel rows per block. A block's working set backward is three activation buffers of
/// `BLOCK_ROWS × 64` values (192 KiB in f32) plus the weights, well inside the 1 MiB L2 per
/// core of the build machine, and `gemm` still sees 256-row operands.
pub const BLOCK_ROWS: usize = 256;

/// One layer of a per-texel MLP as its caller stores it.
#[derive(Debug, Clone, Copy)]
pub struct MlpLayer<'a> {
    /// The stored weight W, shape (out, in).
    pub weight: &'a Tensor,
    /// The stored bias b, shape (out).
    pub bias: &'a Tensor,
    /// The run-time weight scale (`λ/√in` for an equalised-lr layer).
    pub weight_gain: f64,
    /// The run-time bias scale (λ).
    pub bias_gain: f64,
}

/// The activation after every layer but the last: `gain · LeakyReLU(z, slope)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MlpActivation {
    /// Negative slope, in [0, 1].
    pub slope: f64,
    /// Gain, positive (the backward reads the sign of z from the activation).
    pub gain: f64,
}

/// The per-texel MLP `layers` on NCHW inputs, the texel's input row being the channels of
/// `features` followed by those of `omega`; fused on the CPU (module docs).
///
/// # Shapes
/// features (B, C, H, W), omega (B, K, H, W), layer i weight (dᵢ₊₁, dᵢ) with d₀ = C + K and
/// every hidden width equal, bias (dᵢ₊₁) → (B, d_L, H, W).
pub fn per_texel_mlp(
    features: &Tensor,
    omega: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (b, c, h, w) = features.dims4()?;
    let (ob, k, oh, ow) = omega.dims4()?;
    if (ob, oh, ow) != (b, h, w) {
        bail!(
            "per-texel mlp: omega {:?} does not match features {:?}",
            omega.dims(),
            features.dims()
        );
    }
    let net = Net::new(layers, c + k, act)?;
    if !fusable(&[features, omega], layers) {
        return per_texel_mlp_reference(features, omega, layers, act);
    }
    let io = Io {
        batch: b,
        pixels: h * w,
        inputs: vec![Plane::nchw(c, h * w), Plane::nchw(k, h * w)],
        output: Plane::nchw(net.out_width(), h * w),
        output_shape: Shape::from((b, net.out_width(), h, w)),
    };
    let save = features.track_op() || omega.track_op() || layers_track(layers);
    let params = pack(layers)?;
    features
        .contiguous()?
        .apply_op3(&omega.contiguous()?, &params, Forward::new(net, io, save))
}

/// The per-texel MLP `layers` on rows, one texel per row; fused on the CPU (module docs).
///
/// # Shapes
/// rows (N, d₀), layers as in [`per_texel_mlp`] → (N, d_L).
pub fn per_texel_mlp_rows(
    rows: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (n, d0) = rows.dims2()?;
    let net = Net::new(layers, d0, act)?;
    if !fusable(&[rows], layers) {
        return per_texel_mlp_rows_reference(rows, layers, act);
    }
    let io = Io {
        batch: 1,
        pixels: n,
        inputs: vec![Plane::rows(d0, n)],
        output: Plane::rows(net.out_width(), n),
        output_shape: Shape::from((n, net.out_width())),
    };
    let save = rows.track_op() || layers_track(layers);
    let params = pack(layers)?;
    rows.contiguous()?
        .apply_op2(&params, Forward::new(net, io, save))
}

/// [`per_texel_mlp`] composed from candle ops: concatenation, transpose to rows, per layer a
/// matrix product, bias and [`crate::leaky_relu_gain`], transpose back.
///
/// # Shapes
/// As [`per_texel_mlp`].
pub fn per_texel_mlp_reference(
    features: &Tensor,
    omega: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (b, c, h, w) = features.dims4()?;
    let k = omega.dim(1)?;
    let rows = Tensor::cat(&[features, omega], 1)?
        .permute((0, 2, 3, 1))?
        .contiguous()?
        .reshape((b * h * w, c + k))?;
    let y = per_texel_mlp_rows_reference(&rows, layers, act)?;
    let out = y.dim(1)?;
    y.reshape((b, h, w, out))?
        .permute((0, 3, 1, 2))?
        .contiguous()
}

/// [`per_texel_mlp_rows`] composed from candle ops.
///
/// # Shapes
/// As [`per_texel_mlp_rows`].
pub fn per_texel_mlp_rows_reference(
    rows: &Tensor,
    layers: &[MlpLayer<'_>],
    act: MlpActivation,
) -> Result<Tensor> {
    let (_n, d0) = rows.dims2()?;
    Net::new(layers, d0, act)?;
    let mut x = rows.clone();
    for (i, l) in layers.iter().enumerate() {
        let w = l.weight.affine(l.weight_gain, 0.0)?;
        x = x
            .matmul(&w.t()?)?
            .broadcast_add(&l.bias.affine(l.bias_gain, 0.0)?)?;
        if i + 1 < layers.len() {
            x = crate::activation::leaky_relu_gain(&x, act.slope, act.gain)?;
        }
    }
    Ok(x)
}

/// Whether the fused op applies: CPU, f32 or f64 throughout, not in reference mode.
fn fusable(inputs: &[&Tensor], layers: &[MlpLayer<'_>]) -> bool {
    let dtype = inputs[0].dtype();
    let mut all = inputs
        .iter()
        .copied()
        .chain(layers.iter().flat_map(|l| [l.weight, l.bias]));
    matches!(dtype, DType::F32 | DType::F64)
        && all.all(|t| t.device().is_cpu() && t.dtype() == dtype)
        && !crate::reference::reference_ops()
}

fn layers_track(layers: &[MlpLayer<'_>]) -> bool {
    layers
        .iter()
        .any(|l| l.weight.track_op() || l.bias.track_op())
}

/// The stored parameters as one vector `[W₀, b₀, W₁, b₁, …]` (weights row-major), the op's
/// third operand; `cat`'s backward hands each layer its part of the gradient.
fn pack(layers: &[MlpLayer<'_>]) -> Result<Tensor> {
    let parts = layers
        .iter()
        .flat_map(|l| [l.weight.flatten_all(), Ok(l.bias.clone())])
        .collect::<Result<Vec<_>>>()?;
    Tensor::cat(&parts, 0)
}

/// The network's geometry and constants.
#[derive(Debug, Clone)]
struct Net {
    /// Widths d₀ … d_L.
    dims: Vec<usize>,
    weight_gains: Vec<f64>,
    bias_gains: Vec<f64>,
    act: MlpActivation,
}

impl Net {
    fn new(layers: &[MlpLayer<'_>], d0: usize, act: MlpActivation) -> Result<Self> {
        if layers.len() < 2 {
            bail!(
                "per-texel mlp: needs at least 2 layers, got {}",
                layers.len()
            );
        }
        if !(0.0..=1.0).contains(&act.slope) {
            bail!("per-texel mlp: slope {} is outside [0, 1]", act.slope);
        }
        if !(act.gain.is_finite() && act.gain > 0.0) {
            bail!("per-texel mlp: gain {} is not a positive number", act.gain);
        }
        let mut dims = vec![d0];
        for (i, l) in layers.iter().enumerate() {
            let (out, inp) = l.weight.dims2()?;
            if inp != dims[i] || l.bias.dims() != [out] {
                bail!(
                    "per-texel mlp: layer {i} has weight {:?} and bias {:?}, expected {} inputs",
                    l.weight.dims(),
                    l.bias.dims(),
                    dims[i]
                );
            }
            if !(l.weight_gain.is_finite() && l.bias_gain.is_finite()) {
                bail!("per-texel mlp: layer {i} has a non-finite gain");
            }
            dims.push(out);
        }
        if dims[1..layers.len()].iter().any(|&d| d != dims[1]) {
            bail!(
                "per-texel mlp: hidden widths {:?} differ",
                &dims[1..layers.len()]
            );
        }
        Ok(Self {
            dims,
            weight_gains: layers.iter().map(|l| l.weight_gain).collect(),
            bias_gains: layers.iter().map(|l| l.bias_gain).collect(),
            act,
        })
    }

    /// Number of layers L.
    fn layers(&self) -> usize {
        self.dims.len() - 1
    }

    fn in_width(&self) -> usize {
        self.dims[0]
    }

    fn hidden(&self) -> usize {
        self.dims[1]
    }

    fn out_width(&self) -> usize {
        self.dims[self.layers()]
    }

    /// Offsets of layer i's weight and bias in the packed parameters.
    fn offsets(&self, i: usize) -> (usize, usize) {
        let w = (0..i)
            .map(|j| self.dims[j + 1] * (self.dims[j] + 1))
            .sum::<usize>();
        (w, w + self.dims[i + 1] * self.dims[i])
    }

    fn param_len(&self) -> usize {
        let (_, b) = self.offsets(self.layers() - 1);
        b + self.out_width()
    }
}

/// The effective weights of one call: Ŵᵢ (out × in), Ŵᵢᵀ (in × out), b̂ᵢ, all row-major.
struct Weights<T> {
    w: Vec<Vec<T>>,
    wt: Vec<Vec<T>>,
    b: Vec<Vec<T>>,
}

impl<T: WithDType> Weights<T> {
    fn new(net: &Net, params: &[T]) -> Self {
        let mut out = Self {
            w: Vec::new(),
            wt: Vec::new(),
            b: Vec::new(),
        };
        for i in 0..net.layers() {
            let (inp, o) = (net.dims[i], net.dims[i + 1]);
            let (wo, bo) = net.offsets(i);
            let g = T::from_f64(net.weight_gains[i]);
            let w: Vec<T> = params[wo..wo + o * inp].iter().map(|&v| v * g).collect();
            let mut wt = vec![T::zero(); w.len()];
            for r in 0..o {
                for c in 0..inp {
                    wt[c * o + r] = w[r * inp + c];
                }
            }
            let bg = T::from_f64(net.bias_gains[i]);
            out.b
                .push(params[bo..bo + o].iter().map(|&v| v * bg).collect());
            out.w.push(w);
            out.wt.push(wt);
        }
        out
    }
}

/// Where channel c of texel p of image b lives in one operand:
/// `b·batch_stride + c·channel_stride + p·pixel_stride`.
#[derive(Debug, Clone, Copy)]
struct Plane {
    channels: usize,
    batch_stride: usize,
    channel_stride: usize,
    pixel_stride: usize,
}

impl Plane {
    fn nchw(channels: usize, pixels: usize) -> Self {
        Self {
            channels,
            batch_stride: channels * pixels,
            channel_stride: pixels,
            pixel_stride: 1,
        }
    }

    fn rows(channels: usize, n: usize) -> Self {
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
struct Io {
    batch: usize,
    pixels: usize,
    inputs: Vec<Plane>,
    output: Plane,
    output_shape: Shape,
}

/// A run of texels of one image, rows `row .. row + len` of the (B·pixels) rows.
#[derive(Debug, Clone, Copy)]
struct Block {
    image: usize,
    first: usize,
    len: usize,
    row: usize,
}

impl Io {
    fn rows(&self) -> usize {
        self.batch * self.pixels
    }

    fn blocks(&self) -> Vec<Block> {
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
    fn input_lens(&self) -> Vec<usize> {
        self.inputs
            .iter()
            .map(|p| p.batch_stride * self.batch)
            .collect()
    }

    fn output_len(&self) -> usize {
        self.output.batch_stride * self.batch
    }
}

/// Copies the block's rows of `planes` (channels concatenated) into `dst` (len × width).
fn gather<T: Copy>(planes: &[Plane], data: &[&[T]], blk: Block, width: usize, dst: &mut [T]) {
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
struct Scatter<T> {
    ptr: *mut T,
    len: usize,
}

// SAFETY: `Scatter` only hands out element writes; the blocks partition the texels and every
// element belongs to exactly one texel, so concurrent writes never touch one element twice.
unsafe impl<T: Send> Send for Scatter<T> {}
// SAFETY: as above.
unsafe impl<T: Send> Sync for Scatter<T> {}

impl<T: Copy> Scatter<T> {
    fn new(v: &mut [T]) -> Self {
        Self {
            ptr: v.as_mut_ptr(),
            len: v.len(),
        }
    }

    /// Writes the block's rows `src` (len × width, channels of `planes` concatenated), plus
    /// `bias` per channel when given, into their planes, plane k starting at `offsets[k]`.
    fn put(
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

/// `dst (m × n, row-major) = [dst +] lhs (m × k) · rhs (k × n)`, operands given with their
/// (row, column) strides, on the calling thread.
#[allow(clippy::too_many_arguments)]
fn matmul<T: WithDType>(
    (m, n, k): (usize, usize, usize),
    dst: &mut [T],
    accumulate: bool,
    lhs: &[T],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: &[T],
    (rhs_rs, rhs_cs): (usize, usize),
) {
    if m == 0 || n == 0 {
        return;
    }
    let last = |rs: usize, cs: usize, r: usize, c: usize| (r - 1) * rs + (c - 1) * cs;
    assert!(m * n <= dst.len(), "gemm destination out of bounds");
    if k > 0 {
        assert!(
            last(lhs_rs, lhs_cs, m, k) < lhs.len(),
            "gemm lhs out of bounds"
        );
        assert!(
            last(rhs_rs, rhs_cs, k, n) < rhs.len(),
            "gemm rhs out of bounds"
        );
    }
    let one = T::from_f64(1.0);
    // SAFETY: the three views were bounds-checked above; `dst` is borrowed mutably, so it
    // aliases neither operand.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            accumulate,
            lhs.as_ptr(),
            lhs_cs as isize,
            lhs_rs as isize,
            rhs.as_ptr(),
            rhs_cs as isize,
            rhs_rs as isize,
            one,
            one,
            false,
            false,
            false,
            Parallelism::None,
        )
    }
}

/// Slot `read` for reading and slot `write` (≠ `read`) for writing, slots of `len` values.
fn two_slots<T>(buf: &mut [T], len: usize, read: usize, write: usize) -> (&[T], &mut [T]) {
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
fn split_blocks<'a, T>(mut buf: &'a mut [T], blocks: &[Block], per_row: usize) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(blocks.len());
    for b in blocks {
        let (head, tail) = buf.split_at_mut(b.len * per_row);
        out.push(head);
        buf = tail;
    }
    out
}

/// `x ⊙= f'(z)` with the sign of z read from the activation `h` (gain > 0, so h > 0 ⇔ z > 0).
fn mask<T: WithDType>(x: &mut [T], h: &[T], act: MlpActivation) {
    let (p, n) = (T::from_f64(act.gain), T::from_f64(act.gain * act.slope));
    let zero = T::zero();
    for (x, &h) in x.iter_mut().zip(h) {
        *x *= if h > zero { p } else { n };
    }
}

/// Folds `items` in order into one task state per fixed run of consecutive items (as many runs
/// as rayon has threads), then adds the runs' sums (`sums` of each state) in run order. The
/// parameter gradients then depend on the thread count only, not on which thread took which
/// block: with rayon's `fold` + `reduce` the grouping followed work stealing, and two training
/// runs with the same seed drifted apart in the last bits from their fourth step on.
fn sum_over_runs<I: Send, S, T: WithDType>(
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
fn for_blocks<T: Send, S: Send>(
    items: Vec<(Block, &mut [T])>,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, Block, &mut [T]) + Sync + Send,
) {
    items
        .into_par_iter()
        .for_each_init(init, |s, (blk, chunk)| f(s, blk, chunk));
}

/// Input slices of the operands, checked contiguous and sized.
fn operand<'a, T: WithDType>(
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

/// The forward op: (inputs…, packed parameters) → output.
struct Forward {
    net: Arc<Net>,
    io: Arc<Io>,
    save: bool,
    /// The hidden activations of every block (block-major: per block L − 1 layers of
    /// len × hidden values), kept for the backward.
    saved: Mutex<Option<Arc<CpuStorage>>>,
}

impl Forward {
    fn new(net: Net, io: Io, save: bool) -> Self {
        Self {
            net: Arc::new(net),
            io: Arc::new(io),
            save,
            saved: Mutex::new(None),
        }
    }

    fn cpu(
        &self,
        inputs: &[(&CpuStorage, &Layout)],
        params: (&CpuStorage, &Layout),
    ) -> Result<(CpuStorage, Shape)> {
        let (out, hidden) = match params.0.dtype() {
            DType::F32 => self.run::<f32>(inputs, params)?,
            DType::F64 => self.run::<f64>(inputs, params)?,
            d => bail!("per-texel mlp: unsupported dtype {d:?}"),
        };
        *self.saved.lock().expect("mlp saved activations lock") = hidden.map(Arc::new);
        Ok((out, self.io.output_shape.clone()))
    }

    fn run<T: WithDType>(
        &self,
        inputs: &[(&CpuStorage, &Layout)],
        params: (&CpuStorage, &Layout),
    ) -> Result<(CpuStorage, Option<CpuStorage>)> {
        let (net, io) = (&*self.net, &*self.io);
        let lens = io.input_lens();
        let data = inputs
            .iter()
            .zip(&lens)
            .map(|((s, l), &n)| operand::<T>(s, l, n, "an input"))
            .collect::<Result<Vec<_>>>()?;
        let params = operand::<T>(params.0, params.1, net.param_len(), "the parameters")?;
        let wts = Weights::new(net, params);
        let (l, hid, d0, dl) = (net.layers(), net.hidden(), net.in_width(), net.out_width());
        // SAFETY: the blocks cover every row and `scatter.put` writes each block's outputs.
        let mut out = unsafe { output_buffer(io.output_len()) };
        let scatter = Scatter::new(&mut out);
        let blocks = io.blocks();
        let per_row = (l - 1) * hid;
        let block_forward =
            |x: &mut Vec<T>, last: &mut Vec<T>, blk: Block, slots: &mut [T], ns: usize| {
                let len = blk.len;
                gather(&io.inputs, &data, blk, d0, &mut x[..len * d0]);
                let sl = len * hid;
                for i in 0..l {
                    let inw = net.dims[i];
                    let outw = net.dims[i + 1];
                    let rhs = (&wts.wt[i][..], (outw, 1));
                    if i + 1 == l {
                        let prev = &slots[((i - 1) % ns) * sl..((i - 1) % ns + 1) * sl];
                        matmul(
                            (len, outw, inw),
                            &mut last[..len * dl],
                            false,
                            prev,
                            (inw, 1),
                            rhs.0,
                            rhs.1,
                        );
                        scatter.put(
                            &[io.output],
                            &[0],
                            blk,
                            dl,
                            &last[..len * dl],
                            Some(&wts.b[i]),
                        );
                    } else {
                        let dst: &mut [T] = if i == 0 {
                            let dst = &mut slots[..sl];
                            matmul(
                                (len, outw, inw),
                                dst,
                                false,
                                &x[..len * d0],
                                (inw, 1),
                                rhs.0,
                                rhs.1,
                            );
                            dst
                        } else {
                            let (prev, dst) = two_slots(slots, sl, (i - 1) % ns, i % ns);
                            matmul((len, outw, inw), dst, false, prev, (inw, 1), rhs.0, rhs.1);
                            dst
                        };
                        bias_act(dst, &wts.b[i], net.act);
                    }
                }
            };
        let init = || {
            (
                vec![T::zero(); BLOCK_ROWS * d0],
                vec![T::zero(); BLOCK_ROWS * dl],
            )
        };
        let hidden = if self.save {
            // SAFETY: `block_forward` writes every hidden layer's slot for each block's rows
            // (slot i for layer i, `ns` = l − 1 slots), and the blocks cover all rows.
            let mut hidden = unsafe { output_buffer(io.rows() * per_row) };
            let items: Vec<_> = blocks
                .iter()
                .copied()
                .zip(split_blocks(&mut hidden, &blocks, per_row))
                .collect();
            for_blocks(items, init, |(x, last), blk, chunk| {
                block_forward(x, last, blk, chunk, l - 1)
            });
            Some(T::to_cpu_storage_owned(hidden))
        } else {
            // Two ping-pong slots per task instead of every layer's activations.
            let ns = (l - 1).min(2);
            blocks.par_iter().for_each_init(
                || (init(), vec![T::zero(); ns * BLOCK_ROWS * hid]),
                |((x, last), slots), &blk| {
                    block_forward(x, last, blk, &mut slots[..ns * blk.len * hid], ns)
                },
            );
            None
        };
        Ok((T::to_cpu_storage_owned(out), hidden))
    }

    /// Gradients of the inputs (in order) and of the packed parameters.
    fn backward(
        &self,
        inputs: &[&Tensor],
        params: &Tensor,
        grad: &Tensor,
    ) -> Result<(Vec<Tensor>, Tensor)> {
        let Some(hidden) = self
            .saved
            .lock()
            .expect("mlp saved activations lock")
            .clone()
        else {
            bail!(
                "per-texel mlp: backward through a forward that kept no activations (no input \
                 was tracked when it ran)"
            );
        };
        let op = Backward {
            net: self.net.clone(),
            io: self.io.clone(),
            hidden,
            inputs: inputs.iter().map(|t| (*t).clone()).collect(),
            save_dz: candle_core::backprop::keeps_graph(),
            params_needed: params.track_op(),
            saved_dz: Mutex::new(None),
        };
        let packed = grad.contiguous()?.apply_op2(params, op)?;
        let mut off = 0;
        let mut grads = Vec::new();
        for (t, n) in inputs.iter().zip(self.io.input_lens()) {
            grads.push(packed.narrow(0, off, n)?.reshape(t.shape())?);
            off += n;
        }
        let dparams = packed.narrow(0, off, self.net.param_len())?;
        Ok((grads, dparams))
    }
}

/// `x = gain · LeakyReLU(x + bias)` per row of `bias.len()` values.
fn bias_act<T: WithDType>(x: &mut [T], bias: &[T], act: MlpActivation) {
    let (p, n) = (T::from_f64(act.gain), T::from_f64(act.gain * act.slope));
    let zero = T::zero();
    for row in x.chunks_exact_mut(bias.len()) {
        for (v, &b) in row.iter_mut().zip(bias) {
            let z = *v + b;
            *v = if z > zero { p * z } else { n * z };
        }
    }
}

impl CustomOp3 for Forward {
    fn name(&self) -> &'static str {
        "per-texel-mlp"
    }

    fn cpu_fwd(
        &self,
        a: &CpuStorage,
        la: &Layout,
        b: &CpuStorage,
        lb: &Layout,
        p: &CpuStorage,
        lp: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        self.cpu(&[(a, la), (b, lb)], (p, lp))
    }

    fn bwd(
        &self,
        a: &Tensor,
        b: &Tensor,
        p: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let (mut g, dp) = self.backward(&[a, b], p, grad)?;
        let db = g.pop();
        let da = g.pop();
        Ok((da, db, p.track_op().then_some(dp)))
    }
}

impl CustomOp2 for Forward {
    fn name(&self) -> &'static str {
        "per-texel-mlp"
    }

    fn cpu_fwd(
        &self,
        a: &CpuStorage,
        la: &Layout,
        p: &CpuStorage,
        lp: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        self.cpu(&[(a, la)], (p, lp))
    }

    fn bwd(
        &self,
        a: &Tensor,
        p: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let (mut g, dp) = self.backward(&[a], p, grad)?;
        Ok((g.pop(), p.track_op().then_some(dp)))
    }
}

/// The backward op: (dy, packed parameters) → `[d input₀ | d input₁ … | d parameters]`,
/// flat. The inputs (for the first layer's weight gradient) and the forward's activations are
/// read from the op itself; the activations enter only through masks and weight gradients.
struct Backward {
    net: Arc<Net>,
    io: Arc<Io>,
    hidden: Arc<CpuStorage>,
    inputs: Vec<Tensor>,
    save_dz: bool,
    /// Whether the parameters are in the graph: when they are constants (a frozen M, as when
    /// a photo is inverted) their gradient stays zero instead of being computed.
    params_needed: bool,
    /// Every block's dzᵢ, i < L − 1 (laid out as the activations), for the second-order op.
    saved_dz: Mutex<Option<Arc<CpuStorage>>>,
}

impl Backward {
    fn run<T: WithDType>(&self, dy: &[T], params: &[T]) -> Result<(Vec<T>, Option<Vec<T>>)> {
        let (net, io) = (&*self.net, &*self.io);
        let guards: Vec<_> = self.inputs.iter().map(|t| t.storage_and_layout()).collect();
        let lens = io.input_lens();
        let mut data = Vec::new();
        for ((s, l), &n) in guards.iter().zip(&lens) {
            let Storage::Cpu(s) = &**s else {
                bail!("per-texel mlp: backward on a non-CPU input");
            };
            data.push(operand::<T>(s, l, n, "an input")?);
        }
        let hidden = T::cpu_storage_as_slice(&self.hidden)?;
        let wts = Weights::new(net, params);
        let (l, hid, d0, dl) = (net.layers(), net.hidden(), net.in_width(), net.out_width());
        let np = net.param_len();
        let per_row = (l - 1) * hid;
        let total_in: usize = lens.iter().sum();
        let mut out = vec![T::zero(); total_in + np];
        let offsets: Vec<usize> = lens
            .iter()
            .scan(0, |acc, &n| {
                let o = *acc;
                *acc += n;
                Some(o)
            })
            .collect();
        let (grads_in, _) = out.split_at_mut(total_in);
        let scatter = Scatter::new(grads_in);
        let blocks = io.blocks();
        let hidden_chunks: Vec<&[T]> = {
            let mut rest = hidden;
            blocks
                .iter()
                .map(|b| {
                    let (h, t) = rest.split_at(b.len * per_row);
                    rest = t;
                    h
                })
                .collect()
        };
        if hidden.len() != io.rows() * per_row {
            bail!("per-texel mlp: saved activations of the wrong size");
        }
        // One task's state: the parameter-gradient partial sums (unscaled) and scratch.
        struct Task<T> {
            acc: Vec<T>,
            x: Vec<T>,
            dlast: Vec<T>,
            dx: Vec<T>,
            slots: Vec<T>,
        }
        let new_task = || Task {
            acc: vec![T::zero(); np],
            x: vec![T::zero(); BLOCK_ROWS * d0],
            dlast: vec![T::zero(); BLOCK_ROWS * dl],
            dx: vec![T::zero(); BLOCK_ROWS * d0],
            slots: if self.save_dz {
                Vec::new()
            } else {
                vec![T::zero(); 2 * BLOCK_ROWS * hid]
            },
        };
        let block_backward = |t: &mut Task<T>, bi: usize, dz: Option<&mut [T]>| {
            let blk = blocks[bi];
            let len = blk.len;
            let h = hidden_chunks[bi];
            let (dz, ns) = match dz {
                Some(d) => (d, l - 1),
                None => (&mut t.slots[..2 * len * hid], (l - 1).min(2)),
            };
            let sl = len * hid;
            gather(&io.inputs, &data, blk, d0, &mut t.x[..len * d0]);
            gather(&[io.output], &[dy], blk, dl, &mut t.dlast[..len * dl]);
            for i in (0..l).rev() {
                let (inw, outw) = (net.dims[i], net.dims[i + 1]);
                let (wo, bo) = net.offsets(i);
                let prev: &[T] = if i == 0 {
                    &t.x[..len * d0]
                } else {
                    &h[(i - 1) * sl..i * sl]
                };
                // `cur` (len × outw) is dzᵢ; the next dz goes to slot (i − 1) mod ns.
                let (cur, next): (&[T], Option<&mut [T]>) = if i + 1 == l {
                    let next = if i > 0 {
                        let s = (i - 1) % ns;
                        Some(&mut dz[s * sl..(s + 1) * sl])
                    } else {
                        None
                    };
                    (&t.dlast[..len * dl], next)
                } else if i > 0 {
                    let (c, n) = two_slots(dz, sl, i % ns, (i - 1) % ns);
                    (c, Some(n))
                } else {
                    (&dz[(i % ns) * sl..(i % ns + 1) * sl], None)
                };
                // dŴᵢ += dzᵢᵀ·hᵢ₋₁, db̂ᵢ += Σ_rows dzᵢ (unless the parameters are constants).
                if self.params_needed {
                    matmul(
                        (outw, inw, len),
                        &mut t.acc[wo..wo + outw * inw],
                        true,
                        cur,
                        (1, outw),
                        prev,
                        (inw, 1),
                    );
                    for row in cur.chunks_exact(outw) {
                        for (a, &v) in t.acc[bo..bo + outw].iter_mut().zip(row) {
                            *a += v;
                        }
                    }
                }
                // dhᵢ₋₁ = dzᵢ·Ŵᵢ, then the activation's derivative.
                match next {
                    Some(next) => {
                        matmul(
                            (len, inw, outw),
                            next,
                            false,
                            cur,
                            (outw, 1),
                            &wts.w[i],
                            (inw, 1),
                        );
                        mask(next, prev, net.act);
                    }
                    None => {
                        matmul(
                            (len, inw, outw),
                            &mut t.dx[..len * d0],
                            false,
                            cur,
                            (outw, 1),
                            &wts.w[i],
                            (inw, 1),
                        );
                    }
                }
            }
            scatter.put(&io.inputs, &offsets, blk, d0, &t.dx[..len * d0], None);
        };
        let fold = |mut t: Task<T>, (bi, dz): (usize, Option<&mut [T]>)| {
            block_backward(&mut t, bi, dz);
            t
        };
        let mut dz_all = if self.save_dz {
            // SAFETY: `block_backward` writes dz of layers l − 1 … 1 into slots l − 2 … 0 for
            // each block's rows, and the blocks cover all rows.
            unsafe { output_buffer(io.rows() * per_row) }
        } else {
            Vec::new()
        };
        let items: Vec<(usize, Option<&mut [T]>)> = if self.save_dz {
            split_blocks(&mut dz_all, &blocks, per_row)
                .into_iter()
                .map(Some)
                .enumerate()
                .collect()
        } else {
            (0..blocks.len()).map(|i| (i, None)).collect()
        };
        let acc = sum_over_runs(items, new_task, fold, |t| t.acc);
        let dparams = &mut out[total_in..];
        for i in 0..l {
            let (wo, bo) = net.offsets(i);
            let (inw, outw) = (net.dims[i], net.dims[i + 1]);
            let (g, bg) = (
                T::from_f64(net.weight_gains[i]),
                T::from_f64(net.bias_gains[i]),
            );
            for j in wo..wo + outw * inw {
                dparams[j] = acc[j] * g;
            }
            for j in bo..bo + outw {
                dparams[j] = acc[j] * bg;
            }
        }
        Ok((out, self.save_dz.then_some(dz_all)))
    }
}

impl CustomOp2 for Backward {
    fn name(&self) -> &'static str {
        "per-texel-mlp-backward"
    }

    fn cpu_fwd(
        &self,
        dy: &CpuStorage,
        ldy: &Layout,
        p: &CpuStorage,
        lp: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (dyn_, np) = (self.io.output_len(), self.net.param_len());
        let (out, dz) = match p.dtype() {
            DType::F32 => {
                let (o, d) = self.run::<f32>(
                    operand(dy, ldy, dyn_, "dy")?,
                    operand(p, lp, np, "the parameters")?,
                )?;
                (
                    f32::to_cpu_storage_owned(o),
                    d.map(f32::to_cpu_storage_owned),
                )
            }
            DType::F64 => {
                let (o, d) = self.run::<f64>(
                    operand(dy, ldy, dyn_, "dy")?,
                    operand(p, lp, np, "the parameters")?,
                )?;
                (
                    f64::to_cpu_storage_owned(o),
                    d.map(f64::to_cpu_storage_owned),
                )
            }
            d => bail!("per-texel mlp: unsupported dtype {d:?}"),
        };
        *self.saved_dz.lock().expect("mlp saved gradients lock") = dz.map(Arc::new);
        let n = self.io.input_lens().iter().sum::<usize>() + np;
        Ok((out, Shape::from(n)))
    }

    fn bwd(
        &self,
        dy: &Tensor,
        p: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let Some(dz) = self
            .saved_dz
            .lock()
            .expect("mlp saved gradients lock")
            .clone()
        else {
            bail!(
                "per-texel mlp: second derivative through a backward pass that did not keep its graph \
                 (use backward_keeping_graph for the first pass)"
            );
        };
        let op = SecondOrder {
            net: self.net.clone(),
            io: self.io.clone(),
            hidden: self.hidden.clone(),
            dz,
        };
        let packed = grad.contiguous()?.apply_op3(dy, p, op)?;
        let n = self.io.output_len();
        let ddy = packed.narrow(0, 0, n)?.reshape(dy.shape())?;
        let dp = packed.narrow(0, n, self.net.param_len())?;
        Ok((Some(ddy), Some(dp)))
    }
}

/// The backward's backward: (upstream gradient of `[d inputs | d parameters]`, dy, packed
/// parameters) → `[d dy | d parameters]`. Only the input-gradient part may be non-zero (module
/// docs, "Higher derivatives").
struct SecondOrder {
    net: Arc<Net>,
    io: Arc<Io>,
    hidden: Arc<CpuStorage>,
    dz: Arc<CpuStorage>,
}

impl SecondOrder {
    fn run<T: WithDType>(&self, g: &[T], dy: &[T], params: &[T]) -> Result<Vec<T>> {
        let (net, io) = (&*self.net, &*self.io);
        let (l, hid, d0, dl) = (net.layers(), net.hidden(), net.in_width(), net.out_width());
        let np = net.param_len();
        let per_row = (l - 1) * hid;
        let lens = io.input_lens();
        let total_in: usize = lens.iter().sum();
        if g[total_in..].iter().any(|&v| v != T::zero()) {
            bail!(
                "per-texel mlp: the second derivative of the weight gradients is not \
                 implemented; use photomat_kernels::with_reference_ops"
            );
        }
        let mut gs = Vec::new();
        let mut rest = &g[..total_in];
        for &n in &lens {
            let (a, b) = rest.split_at(n);
            gs.push(a);
            rest = b;
        }
        let hidden = T::cpu_storage_as_slice(&self.hidden)?;
        let dz = T::cpu_storage_as_slice(&self.dz)?;
        if hidden.len() != io.rows() * per_row || dz.len() != hidden.len() {
            bail!("per-texel mlp: saved buffers of the wrong size");
        }
        let wts = Weights::new(net, params);
        let mut out = vec![T::zero(); io.output_len() + np];
        let scatter = Scatter::new(&mut out[..io.output_len()]);
        let blocks = io.blocks();
        let starts: Vec<usize> = blocks.iter().map(|b| b.row * per_row).collect();
        struct Task<T> {
            acc: Vec<T>,
            x: Vec<T>,
            dlast: Vec<T>,
            ulast: Vec<T>,
            slots: Vec<T>,
        }
        let new_task = || Task {
            acc: vec![T::zero(); np],
            x: vec![T::zero(); BLOCK_ROWS * d0],
            dlast: vec![T::zero(); BLOCK_ROWS * dl],
            ulast: vec![T::zero(); BLOCK_ROWS * dl],
            slots: vec![T::zero(); 2 * BLOCK_ROWS * hid],
        };
        let block = |t: &mut Task<T>, bi: usize| {
            let blk = blocks[bi];
            let len = blk.len;
            let sl = len * hid;
            let h = &hidden[starts[bi]..starts[bi] + len * per_row];
            let dzb = &dz[starts[bi]..starts[bi] + len * per_row];
            gather(&io.inputs, &gs, blk, d0, &mut t.x[..len * d0]);
            gather(&[io.output], &[dy], blk, dl, &mut t.dlast[..len * dl]);
            let slots = &mut t.slots[..2 * sl];
            for i in 0..l {
                let (inw, outw) = (net.dims[i], net.dims[i + 1]);
                let wo = net.offsets(i).0;
                let dzi: &[T] = if i + 1 == l {
                    &t.dlast[..len * dl]
                } else {
                    &dzb[i * sl..(i + 1) * sl]
                };
                // uᵢ = uᵢ₋₁·Ŵᵢᵀ (masked below), ∂/∂Ŵᵢ += dzᵢᵀ·uᵢ₋₁.
                let rhs = &wts.wt[i][..];
                if i + 1 == l {
                    let prev = &slots[((i - 1) % 2) * sl..((i - 1) % 2 + 1) * sl];
                    matmul(
                        (outw, inw, len),
                        &mut t.acc[wo..wo + outw * inw],
                        true,
                        dzi,
                        (1, outw),
                        prev,
                        (inw, 1),
                    );
                    matmul(
                        (len, outw, inw),
                        &mut t.ulast[..len * dl],
                        false,
                        prev,
                        (inw, 1),
                        rhs,
                        (outw, 1),
                    );
                } else {
                    let dst: &mut [T] = if i == 0 {
                        let prev = &t.x[..len * d0];
                        matmul(
                            (outw, inw, len),
                            &mut t.acc[wo..wo + outw * inw],
                            true,
                            dzi,
                            (1, outw),
                            prev,
                            (inw, 1),
                        );
                        let dst = &mut slots[..sl];
                        matmul((len, outw, inw), dst, false, prev, (inw, 1), rhs, (outw, 1));
                        dst
                    } else {
                        let (prev, dst) = two_slots(slots, sl, (i - 1) % 2, i % 2);
                        matmul(
                            (outw, inw, len),
                            &mut t.acc[wo..wo + outw * inw],
                            true,
                            dzi,
                            (1, outw),
                            prev,
                            (inw, 1),
                        );
                        matmul((len, outw, inw), dst, false, prev, (inw, 1), rhs, (outw, 1));
                        dst
                    };
                    mask(dst, &h[i * sl..(i + 1) * sl], net.act);
                }
            }
            scatter.put(&[io.output], &[0], blk, dl, &t.ulast[..len * dl], None);
        };
        let fold = |mut t: Task<T>, bi: usize| {
            block(&mut t, bi);
            t
        };
        let acc = sum_over_runs((0..blocks.len()).collect(), new_task, fold, |t| t.acc);
        let dparams = &mut out[io.output_len()..];
        for i in 0..l {
            let (wo, _) = net.offsets(i);
            let n = net.dims[i] * net.dims[i + 1];
            let g = T::from_f64(net.weight_gains[i]);
            for j in wo..wo + n {
                dparams[j] = acc[j] * g;
            }
            // The input gradient does not depend on the biases: their entries stay zero.
        }
        Ok(out)
    }
}

impl CustomOp3 for SecondOrder {
    fn name(&self) -> &'static str {
        "per-texel-mlp-second-order"
    }

    fn cpu_fwd(
        &self,
        g: &CpuStorage,
        lg: &Layout,
        dy: &CpuStorage,
        ldy: &Layout,
        p: &CpuStorage,
        lp: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let ng = self.io.input_lens().iter().sum::<usize>() + self.net.param_len();
        let (ndy, np) = (self.io.output_len(), self.net.param_len());
        let out = match p.dtype() {
            DType::F32 => f32::to_cpu_storage_owned(self.run::<f32>(
                operand(g, lg, ng, "the upstream gradient")?,
                operand(dy, ldy, ndy, "dy")?,
                operand(p, lp, np, "the parameters")?,
            )?),
            DType::F64 => f64::to_cpu_storage_owned(self.run::<f64>(
                operand(g, lg, ng, "the upstream gradient")?,
                operand(dy, ldy, ndy, "dy")?,
                operand(p, lp, np, "the parameters")?,
            )?),
            d => bail!("per-texel mlp: unsupported dtype {d:?}"),
        };
        Ok((out, Shape::from(ndy + np)))
    }

    fn bwd(
        &self,
        _g: &Tensor,
        _dy: &Tensor,
        _p: &Tensor,
        _res: &Tensor,
        _grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        bail!(
            "per-texel mlp: third derivatives are not implemented; use \
             photomat_kernels::with_reference_ops"
        )
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::testing::max_abs_diff;
    use photomat_core::rng::pseudo_random;

    const ACT: MlpActivation = MlpActivation {
        slope: 0.2,
        gain: std::f64::consts::SQRT_2,
    };

    /// Weights and biases of a `dims` MLP as variables, with equalised-lr-like gains.
    fn layers(dims: &[usize], seed: u64, dtype: DType) -> Result<Vec<(Var, Var, f64, f64)>> {
        let dev = Device::Cpu;
        (0..dims.len() - 1)
            .map(|i| {
                let s = seed + 2 * i as u64;
                let w = Var::from_tensor(&pseudo_random((dims[i + 1], dims[i]), s, dtype, &dev)?)?;
                let b = Var::from_tensor(&pseudo_random(dims[i + 1], s + 1, dtype, &dev)?)?;
                Ok((w, b, 1.3 / (dims[i] as f64).sqrt(), 0.7))
            })
            .collect()
    }

    fn views(l: &[(Var, Var, f64, f64)]) -> Vec<MlpLayer<'_>> {
        l.iter()
            .map(|(w, b, g, bg)| MlpLayer {
                weight: w.as_tensor(),
                bias: b.as_tensor(),
                weight_gain: *g,
                bias_gain: *bg,
            })
            .collect()
    }

    /// The layers' weights and biases as constant tensors (outside any graph), with their gains.
    fn detached(l: &[(Var, Var, f64, f64)]) -> Vec<(Tensor, Tensor, f64, f64)> {
        l.iter()
            .map(|(w, b, g, bg)| (w.as_tensor().detach(), b.as_tensor().detach(), *g, *bg))
            .collect()
    }

    /// [`views`] of [`detached`] layers.
    fn constant_views(l: &[(Tensor, Tensor, f64, f64)]) -> Vec<MlpLayer<'_>> {
        l.iter()
            .map(|(w, b, g, bg)| MlpLayer {
                weight: w,
                bias: b,
                weight_gain: *g,
                bias_gain: *bg,
            })
            .collect()
    }

    /// Output and the gradients of `Σ y ⊙ r` with respect to every input and parameter.
    fn value_and_grads(
        y: &Tensor,
        r: &Tensor,
        wrt: &[&Var],
        params: &[(Var, Var, f64, f64)],
    ) -> Result<Vec<Tensor>> {
        let store = (y * r)?.sum_all()?.backward()?;
        let mut out = vec![y.clone()];
        for v in wrt
            .iter()
            .copied()
            .chain(params.iter().flat_map(|(w, b, _, _)| [w, b]))
        {
            out.push(store.get(v.as_tensor()).cloned().expect("a gradient"));
        }
        Ok(out)
    }

    fn compare(fused: &[Tensor], reference: &[Tensor], tol: f64, what: &str) -> Result<()> {
        assert_eq!(fused.len(), reference.len());
        for (j, (f, r)) in fused.iter().zip(reference).enumerate() {
            assert_eq!(f.dims(), r.dims(), "{what}, output {j}");
            let scale = r.abs()?.max_keepdim(0)?.flatten_all()?.max(0)?;
            let scale = scale.to_dtype(DType::F64)?.to_scalar::<f64>()?.max(1.0);
            let d = max_abs_diff(f, r)?;
            assert!(
                d <= tol * scale,
                "{what}, output {j}: |Δ| {d}, scale {scale}"
            );
        }
        Ok(())
    }

    /// With constant parameters (a frozen M) the inputs' gradients are those of the full
    /// backward pass, and the parameters get none.
    #[test]
    fn a_frozen_mlp_passes_the_same_input_gradients() -> Result<()> {
        let dev = Device::Cpu;
        let params = layers(&[7, 16, 16, 3], 5, DType::F64)?;
        let f = Var::from_tensor(&pseudo_random((2, 4, 17, 19), 6, DType::F64, &dev)?)?;
        let om = pseudo_random((2, 3, 17, 19), 7, DType::F64, &dev)?;
        let r = pseudo_random((2, 3, 17, 19), 8, DType::F64, &dev)?;
        let y = per_texel_mlp(f.as_tensor(), &om, &views(&params), ACT)?;
        let full = (y * &r)?.sum_all()?.backward()?;
        let frozen = detached(&params);
        let y = per_texel_mlp(f.as_tensor(), &om, &constant_views(&frozen), ACT)?;
        let store = (y * &r)?.sum_all()?.backward()?;
        let df = store.get(f.as_tensor()).expect("an input gradient");
        assert!(max_abs_diff(df, full.get(f.as_tensor()).expect("df"))? < 1e-12);
        assert!(
            params
                .iter()
                .all(|(w, _, _, _)| store.get(w.as_tensor()).is_none())
        );
        Ok(())
    }

    /// The parameter gradients sum over blocks of texels on several threads: they must come out
    /// the same, to the bit, every time (a training run must repeat, and a resumed one continue
    /// exactly), whichever thread takes which block.
    #[test]
    fn parameter_gradients_do_not_depend_on_thread_timing() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [7, 16, 16, 3];
        let params = layers(&dims, 1, DType::F32)?;
        // 4·48·48 = 9216 texels: 36 blocks over 4 threads.
        let f = pseudo_random((4, 4, 48, 48), 2, DType::F32, &dev)?;
        let om = pseudo_random((4, 3, 48, 48), 3, DType::F32, &dev)?;
        let r = pseudo_random((4, 3, 48, 48), 4, DType::F32, &dev)?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .expect("a pool");
        let grads = || -> Result<Vec<Vec<f32>>> {
            let y = per_texel_mlp(&f, &om, &views(&params), ACT)?;
            let store = (y * &r)?.sum_all()?.backward()?;
            params
                .iter()
                .flat_map(|(w, b, _, _)| [w, b])
                .map(|v| {
                    store
                        .get(v.as_tensor())
                        .expect("a gradient")
                        .flatten_all()?
                        .to_vec1()
                })
                .collect()
        };
        let first = pool.install(grads)?;
        for _ in 0..20 {
            assert!(
                pool.install(grads)? == first,
                "gradients differ between runs"
            );
        }
        Ok(())
    }

    #[test]
    fn fused_mlp_matches_the_candle_composition_and_its_gradients() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [7, 16, 16, 16, 3];
        // Odd texel counts, one of them above a block (17·19 = 323 = 256 + 67), batch 1 and 2.
        for (case, (b, h, w)) in [(2, 17, 19), (1, 3, 5), (3, 1, 1)].into_iter().enumerate() {
            let seed = 100 * case as u64;
            let params = layers(&dims, seed, DType::F64)?;
            let f = Var::from_tensor(&pseudo_random((b, 4, h, w), seed + 50, DType::F64, &dev)?)?;
            let om = Var::from_tensor(&pseudo_random((b, 3, h, w), seed + 51, DType::F64, &dev)?)?;
            let r = pseudo_random((b, 3, h, w), seed + 52, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = per_texel_mlp(f.as_tensor(), om.as_tensor(), &views(&params), ACT)?;
                value_and_grads(&y, &r, &[&f, &om], &params)
            };
            let fused = run()?;
            let reference = crate::reference::with_reference_ops(run)?;
            // f64 sums of ≤ 323·16 O(1) terms in another order: far below 1e-9 (relative to
            // the largest value); pseudo-random inputs put no pre-activation exactly at 0.
            compare(&fused, &reference, 1e-9, &format!("nchw case {case}"))?;
            assert_eq!(fused.len(), 3 + 2 * (dims.len() - 1));
        }
        Ok(())
    }

    #[test]
    fn fused_mlp_on_rows_matches_the_candle_composition() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [5, 8, 8, 2];
        for (case, n) in [1usize, 255, 513].into_iter().enumerate() {
            let seed = 7 + 10 * case as u64;
            let params = layers(&dims, seed, DType::F64)?;
            let x = Var::from_tensor(&pseudo_random((n, 5), seed + 8, DType::F64, &dev)?)?;
            let r = pseudo_random((n, 2), seed + 9, DType::F64, &dev)?;
            let run = || -> Result<Vec<Tensor>> {
                let y = per_texel_mlp_rows(x.as_tensor(), &views(&params), ACT)?;
                value_and_grads(&y, &r, &[&x], &params)
            };
            let fused = run()?;
            let reference = crate::reference::with_reference_ops(run)?;
            compare(&fused, &reference, 1e-9, &format!("rows case {case}"))?;
        }
        Ok(())
    }

    #[test]
    fn fused_mlp_f32_and_untracked_inputs_match() -> Result<()> {
        let dev = Device::Cpu;
        let dims = [6, 32, 32, 3];
        let params = layers(&dims, 3, DType::F32)?;
        let f = pseudo_random((2, 3, 20, 20), 4, DType::F32, &dev)?;
        let om = pseudo_random((2, 3, 20, 20), 5, DType::F32, &dev)?;
        // Plain tensors only: the forward keeps no activations, and still equals the reference.
        let plain = detached(&params);
        let l = constant_views(&plain);
        let fused = per_texel_mlp(&f, &om, &l, ACT)?;
        let reference = per_texel_mlp_reference(&f, &om, &l, ACT)?;
        // f32 sums of ≤ 38 O(1) terms per layer over 3 layers: ≈ 1e-6 relative.
        compare(&[fused], &[reference], 1e-5, "f32 untracked")?;
        Ok(())
    }

    #[test]
    fn fused_mlp_rejects_bad_arguments() -> Result<()> {
        let dev = Device::Cpu;
        let params = layers(&[5, 4, 4, 3], 1, DType::F32)?;
        let l = views(&params);
        let f = Tensor::zeros((1, 2, 4, 4), DType::F32, &dev)?;
        let om = Tensor::zeros((1, 3, 4, 4), DType::F32, &dev)?;
        assert!(per_texel_mlp(&f, &om, &l, ACT).is_ok());
        let om_bad = Tensor::zeros((1, 3, 4, 5), DType::F32, &dev)?;
        assert!(
            per_texel_mlp(&f, &om_bad, &l, ACT).is_err(),
            "ω of another size"
        );
        let f_bad = Tensor::zeros((1, 3, 4, 4), DType::F32, &dev)?;
        assert!(
            per_texel_mlp(&f_bad, &om, &l, ACT).is_err(),
            "wrong input width"
        );
        assert!(per_texel_mlp(&f, &om, &l[..1], ACT).is_err(), "one layer");
        let bad = MlpActivation {
            slope: 1.5,
            gain: 1.0,
        };
        assert!(per_texel_mlp(&f, &om, &l, bad).is_err(), "slope");
        let bad = MlpActivation {
            slope: 0.2,
            gain: 0.0,
        };
        assert!(per_texel_mlp(&f, &om, &l, bad).is_err(), "gain");
        let uneven = layers(&[5, 4, 6, 3], 2, DType::F32)?;
        assert!(
            per_texel_mlp(&f, &om, &views(&uneven), ACT).is_err(),
            "hidden widths"
        );
        Ok(())
    }
}
