//! The per-texel MLP's backward op: the chain in reverse per block, input gradients written
//! in their NCHW layout, weight and bias gradients summed per run of blocks; it keeps every
//! block's `dzᵢ` when its own graph is kept, for [`super::second_order`].

use std::sync::{Arc, Mutex};

use candle_core::backend::BackendStorage;
use candle_core::{
    CpuStorage, CustomOp2, DType, Layout, Result, Shape, Storage, Tensor, WithDType, bail,
};

use super::net::{Net, Weights, mask};
use super::rows::{
    BLOCK_ROWS, Block, Io, Scatter, gather, operand, split_blocks, sum_over_runs, two_slots,
};
use super::second_order::SecondOrder;
use crate::alloc::output_buffer;
use crate::matmul::{Mat, matmul_rows};

/// The backward op: (dy, packed parameters) → `[d input₀ | d input₁ … | d parameters]`,
/// flat. The inputs (for the first layer's weight gradient) and the forward's activations are
/// read from the op itself; the activations enter only through masks and weight gradients.
pub(super) struct Backward {
    pub(super) net: Arc<Net>,
    pub(super) io: Arc<Io>,
    pub(super) hidden: Arc<CpuStorage>,
    pub(super) inputs: Vec<Tensor>,
    pub(super) save_dz: bool,
    /// Whether the parameters are in the graph: when they are constants (a frozen M, as when
    /// a photo is inverted) their gradient stays zero instead of being computed.
    pub(super) params_needed: bool,
    /// Every block's dzᵢ, i < L − 1 (laid out as the activations), for the second-order op.
    pub(super) saved_dz: Mutex<Option<Arc<CpuStorage>>>,
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
        let pass = Pass {
            net,
            io,
            wts: Weights::new(net, params),
            data,
            dy,
            hidden: hidden_chunks,
            offsets,
            scatter: Scatter::new(grads_in),
            params_needed: self.params_needed,
        };
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
        let fold = |mut t: Task<T>, (bi, dz): (usize, Option<&mut [T]>)| {
            pass.block(&mut t, blocks[bi], bi, dz);
            t
        };
        let mut dz_all = if self.save_dz {
            // SAFETY: `Pass::block` writes dz of layers l − 1 … 1 into slots l − 2 … 0 for
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
        net.scale_gradients(&acc, &mut out[total_in..], true);
        Ok((out, self.save_dz.then_some(dz_all)))
    }
}

/// One task's state: the parameter-gradient partial sums (unscaled) and scratch.
struct Task<T> {
    acc: Vec<T>,
    x: Vec<T>,
    dlast: Vec<T>,
    dx: Vec<T>,
    slots: Vec<T>,
}

/// What every block of one backward pass reads, and where it writes the input gradients.
struct Pass<'a, T> {
    net: &'a Net,
    io: &'a Io,
    wts: Weights<T>,
    /// The inputs, in order.
    data: Vec<&'a [T]>,
    dy: &'a [T],
    /// Each block's saved activations.
    hidden: Vec<&'a [T]>,
    /// Where each input's gradient starts in the op's output.
    offsets: Vec<usize>,
    scatter: Scatter<T>,
    params_needed: bool,
}

impl<T: WithDType> Pass<'_, T> {
    /// The chain in reverse over block `blk` (number `bi`): its input gradients scattered
    /// into place, its parameter gradients added to `t.acc`, its dzᵢ (i < L − 1) into `dz`
    /// when given (else into the task's two ping-pong slots).
    fn block(&self, t: &mut Task<T>, blk: Block, bi: usize, dz: Option<&mut [T]>) {
        let (net, io, wts) = (self.net, self.io, &self.wts);
        let (l, hid, d0, dl) = (net.layers(), net.hidden(), net.in_width(), net.out_width());
        let len = blk.len;
        let h = self.hidden[bi];
        let (dz, ns) = match dz {
            Some(d) => (d, l - 1),
            None => (&mut t.slots[..2 * len * hid], (l - 1).min(2)),
        };
        let sl = len * hid;
        gather(&io.inputs, &self.data, blk, d0, &mut t.x[..len * d0]);
        gather(&[io.output], &[self.dy], blk, dl, &mut t.dlast[..len * dl]);
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
                matmul_rows(
                    (outw, inw, len),
                    &mut t.acc[wo..wo + outw * inw],
                    true,
                    Mat::new(cur, 1, outw),
                    Mat::new(prev, inw, 1),
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
                    matmul_rows(
                        (len, inw, outw),
                        next,
                        false,
                        Mat::new(cur, outw, 1),
                        Mat::new(&wts.w[i], inw, 1),
                    );
                    mask(next, prev, net.act);
                }
                None => {
                    matmul_rows(
                        (len, inw, outw),
                        &mut t.dx[..len * d0],
                        false,
                        Mat::new(cur, outw, 1),
                        Mat::new(&wts.w[i], inw, 1),
                    );
                }
            }
        }
        let dx = &t.dx[..len * d0];
        self.scatter
            .put(&io.inputs, &self.offsets, blk, d0, dx, None);
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
