//! The light-conditioned discriminator D (PhotoMat paper §4 "Implementation": StyleGAN2's
//! discriminator with the per-pixel light directions concatenated to the RGB input, 6
//! channels; StyleGAN2 "resnet" D, Karras et al. 2020 Fig. 7c, StyleGAN2-ADA
//! `DiscriminatorBlock` and `DiscriminatorEpilogue`).
//!
//! ```text
//! RGB ‖ ω (B,6,R,R) → fromrgb 1×1 (C_R) ─┐
//! block r (R … 8):  x ─┬─ conv0 3×3 ── conv1 3×3 ↓2 ──·√½ ─⊕→ (C_{r/2}, r/2)
//!                      └─ skip 1×1 ↓2, no bias ───────·√½ ─┘
//! epilogue (4²): minibatch stddev (+1 ch) → conv 3×3 → fc (C₄·16 → C₄) → out (C₄ → 1)
//! ```
//!
//! Every conv and fc is an equalised-lr layer ([`crate::equalized`], λ = 1, biases 0) followed
//! by `lrelu` except the skip and the output. Downsampling uses the `[1,3,3,1]` FIR filter
//! ([`crate::fir`]) exactly as StyleGAN2's `conv2d_resample`: blur then stride-2 conv for the
//! 3×3 conv1, filter-and-decimate then 1×1 for the skip. D pads with zeros: it judges real
//! crops, which are not periodic, so it is the same in tileable mode.
//!
//! # Minibatch standard deviation
//! StyleGAN2 splits the batch into groups of G = min(4, B) samples (sample n in group
//! n mod (B/G)), computes per group the standard deviation of every feature over the group,
//! averages it over features and pixels into `mbstd_channels` = 1 value per group and appends
//! it as a constant channel. StyleGAN2 requires B to be a multiple of G; here the batch is
//! split into ⌈B/G⌉ groups by the same rule (sample n in group n mod ⌈B/G⌉), whose sizes then
//! differ by at most one and are ≥ 2 for B ≥ 2: identical to StyleGAN2 when G divides B, and
//! defined for any B. ε = 1e-8 inside the square root (StyleGAN2) keeps the derivative finite
//! (≤ 1/(2·10⁻⁴)) when a group's samples coincide, which a single-sample group always does.
//!
//! # Input sharpening
//! With [`GeneratorConfig::d_input_sharpen`] k > 0, D reads `x + k·(x − box₃ₓ₃ x)` in place of
//! the image x (the 3×3 mean with replicated borders, every image alike, ω untouched): a fixed
//! high-pass boost in front of `fromrgb`. Texture on flash photos has a small amplitude next
//! to the colour and the highlight, and a D started from unit-gain weights did not grow the
//! gain to see it: trained on nothing but real patches against their blurred copies it reached
//! a logit gap of 0.06 in 300 steps, against 3 in 50 steps with k = 9
//! (docs/benchmarks/gan-training.md, "Can the discriminator learn texture at all?"). R1 is taken
//! with respect to x, through it.
//!
//! Parameter names under `vb`: `b{r}.{fromrgb,conv0,conv1,skip}.{weight,bias}` for r = R … 8,
//! `b4.{conv,fc,out}.{weight,bias}`.

use candle_core::{D, Result, Tensor, bail};
use candle_nn::VarBuilder;

use crate::activation::{LRELU_GAIN, LRELU_SLOPE, bias_leaky_relu_gain, leaky_relu_gain};
use crate::equalized::{
    EqualizedConv2d, EqualizedLinear, LinearConfig, equalized_conv2d, equalized_linear,
};
use crate::fir::{blur_for_strided_conv, downsample2d};
use crate::padding::Padding;
use crate::relight::{OMEGA_CHANNELS, RGB_CHANNELS};
use crate::{BASE_RESOLUTION, GeneratorConfig};

