//! The per-texel MLP's layers as the caller stores them ([`MlpLayer`], [`MlpActivation`]), the
//! network's checked geometry and constants ([`Net`]), its effective weights for one call
//! ([`Weights`], the equalised learning rate of Karras et al. 2018 §4.1) and the activation
//! applied to a block of rows, forward and backward.

use candle_core::{Result, Tensor, WithDType, bail};

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

/// The stored parameters as one vector `[W₀, b₀, W₁, b₁, …]` (weights row-major), the op's
/// third operand; `cat`'s backward hands each layer its part of the gradient.
pub(super) fn pack(layers: &[MlpLayer<'_>]) -> Result<Tensor> {
    let parts = layers
        .iter()
        .flat_map(|l| [l.weight.flatten_all(), Ok(l.bias.clone())])
        .collect::<Result<Vec<_>>>()?;
    Tensor::cat(&parts, 0)
}

/// The network's geometry and constants.
#[derive(Debug, Clone)]
pub(super) struct Net {
    /// Widths d₀ … d_L.
    pub(super) dims: Vec<usize>,
    pub(super) weight_gains: Vec<f64>,
    pub(super) bias_gains: Vec<f64>,
    pub(super) act: MlpActivation,
}

impl Net {
    pub(super) fn new(layers: &[MlpLayer<'_>], d0: usize, act: MlpActivation) -> Result<Self> {
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
    pub(super) fn layers(&self) -> usize {
        self.dims.len() - 1
    }

    pub(super) fn in_width(&self) -> usize {
        self.dims[0]
    }

    pub(super) fn hidden(&self) -> usize {
        self.dims[1]
    }

    pub(super) fn out_width(&self) -> usize {
        self.dims[self.layers()]
    }

    /// Offsets of layer i's weight and bias in the packed parameters.
    pub(super) fn offsets(&self, i: usize) -> (usize, usize) {
        let w = (0..i)
            .map(|j| self.dims[j + 1] * (self.dims[j] + 1))
            .sum::<usize>();
        (w, w + self.dims[i + 1] * self.dims[i])
    }

    pub(super) fn param_len(&self) -> usize {
        let (_, b) = self.offsets(self.layers() - 1);
        b + self.out_width()
    }

    /// The gradients of the stored parameters from `acc`, those of the effective ones
    /// (`∂/∂W = weight_gain · ∂/∂Ŵ`, likewise the biases), written into `out` (packed as the
    /// parameters); bias entries are left as they are unless `biases`.
    pub(super) fn scale_gradients<T: WithDType>(&self, acc: &[T], out: &mut [T], biases: bool) {
        for i in 0..self.layers() {
            let (wo, bo) = self.offsets(i);
            let (inw, outw) = (self.dims[i], self.dims[i + 1]);
            let g = T::from_f64(self.weight_gains[i]);
            for j in wo..wo + outw * inw {
                out[j] = acc[j] * g;
            }
            if biases {
                let bg = T::from_f64(self.bias_gains[i]);
                for j in bo..bo + outw {
                    out[j] = acc[j] * bg;
                }
            }
        }
    }
}

/// The effective weights of one call: Ŵᵢ (out × in), Ŵᵢᵀ (in × out), b̂ᵢ, all row-major.
pub(super) struct Weights<T> {
    pub(super) w: Vec<Vec<T>>,
    pub(super) wt: Vec<Vec<T>>,
    pub(super) b: Vec<Vec<T>>,
}

impl<T: WithDType> Weights<T> {
    pub(super) fn new(net: &Net, params: &[T]) -> Self {
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

/// `x ⊙= f'(z)` with the sign of z read from the activation `h` (gain > 0, so h > 0 ⇔ z > 0).
pub(super) fn mask<T: WithDType>(x: &mut [T], h: &[T], act: MlpActivation) {
    let (p, n) = (T::from_f64(act.gain), T::from_f64(act.gain * act.slope));
    let zero = T::zero();
    for (x, &h) in x.iter_mut().zip(h) {
        *x *= if h > zero { p } else { n };
    }
}

/// `x = gain · LeakyReLU(x + bias)` per row of `bias.len()` values.
pub(super) fn bias_act<T: WithDType>(x: &mut [T], bias: &[T], act: MlpActivation) {
    let (p, n) = (T::from_f64(act.gain), T::from_f64(act.gain * act.slope));
    let zero = T::zero();
    for row in x.chunks_exact_mut(bias.len()) {
        for (v, &b) in row.iter_mut().zip(bias) {
            let z = *v + b;
            *v = if z > zero { p * z } else { n * z };
        }
    }
}
