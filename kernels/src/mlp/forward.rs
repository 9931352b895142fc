//! The per-texel MLP's forward op: each block of rows runs the whole chain of layers while
//! its activations are in cache, keeping the hidden activations for the backward only when
//! an operand is tracked.

use std::sync::{Arc, Mutex};

use candle_core::backend::BackendStorage;
use candle_core::{
    CpuStorage, CustomOp2, CustomOp3, DType, Layout, Result, Shape, Tensor, WithDType, bail,
};
use rayon::prelude::*;

use super::backward::Backward;
use super::net::{Net, Weights, bias_act};
use super::rows::{
    BLOCK_ROWS, Block, Io, Scatter, for_blocks, gather, operand, split_blocks, two_slots,
};
use crate::alloc::output_buffer;
use crate::matmul::{Mat, matmul_rows};

/// The forward op: (inputs…, packed parameters) → output.
pub(super) struct Forward {
    net: Arc<Net>,
    io: Arc<Io>,
    save: bool,
    /// The hidden activations of every block (block-major: per block L − 1 layers of
    /// len × hidden values), kept for the backward.
    saved: Mutex<Option<Arc<CpuStorage>>>,
}

impl Forward {
    pub(super) fn new(net: Net, io: Io, save: bool) -> Self {
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
                    let rhs = Mat::new(&wts.wt[i][..], outw, 1);
                    if i + 1 == l {
                        let prev = &slots[((i - 1) % ns) * sl..((i - 1) % ns + 1) * sl];
                        matmul_rows(
                            (len, outw, inw),
                            &mut last[..len * dl],
                            false,
                            Mat::new(prev, inw, 1),
                            rhs,
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
                            matmul_rows(
                                (len, outw, inw),
                                dst,
                                false,
                                Mat::new(&x[..len * d0], inw, 1),
                                rhs,
                            );
                            dst
                        } else {
                            let (prev, dst) = two_slots(slots, sl, (i - 1) % ns, i % ns);
                            matmul_rows((len, outw, inw), dst, false, Mat::new(prev, inw, 1), rhs);
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

impl CustomOp3 for Forward {
    fn name(&self) -> &'static str {
        "per-texel-mlp"
    }

    fn cpu_fwd(
        &self,
        features: &CpuStorage,
        l_features: &Layout,
        omega: &CpuStorage,
        l_omega: &Layout,
        params: &CpuStorage,
        l_params: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        self.cpu(
            &[(features, l_features), (omega, l_omega)],
            (params, l_params),
        )
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
        rows: &CpuStorage,
        l_rows: &Layout,
        params: &CpuStorage,
        l_params: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        self.cpu(&[(rows, l_rows)], (params, l_params))
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