/// ε of the minibatch standard deviation (justified in the module docs).
pub const MBSTD_EPS: f64 = 1e-8;
/// √½: the residual branches' gain, keeping the sum's variance.
const RESIDUAL_GAIN: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// StyleGAN2's `Conv2dLayer`: conv (optionally ↓2), bias, optional `lrelu`, times `gain`.
#[derive(Debug, Clone)]
struct DConv {
    conv: EqualizedConv2d,
    activate: bool,
    down: bool,
    gain: f64,
}

fn dconv(
    c_in: usize,
    c_out: usize,
    kernel: usize,
    (bias, activate, down, gain): (bool, bool, bool, f64),
    vb: VarBuilder,
) -> Result<DConv> {
    Ok(DConv {
        conv: equalized_conv2d(c_in, c_out, kernel, bias, vb)?,
        activate,
        down,
        gain,
    })
}

impl DConv {
    /// # Shapes
    /// (B, C_in, H, W) → (B, C_out, H/2, W/2) when downsampling, (B, C_out, H, W) otherwise.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let k = self.conv.kernel();
        // The output gain goes into the weights of a linear layer (the residual skip) and into
        // the fused activation's gain otherwise: no pass over the output of its own.
        let linear_gain = if self.activate { 1.0 } else { self.gain };
        let zeros = Padding::Zeros;
        let y = match (self.down, k) {
            (false, _) => self.conv.conv_times(x, 1, k / 2, zeros, linear_gain)?,
            (true, 1) => {
                self.conv
                    .conv_times(&downsample2d(x, zeros)?, 1, 0, zeros, linear_gain)?
            }
            (true, 3) => {
                let blurred = blur_for_strided_conv(x, zeros)?;
                self.conv.conv_times(&blurred, 2, 0, zeros, linear_gain)?
            }
            (true, k) => bail!("discriminator: no downsampling {k}×{k} conv"),
        };
        let gain = LRELU_GAIN * self.gain;
        match (self.activate, self.conv.bias()) {
            (true, Some(b)) => bias_leaky_relu_gain(&y, b, LRELU_SLOPE, gain),
            (true, None) => leaky_relu_gain(&y, LRELU_SLOPE, gain),
            (false, Some(b)) if self.gain != 1.0 => {
                photomat_kernels::add_channel_bias(&y, &b.affine(self.gain, 0.0)?)
            }
            (false, _) => self.conv.add_bias(&y),
        }
    }
}

/// One residual block of D, halving the resolution.
#[derive(Debug, Clone)]
struct DBlock {
    fromrgb: Option<DConv>,
    conv0: DConv,
    conv1: DConv,
    skip: DConv,
}

impl DBlock {
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let x = match &self.fromrgb {
            Some(f) => f.forward(x)?,
            None => x.clone(),
        };
        let y = self.skip.forward(&x)?;
        let x = self.conv1.forward(&self.conv0.forward(&x)?)?;
        y + x
    }
}

/// The discriminator D.
#[derive(Debug, Clone)]
pub struct Discriminator {
    blocks: Vec<DBlock>,
    conv: DConv,
    fc: EqualizedLinear,
    out: EqualizedLinear,
    resolution: usize,
    mbstd_group_size: usize,
    mbstd_channels: usize,
    input_sharpen: f64,
}

