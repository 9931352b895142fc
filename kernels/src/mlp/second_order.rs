//! The per-texel MLP's second-order op, the backward of [`super::backward`]'s input
//! gradient (module docs of [`crate::mlp`], "Higher derivatives").

use std::sync::Arc;

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp3, DType, Layout, Result, Shape, Tensor, WithDType, bail};

use super::net::{Net, Weights, mask};
use super::rows::{BLOCK_ROWS, Block, Io, Scatter, gather, operand, sum_over_runs, two_slots};
use crate::matmul::{Mat, matmul_rows};

/// The backward's backward: (upstream gradient of `[d inputs | d parameters]`, dy, packed
/// parameters) → `[d dy | d parameters]`. Only the input-gradient part may be non-zero (module
/// docs, "Higher derivatives").
pub(super) struct SecondOrder {
    pub(super) net: Arc<Net>,
    pub(super) io: Arc<Io>,
    pub(super) hidden: Arc<CpuStorage>,
    pub(super) dz: Arc<CpuStorage>,
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
        let mut out = vec![T::zero(); io.output_len() + np];
        let blocks = io.blocks();
        let pass = Pass {
            net,
            io,
            wts: Weights::new(net, params),
            gs,
            dy,
            hidden,
            dz,
            per_row,
            scatter: Scatter::new(&mut out[..io.output_len()]),
        };
        let new_task = || Task {
            acc: vec![T::zero(); np],
            x: vec![T::zero(); BLOCK_ROWS * d0],
            dlast: vec![T::zero(); BLOCK_ROWS * dl],
            ulast: vec![T::zero(); BLOCK_ROWS * dl],
            slots: vec![T::zero(); 2 * BLOCK_ROWS * hid],
        };
        let fold = |mut t: Task<T>, bi: usize| {
            pass.block(&mut t, blocks[bi]);
            t
        };
        let acc = sum_over_runs((0..blocks.len()).collect(), new_task, fold, |t| t.acc);
        // The input gradient does not depend on the biases: their entries stay zero.
        net.scale_gradients(&acc, &mut out[io.output_len()..], false);
        Ok(out)
    }
}

/// One task's state: the weight-gradient partial sums (unscaled) and scratch.
struct Task<T> {
    acc: Vec<T>,
    x: Vec<T>,
    dlast: Vec<T>,
    ulast: Vec<T>,
    slots: Vec<T>,
}

/// What every block of one second-order pass reads, and where it writes `d dy`.
struct Pass<'a, T> {
    net: &'a Net,
    io: &'a Io,
    wts: Weights<T>,
    /// The upstream gradient of each input's gradient.
    gs: Vec<&'a [T]>,
    dy: &'a [T],
    /// The forward's activations and the backward's dzᵢ, block-major.
    hidden: &'a [T],
    dz: &'a [T],
    per_row: usize,
    scatter: Scatter<T>,
}

impl<T: WithDType> Pass<'_, T> {
    /// The masked chain forward over block `blk` on the upstream gradient: `d dy` scattered
    /// into place, the weight products added to `t.acc`.
    fn block(&self, t: &mut Task<T>, blk: Block) {
        let (net, io) = (self.net, self.io);
        let (l, hid, d0, dl) = (net.layers(), net.hidden(), net.in_width(), net.out_width());
        let Task {
            acc,
            x,
            dlast,
            ulast,
            slots,
        } = t;
        let len = blk.len;
        let sl = len * hid;
        let start = blk.row * self.per_row;
        let h = &self.hidden[start..start + len * self.per_row];
        let dzb = &self.dz[start..start + len * self.per_row];
        gather(&io.inputs, &self.gs, blk, d0, &mut x[..len * d0]);
        gather(&[io.output], &[self.dy], blk, dl, &mut dlast[..len * dl]);
        let slots = &mut slots[..2 * sl];
        for i in 0..l {
            let (inw, outw) = (net.dims[i], net.dims[i + 1]);
            let wo = net.offsets(i).0;
            let last = i + 1 == l;
            let dzi: &[T] = if last {
                &dlast[..len * dl]
            } else {
                &dzb[i * sl..(i + 1) * sl]
            };
            // uᵢ = uᵢ₋₁·Ŵᵢᵀ (masked below), ∂/∂Ŵᵢ += dzᵢᵀ·uᵢ₋₁. L ≥ 2, so layer 0 is never
            // the last.
            let (prev, dst): (&[T], &mut [T]) = if i == 0 {
                (&x[..len * d0], &mut slots[..sl])
            } else if last {
                let s = (i - 1) % 2;
                (&slots[s * sl..(s + 1) * sl], &mut ulast[..len * dl])
            } else {
                two_slots(slots, sl, (i - 1) % 2, i % 2)
            };
            matmul_rows(
                (outw, inw, len),
                &mut acc[wo..wo + outw * inw],
                true,
                Mat::new(dzi, 1, outw),
                Mat::new(prev, inw, 1),
            );
            let wt = Mat::new(&self.wts.wt[i][..], outw, 1);
            matmul_rows((len, outw, inw), dst, false, Mat::new(prev, inw, 1), wt);
            if !last {
                mask(dst, &h[i * sl..(i + 1) * sl], net.act);
            }
        }
        let u = &ulast[..len * dl];
        self.scatter.put(&[io.output], &[0], blk, dl, u, None);
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