impl Discriminator {
    /// Builds D of `cfg` (resolution, channel table, minibatch-stddev settings) under `vb`.
    pub fn new(cfg: &GeneratorConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let mut blocks = Vec::new();
        let mut res = cfg.resolution;
        while res > BASE_RESOLUTION {
            let vb = vb.pp(format!("b{res}"));
            let (c, c_out) = (cfg.channels_at(res), cfg.channels_at(res / 2));
            let fromrgb = if res == cfg.resolution {
                let spec = (true, true, false, 1.0);
                Some(dconv(
                    RGB_CHANNELS + OMEGA_CHANNELS,
                    c,
                    1,
                    spec,
                    vb.pp("fromrgb"),
                )?)
            } else {
                None
            };
            blocks.push(DBlock {
                fromrgb,
                conv0: dconv(c, c, 3, (true, true, false, 1.0), vb.pp("conv0"))?,
                conv1: dconv(
                    c,
                    c_out,
                    3,
                    (true, true, true, RESIDUAL_GAIN),
                    vb.pp("conv1"),
                )?,
                skip: dconv(
                    c,
                    c_out,
                    1,
                    (false, false, true, RESIDUAL_GAIN),
                    vb.pp("skip"),
                )?,
            });
            res /= 2;
        }
        let vb = vb.pp(format!("b{BASE_RESOLUTION}"));
        let c4 = cfg.channels_at(BASE_RESOLUTION);
        if !c4.is_multiple_of(cfg.mbstd_channels) {
            bail!(
                "discriminator: {} minibatch-stddev channels do not divide the {c4} features at 4²",
                cfg.mbstd_channels
            );
        }
        let conv = dconv(
            c4 + cfg.mbstd_channels,
            c4,
            3,
            (true, true, false, 1.0),
            vb.pp("conv"),
        )?;
        let area = BASE_RESOLUTION * BASE_RESOLUTION;
        let fc = equalized_linear(c4 * area, c4, LinearConfig::default(), vb.pp("fc"))?;
        let out = equalized_linear(c4, 1, LinearConfig::default(), vb.pp("out"))?;
        Ok(Self {
            blocks,
            conv,
            fc,
            out,
            resolution: cfg.resolution,
            mbstd_group_size: cfg.mbstd_group_size,
            mbstd_channels: cfg.mbstd_channels,
            input_sharpen: cfg.d_input_sharpen,
        })
    }

    /// Logits for images under their light directions.
    ///
    /// # Shapes
    /// image (B, 3, R, R) in encoded space, omega (B, 3, R, R) → (B, 1).
    pub fn forward(&self, image: &Tensor, omega: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = image.dims4()?;
        if c != RGB_CHANNELS || (h, w) != (self.resolution, self.resolution) {
            bail!(
                "discriminator: image of shape {:?}, expected (B, 3, {r}, {r})",
                image.dims(),
                r = self.resolution
            );
        }
        if omega.dims4()? != (b, OMEGA_CHANNELS, h, w) {
            bail!(
                "discriminator: ω of shape {:?} does not match the image {:?}",
                omega.dims(),
                image.dims()
            );
        }
        let image = if self.input_sharpen > 0.0 {
            sharpen(image, self.input_sharpen)?
        } else {
            image.clone()
        };
        let mut x = Tensor::cat(&[&image, omega], 1)?;
        for block in &self.blocks {
            x = block.forward(&x)?;
        }
        let x = minibatch_stddev(&x, self.mbstd_group_size, self.mbstd_channels)?;
        let x = self.conv.forward(&x)?;
        let x = self.fc.forward_lrelu(&x.flatten_from(1)?)?;
        self.out.forward(&x)
    }
}

/// `x + k·(x − box₃ₓ₃ x)`: the 3×3 mean of each channel with replicated borders, subtracted
/// and amplified (module docs, "Input sharpening"). Differentiable to second order (pads,
/// narrows and sums).
///
/// # Shapes
/// (B, C, H, W) → same.
pub fn sharpen(x: &Tensor, k: f64) -> Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    let padded = x.pad_with_same(2, 1, 1)?.pad_with_same(3, 1, 1)?;
    let mut sum = padded.narrow(2, 0, h)?.narrow(3, 0, w)?;
    for (dy, dx) in (0..3).flat_map(|dy| (0..3).map(move |dx| (dy, dx))).skip(1) {
        sum = (sum + padded.narrow(2, dy, h)?.narrow(3, dx, w)?)?;
    }
    let mean = (sum / 9.0)?;
    x + ((x - mean)? * k)?
}

/// Appends the minibatch standard deviation channels (see the module docs).
///
/// # Shapes
/// (B, C, H, W) → (B, C + channels, H, W); C must be a multiple of `channels`.
pub fn minibatch_stddev(x: &Tensor, group_size: usize, channels: usize) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    if group_size == 0 || channels == 0 || c % channels != 0 {
        bail!("minibatch stddev: group {group_size}, {channels} channels for {c} features");
    }
    let groups = b.div_ceil(group_size.min(b));
    // Samples of group m: m, m + groups, m + 2·groups, … (narrow + cat: exact second
    // derivatives, `docs/candle-notes.md`).
    let members = |m: usize| -> Result<Tensor> {
        let parts = (m..b)
            .step_by(groups)
            .map(|n| x.narrow(0, n, 1))
            .collect::<Result<Vec<_>>>()?;
        Tensor::cat(&parts, 0)
    };
    let mut stats = Vec::with_capacity(groups);
    for m in 0..groups {
        let y = members(m)?.reshape(((), channels, c / channels, h, w))?; // (g, F, c/F, H, W)
        let centred = y.broadcast_sub(&y.mean_keepdim(0)?)?;
        let std = (centred.sqr()?.mean(0)? + MBSTD_EPS)?.sqrt()?; // (F, c/F, H, W)
        stats.push(std.reshape((channels, ()))?.mean(D::Minus1)?.unsqueeze(0)?); // (1, F)
    }
    let per_sample = (0..b)
        .map(|n| stats[n % groups].clone())
        .collect::<Vec<_>>();
    let s = Tensor::cat(&per_sample, 0)?
        .reshape((b, channels, 1, 1))?
        .broadcast_as((b, channels, h, w))?;
    Tensor::cat(&[x, &s.contiguous()?], 1)
}

impl Discriminator {
    /// The R1 penalty of StyleGAN2 (Mescheder et al. 2018, eq. 9): per sample, the squared
    /// norm of the gradient of D's logit with respect to the image, `‖∇ₓ D(x, ω)‖²`, ω held
    /// fixed. The result keeps its graph so that its gradient reaches D's parameters (the
    /// trainer applies γ/2 and the batch mean).
    ///
    /// This is a double backward: the input gradient comes from a backward pass that keeps its
    /// graph (`backward_keeping_graph`, `docs/candle-notes.md`, "Second-order gradients").
    ///
    /// # Shapes
    /// image (B, 3, R, R), omega (B, 3, R, R) → (B).
    pub fn r1_penalty(&self, image: &Tensor, omega: &Tensor) -> Result<Tensor> {
        let x = candle_core::Var::from_tensor(&image.detach())?;
        let logits = self.forward(x.as_tensor(), omega)?;
        let grads = logits.sum_all()?.backward_keeping_graph()?;
        let Some(gx) = grads.get(x.as_tensor()) else {
            bail!("R1 penalty: the logits do not depend on the image");
        };
        gx.sqr()?.flatten_from(1)?.sum(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    #[test]
    fn a_layer_gain_folded_into_weights_or_activation_scales_the_output() -> Result<()> {
        // A layer's output gain is applied inside its conv's weights (linear layers) or its
        // fused activation's gain: the layer with gain g must give g × the layer with gain 1,
        // same weights, for every (bias, activation, down, kernel) the discriminator uses, on
        // the fast ops and on plain candle.
        let dev = Device::Cpu;
        let x = photomat_core::rng::pseudo_random((2, 3, 8, 8), 4, DType::F64, &dev)?;
        let g = 0.6;
        for (bias, activate, down, k) in [
            (true, true, false, 3),
            (true, true, true, 3),
            (false, false, true, 1),
            (true, false, false, 3),
            (false, true, false, 1),
        ] {
            let vm = VarMap::new();
            let vb = VarBuilder::from_varmap(&vm, DType::F64, &dev);
            let scaled = dconv(3, 4, k, (bias, activate, down, g), vb.pp("l"))?;
            let plain = dconv(3, 4, k, (bias, activate, down, 1.0), vb.pp("l"))?;
            if bias {
                // Non-zero biases, so that a bias left unscaled shows.
                let b = vm.data().lock().expect("lock")["l.bias"].clone();
                b.set(&Tensor::new(&[0.3, -0.2, 0.5, -0.7], &dev)?)?;
            }
            for reference in [false, true] {
                let run = || -> Result<(Tensor, Tensor)> {
                    Ok((scaled.forward(&x)?, plain.forward(&x)?.affine(g, 0.0)?))
                };
                let (a, b) = if reference {
                    photomat_kernels::with_reference_ops(run)?
                } else {
                    run()?
                };
                let err = (a - b)?.abs()?.max_all()?.to_scalar::<f64>()?;
                // f64 rounding of O(1) sums.
                assert!(
                    err < 1e-12,
                    "{:?} reference {reference}: {err}",
                    (bias, activate, down, k)
                );
            }
        }
        Ok(())
    }

    #[test]
    fn sharpen_boosts_detail_around_the_replicated_3x3_mean() {
        let dev = Device::Cpu;
        // 4×4, one channel: v(r, c) = r·4 + c, plus a bump of 1 at (1, 2).
        let mut data: Vec<f64> = (0..16).map(|i| i as f64).collect();
        data[6] += 1.0;
        let x = Tensor::from_vec(data.clone(), (1, 1, 4, 4), &dev).unwrap();
        let k = 9.0;
        let y = sharpen(&x, k)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f64>()
            .unwrap();
        let at = |r: i64, c: i64| data[(r.clamp(0, 3) * 4 + c.clamp(0, 3)) as usize];
        for (r, c) in [(1, 2), (0, 0), (3, 1), (2, 2)] {
            let mean = (-1..=1)
                .flat_map(|dr| (-1..=1).map(move |dc| (dr, dc)))
                .map(|(dr, dc)| at(r + dr, c + dc))
                .sum::<f64>()
                / 9.0;
            let expect = at(r, c) + k * (at(r, c) - mean);
            assert!(
                (y[(r * 4 + c) as usize] - expect).abs() < 1e-12,
                "({r}, {c})"
            );
        }
        // A constant image is unchanged: only detail is boosted.
        let c = Tensor::full(0.3f64, (2, 3, 5, 5), &dev).unwrap();
        let d = (sharpen(&c, k).unwrap() - &c).unwrap().abs().unwrap();
        assert!(d.max_all().unwrap().to_scalar::<f64>().unwrap() < 1e-12);
    }

    #[test]
    fn a_sharpening_d_reads_the_gain_from_its_config_and_only_then_differs() {
        let dev = Device::Cpu;
        let cfg = GeneratorConfig {
            resolution: 32,
            channel_multiplier: 1.0 / 64.0,
            ..GeneratorConfig::default()
        };
        let build = |k: f64| {
            let vars = candle_nn::VarMap::new();
            let cfg = GeneratorConfig {
                d_input_sharpen: k,
                ..cfg.clone()
            };
            let vb = crate::init::seeded_var_builder(&vars, 3, candle_core::DType::F64, &dev);
            Discriminator::new(&cfg, vb).unwrap()
        };
        let image =
            crate::seeded_uniform((2, 3, 32, 32), 1, candle_core::DType::F64, &dev).unwrap();
        let omega =
            crate::seeded_uniform((2, 3, 32, 32), 2, candle_core::DType::F64, &dev).unwrap();
        let logits = |d: &Discriminator, x: &Tensor| {
            d.forward(x, &omega)
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1::<f64>()
                .unwrap()
        };
        let (plain, sharp) = (build(0.0), build(9.0));
        // The same weights (same seed): D with gain 9 on x is D with gain 0 on sharpen(x, 9).
        assert_eq!(
            logits(&sharp, &image),
            logits(&plain, &sharpen(&image, 9.0).unwrap())
        );
        assert_ne!(logits(&sharp, &image), logits(&plain, &image));
        // Out-of-range gains are refused by the config.
        let bad = GeneratorConfig {
            d_input_sharpen: -1.0,
            ..cfg
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("d_input_sharpen")
        );
    }
}
