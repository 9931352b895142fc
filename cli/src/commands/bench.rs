//! `photomat bench`: time whole training and sampling steps of G, M, D and E, and the
//! convolutions they are made of, for the side-by-side comparison with PyTorch CPU
//! (`bench/README.md`).
//!
//! The PyTorch half is `bench/pytorch/bench_steps.py`: same cases, same options, same JSON
//! schema; `bench/compare.py` runs both with equal thread counts and prints the table
//! (`bench/README.md`). Cases ([`Case`]):
//!
//! | case | what one iteration is |
//! |---|---|
//! | `g_step` | G + M forward, frozen D on the fakes, `softplus(−D)` loss, backward (the trainer's G phase) |
//! | `d_step` | D on fakes and reals, logistic loss, backward (the trainer's D phase, no R1) |
//! | `d_r1` | R1 penalty (D forward, input gradient with its graph, squared norm), backward |
//! | `e_step` | E forward, `height(ggx)` decode, flash render, 0.1·L1 to M's image, backward |
//! | `sample` | one material (batch 1): G forward, M relight, E maps, analytic render |
//! | `mlp` | M alone on B·R² texel rows, forward + backward |
//! | `conv3x3`, `conv4x4s2`, `conv1x1` | one 64→64 conv at 2R × 2R (128² at R = 64), fwd + bwd |
//! | `modconv` | G's modulated, demodulated 3×3 conv 64→64 at R × R, fwd + bwd |
//! | `fir_up`, `bilinear_up` | G's FIR ×2 and E's periodic bilinear ×2 upsampling, 64 channels at R × R, fwd + bwd |
//! | `bias_lrelu` | bias + `lrelu` on 64 channels at 2R × 2R, fwd + bwd |
//! | `sgemm` | one 1024² × 1024² f32 matmul: the GEMM ceiling of this machine |
//!
//! Every backward is taken of a scalar and produces the gradients of every parameter in the
//! graph (`g_step` judges the fakes with D's weights as constants, as the trainer's G phase
//! does, so not D's); no optimiser update
//! is timed. Inputs (latents, noise images, fakes, reals, lights) are drawn once, seeded,
//! outside the timed region. Each case runs `--warmup` untimed iterations and `--iters` timed
//! ones, in its own thread; the report holds every time, the median (the middle value, the
//! upper one for an even count) and the minimum. Threads: `RAYON_NUM_THREADS`, else one per
//! physical core ([`photomat_kernels::alloc`]).
//!
//! `--candle-reference` runs every photomat-kernels op on its plain-candle reference path
//! ([`with_reference_ops`]): the same steps as before the fast kernels, for a three-way
//! comparison (`bench/compare.py --candle-baseline`).
//!
//! As in the GAN trainer, only R1's inner backward pass keeps the graph of its gradients
//! (`backward_keeping_graph`); every other backward pass detaches them.

use std::io::Write;
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::VarMap;
use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::render::to_network_range;
use photomat_core::rng::{SplitMix64, pseudo_random};
use photomat_core::{
    Brdf, FlashGeometry, Highlight, LightSet, encode_display, lookup, render_radiance_with,
};
use photomat_estimator::{EstimatorConfig, EstimatorModel, upsample2x_periodic};
use photomat_generator::activation::bias_lrelu;
use photomat_generator::fir::upsample2d;
use photomat_generator::modulated_conv::modulated_conv2d;
use photomat_generator::padding::Padding;
use photomat_generator::train::config::default_r1_gamma;
use photomat_generator::train::loss::{discriminator_loss, generator_loss, r1_loss};
use photomat_generator::{
    Discriminator, GanModel, GeneratorConfig, NoiseInput, parameter_count, seeded_var_builder,
};
use photomat_kernels::{Conv2dSpec, conv2d, with_reference_ops};
use photomat_train::varmap::frozen_var_builder;
use serde::Serialize;

/// BRDF model of the estimator cases: the paper's configuration (n = 8).
const BRDF: &str = "height(ggx)";
/// Channels of the per-op convolution cases (the 64-channel layers of G at 128², E's level 2).
const MICRO_CHANNELS: usize = 64;
/// Side of the square matrices of the `sgemm` case.
const SGEMM_SIDE: usize = 1024;
/// Weight of the L1 term of E's loss (PhotoMat §3: 0.1·L1, Gram left out of this bench).
const L1_WEIGHT: f64 = 0.1;
/// Lazy R1 interval of the reference (StyleGAN2, Karras et al. 2020), applied as the trainer
/// does.
const R1_INTERVAL: usize = 16;

/// One benchmark case.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Case {
    #[value(name = "g_step")]
    GStep,
    #[value(name = "d_step")]
    DStep,
    #[value(name = "d_r1")]
    DR1,
    #[value(name = "e_step")]
    EStep,
    #[value(name = "sample")]
    Sample,
    #[value(name = "mlp")]
    Mlp,
    #[value(name = "conv3x3")]
    Conv3x3,
    #[value(name = "conv4x4s2")]
    Conv4x4s2,
    #[value(name = "conv1x1")]
    Conv1x1,
    #[value(name = "modconv")]
    ModConv,
    #[value(name = "fir_up")]
    FirUp,
    #[value(name = "bias_lrelu")]
    BiasLrelu,
    #[value(name = "bilinear_up")]
    BilinearUp,
    #[value(name = "sgemm")]
    Sgemm,
}

impl Case {
    /// Every case, in report order.
    pub const ALL: [Case; 14] = [
        Case::GStep,
        Case::DStep,
        Case::DR1,
        Case::EStep,
        Case::Sample,
        Case::Mlp,
        Case::Conv3x3,
        Case::Conv4x4s2,
        Case::Conv1x1,
        Case::ModConv,
        Case::FirUp,
        Case::BiasLrelu,
        Case::BilinearUp,
        Case::Sgemm,
    ];

    /// The name shared with the PyTorch script.
    pub fn name(self) -> &'static str {
        match self {
            Case::GStep => "g_step",
            Case::DStep => "d_step",
            Case::DR1 => "d_r1",
            Case::EStep => "e_step",
            Case::Sample => "sample",
            Case::Mlp => "mlp",
            Case::Conv3x3 => "conv3x3",
            Case::Conv4x4s2 => "conv4x4s2",
            Case::Conv1x1 => "conv1x1",
            Case::ModConv => "modconv",
            Case::FirUp => "fir_up",
            Case::BiasLrelu => "bias_lrelu",
            Case::BilinearUp => "bilinear_up",
            Case::Sgemm => "sgemm",
        }
    }

    /// What one iteration does (the same text as the PyTorch script's).
    pub fn what(self) -> &'static str {
        match self {
            Case::GStep => {
                "G+M forward, frozen D on the fakes, softplus(-D) loss, backward (G and M gradients)"
            }
            Case::DStep => "D forward on fake+real images, logistic loss, backward to D (no R1)",
            Case::DR1 => {
                "R1 penalty (D forward, input gradient with graph, squared norm), backward to D"
            }
            Case::EStep => {
                "E forward, height(ggx) decode, flash render, 0.1*L1 to M's image, backward to E"
            }
            Case::Sample => {
                "one material: G forward, M relight and E maps + analytic render at the centre"
            }
            Case::Mlp => "M alone (per-texel MLP on B*R*R rows), forward + backward",
            Case::Conv3x3 => "3x3 conv 64->64, stride 1, zero padding 1, at 2R x 2R: fwd + bwd",
            Case::Conv4x4s2 => "4x4 conv 64->64, stride 2, zero padding 1, at 2R x 2R: fwd + bwd",
            Case::Conv1x1 => "1x1 conv 64->64 at 2R x 2R: forward + backward",
            Case::ModConv => "G's modulated 3x3 conv 64->64 with demodulation at R x R: fwd + bwd",
            Case::FirUp => "G's [1,3,3,1] FIR x2 upsampling of 64 channels, R -> 2R: fwd + bwd",
            Case::BiasLrelu => {
                "bias + LeakyReLU(0.2) * sqrt(2) on 64 channels at 2R x 2R: fwd + bwd"
            }
            Case::BilinearUp => {
                "E's periodic bilinear x2 upsampling of 64 channels, R -> 2R: fwd + bwd"
            }
            Case::Sgemm => "one 1024x1024 by 1024x1024 f32 matrix product (the GEMM ceiling)",
        }
    }

    /// (kernel, stride, padding) of the convolution cases.
    fn conv_shape(self) -> Option<(usize, usize, usize)> {
        match self {
            Case::Conv3x3 => Some((3, 1, 1)),
            Case::Conv4x4s2 => Some((4, 2, 1)),
            Case::Conv1x1 => Some((1, 1, 0)),
            _ => None,
        }
    }
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Resolution R of G, M, D and E (a power of two ≥ 32); the conv cases run at 2R × 2R.
    #[arg(long, default_value_t = 64)]
    pub size: usize,

    /// Channel multiplier of G and D (1 = the paper's network).
    #[arg(long, default_value_t = 0.25)]
    pub multiplier: f64,

    /// Batch of the training steps and the conv cases (sampling is one material).
    #[arg(long, default_value_t = 4)]
    pub batch: usize,

    /// Timed iterations per case.
    #[arg(long, default_value_t = 5)]
    pub iters: usize,

    /// Untimed iterations per case before the timed ones.
    #[arg(long, default_value_t = 1)]
    pub warmup: usize,

    /// Cases to run, comma-separated (default: all).
    #[arg(long, value_delimiter = ',', value_enum, default_values_t = Case::ALL)]
    pub cases: Vec<Case>,

    /// Seed of the weights and inputs.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,

    /// Print the report as JSON (the schema `bench/compare.py` reads) instead of a table.
    #[arg(long)]
    pub json: bool,

    /// Run every photomat-kernels op on its plain-candle reference path
    /// (`photomat_kernels::with_reference_ops`): the baseline before the fast kernels.
    #[arg(long)]
    pub candle_reference: bool,
}

/// Trainable parameter counts (buffers apart), for the equality check against PyTorch.
#[derive(Debug, Serialize)]
struct Parameters {
    g: usize,
    g_buffers: usize,
    m: usize,
    d: usize,
    e: usize,
}

/// One case's timings.
#[derive(Debug, Serialize)]
struct CaseReport {
    name: &'static str,
    what: &'static str,
    size: usize,
    batch: usize,
    median_s: f64,
    min_s: f64,
    times_s: Vec<f64>,
    /// Floating-point operations per iteration where they are known exactly (conv, sgemm).
    flops: Option<f64>,
}

/// The whole report; the PyTorch script writes the same fields.
#[derive(Debug, Serialize)]
struct Report {
    implementation: &'static str,
    version: String,
    threads: usize,
    platform: String,
    /// The vector family of photomat-kernels' direct kernels (`avx512`, `avx2`, `scalar`).
    kernels: &'static str,
    size: usize,
    multiplier: f64,
    batch: usize,
    iters: usize,
    warmup: usize,
    /// Whether the kernels ran on their candle reference path (`--candle-reference`).
    reference_ops: bool,
    parameters: Parameters,
    cases: Vec<CaseReport>,
}

/// Networks and inputs shared by the cases of one run (built once, outside every timing).
struct Setup {
    gan: GanModel,
    d: Discriminator,
    /// D with its weights as constants (the trainer's G phase).
    d_frozen: Discriminator,
    e: EstimatorModel,
    brdf: Brdf,
    /// Flash geometry of the batch's highlights and of the centred flash (batch 1).
    lights: FlashGeometry,
    centre: FlashGeometry,
    z: Tensor,
    noise: Vec<Tensor>,
    z1: Tensor,
    noise1: Vec<Tensor>,
    /// G's features and M's images of the batch, without graph: E's inputs and targets, D's fakes.
    features: Tensor,
    fakes: Tensor,
    reals: Tensor,
    parameters: Parameters,
}

impl Setup {
    fn new(args: &Args) -> anyhow::Result<Self> {
        let dev = Device::Cpu;
        let (r, b) = (args.size, args.batch);
        let cfg = GeneratorConfig {
            resolution: r,
            channel_multiplier: args.multiplier,
            ..Default::default()
        };
        cfg.validate().context("invalid --size or --multiplier")?;
        let gan = GanModel::new(&cfg, args.seed, &dev)?;
        let d_vars = VarMap::new();
        let d = Discriminator::new(
            &cfg,
            seeded_var_builder(&d_vars, args.seed ^ 1, DType::F32, &dev),
        )?;
        let d_frozen = Discriminator::new(&cfg, frozen_var_builder(&d_vars, DType::F32, &dev))?;
        let brdf = lookup(BRDF)?;
        let e = EstimatorModel::new(
            brdf.clone(),
            EstimatorConfig::for_brdf(brdf.as_ref()),
            VarMap::new(),
            &dev,
        )?;
        let mut rng = SplitMix64(args.seed);
        let lights = LightSet::uniform(b, || rng.next_unit()).geometry(r, DType::F32, &dev)?;
        let centre = LightSet::single(Highlight::CENTER).geometry(r, DType::F32, &dev)?;
        let seeds: Vec<u64> = (0..b as u64).map(|i| args.seed.wrapping_add(i)).collect();
        let (z, noise) = (gan.latents(&seeds)?, gan.noise_images(&seeds)?);
        let (z1, noise1) = (gan.latents(&seeds[..1])?, gan.noise_images(&seeds[..1])?);
        let features = gan
            .generator()
            .forward(&z, 1.0, &NoiseInput::Given(&noise))?
            .detach();
        let fakes = gan.relight().forward(&features, &lights.omega)?.detach();
        let reals = pseudo_random((b, 3, r, r), args.seed ^ 2, DType::F32, &dev)?;
        let count = |prefix: &str| -> (usize, usize) {
            let data = gan.vars().data().lock().expect("VarMap lock poisoned");
            let mut sums = (0, 0);
            for (name, var) in data.iter().filter(|(n, _)| n.starts_with(prefix)) {
                if photomat_generator::is_buffer(name) {
                    sums.1 += var.elem_count();
                } else {
                    sums.0 += var.elem_count();
                }
            }
            sums
        };
        let ((g, g_buffers), (m, _)) = (count("g."), count("m."));
        let parameters = Parameters {
            g,
            g_buffers,
            m,
            d: parameter_count(&d_vars, false),
            e: e.estimator().config().num_parameters(),
        };
        Ok(Self {
            gan,
            d,
            d_frozen,
            e,
            brdf,
            lights,
            centre,
            z,
            noise,
            z1,
            noise1,
            features,
            fakes,
            reals,
            parameters,
        })
    }
}

/// A timed iteration of one case.
type Step<'a> = Box<dyn FnMut() -> anyhow::Result<()> + 'a>;

/// The iteration of `case`, its batch and its FLOPs (where known); inputs are made here.
fn step<'a>(
    case: Case,
    s: &'a Setup,
    args: &Args,
) -> anyhow::Result<(Step<'a>, usize, Option<f64>)> {
    let (r, b) = (args.size, args.batch);
    let g = s.gan.generator();
    let m = s.gan.relight();
    let omega = &s.lights.omega;
    let dev = Device::Cpu;
    Ok(match case {
        Case::GStep => (
            Box::new(move || {
                let f = g.forward(&s.z, 1.0, &NoiseInput::Given(&s.noise))?;
                let logits = s.d_frozen.forward(&m.forward(&f, omega)?, omega)?;
                drop(generator_loss(&logits)?.backward()?);
                Ok(())
            }),
            b,
            None,
        ),
        Case::DStep => (
            Box::new(move || {
                let fake = s.d.forward(&s.fakes, omega)?;
                let real = s.d.forward(&s.reals, omega)?;
                drop(discriminator_loss(&real, &fake, None)?.backward()?);
                Ok(())
            }),
            b,
            None,
        ),
        Case::DR1 => {
            let gamma = default_r1_gamma(r, b);
            (
                Box::new(move || {
                    let penalty = s.d.r1_penalty(&s.reals, omega)?;
                    drop(r1_loss(&penalty, gamma, R1_INTERVAL)?.backward()?);
                    Ok(())
                }),
                b,
                None,
            )
        }
        Case::EStep => (
            Box::new(move || {
                let maps = s.e.estimate(&s.features)?;
                let radiance = render_radiance_with(s.brdf.as_ref(), &maps, &s.lights)?;
                let image = to_network_range(&encode_display(&radiance)?)?;
                let loss = ((image - &s.fakes)?.abs()?.mean_all()? * L1_WEIGHT)?;
                drop(loss.backward()?);
                Ok(())
            }),
            b,
            None,
        ),
        Case::Sample => (
            Box::new(move || {
                let f = g.forward(&s.z1, 1.0, &NoiseInput::Given(&s.noise1))?;
                let relit = m.forward(&f, &s.centre.omega)?;
                let maps = s.e.estimate(&f)?;
                let render = render_radiance_with(s.brdf.as_ref(), &maps, &s.centre)?;
                drop((relit, encode_display(&render)?));
                Ok(())
            }),
            1,
            None,
        ),
        Case::Mlp => {
            let rows = Tensor::cat(&[&s.features, omega], 1)?
                .permute((0, 2, 3, 1))?
                .contiguous()?
                .reshape((b * r * r, ()))?;
            let weights = pseudo_random((b * r * r, 3), args.seed ^ 3, DType::F32, &dev)?;
            (
                Box::new(move || {
                    let y = m.forward_rows(&rows)?;
                    drop((y * &weights)?.sum_all()?.backward()?);
                    Ok(())
                }),
                b,
                None,
            )
        }
        Case::Conv3x3 | Case::Conv4x4s2 | Case::Conv1x1 => {
            let (k, stride, padding) = case.conv_shape().expect("a conv case");
            let c = MICRO_CHANNELS;
            let w = Var::from_tensor(&pseudo_random(
                (c, c, k, k),
                args.seed ^ 5,
                DType::F32,
                &dev,
            )?)?;
            let spec = Conv2dSpec::zeros(stride, padding);
            let side = 2 * r;
            let out = (side + 2 * padding - k) / stride + 1;
            let flops = 3.0 * conv_flops(b, c, out, k);
            let conv = move |x: &Tensor| conv2d(x, w.as_tensor(), spec);
            (
                gradient_step((b, c, side, side), args.seed, conv)?,
                b,
                Some(flops),
            )
        }
        Case::ModConv => {
            let c = MICRO_CHANNELS;
            let latent = GeneratorConfig::default().latent_dim;
            let vars = VarMap::new();
            let vb = seeded_var_builder(&vars, args.seed ^ 5, DType::F32, &dev);
            let layer = modulated_conv2d(c, c, 3, latent, true, Padding::Zeros, vb)?;
            let w = pseudo_random((b, latent), args.seed ^ 9, DType::F32, &dev)?;
            let conv = move |x: &Tensor| layer.forward(x, &w);
            let flops = 3.0 * conv_flops(b, c, r, 3);
            (
                gradient_step((b, c, r, r), args.seed, conv)?,
                b,
                Some(flops),
            )
        }
        Case::FirUp => {
            let up = |x: &Tensor| upsample2d(x, Padding::Zeros);
            (
                gradient_step((b, MICRO_CHANNELS, r, r), args.seed, up)?,
                b,
                None,
            )
        }
        Case::BiasLrelu => {
            let bias = Var::from_tensor(&pseudo_random(
                MICRO_CHANNELS,
                args.seed ^ 9,
                DType::F32,
                &dev,
            )?)?;
            let act = move |x: &Tensor| bias_lrelu(x, bias.as_tensor());
            let shape = (b, MICRO_CHANNELS, 2 * r, 2 * r);
            (gradient_step(shape, args.seed, act)?, b, None)
        }
        Case::BilinearUp => (
            gradient_step((b, MICRO_CHANNELS, r, r), args.seed, upsample2x_periodic)?,
            b,
            None,
        ),
        Case::Sgemm => {
            let n = SGEMM_SIDE;
            let a = pseudo_random((n, n), args.seed ^ 7, DType::F32, &dev)?;
            let bm = pseudo_random((n, n), args.seed ^ 8, DType::F32, &dev)?;
            (
                Box::new(move || {
                    drop(a.matmul(&bm)?);
                    Ok(())
                }),
                1,
                Some(2.0 * (n * n * n) as f64),
            )
        }
    })
}

/// FLOPs of one pass of a stride-aware k×k conv with `c` channels in and out and an
/// `out` × `out` output: `2·B·C_out·H_out·W_out·C_in·k²`.
fn conv_flops(b: usize, c: usize, out: usize, k: usize) -> f64 {
    2.0 * (b * c * out * out * c * k * k) as f64
}

/// Forward + backward of `Σ f(x) ⊙ g` with respect to a seeded input `x` of `shape` (and every
/// parameter `f` holds), `g` a seeded tensor of f's output shape: the per-op cases.
fn gradient_step<'a>(
    shape: (usize, usize, usize, usize),
    seed: u64,
    f: impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a,
) -> anyhow::Result<Step<'a>> {
    let dev = Device::Cpu;
    let x = Var::from_tensor(&pseudo_random(shape, seed ^ 4, DType::F32, &dev)?)?;
    let y = f(&x.as_tensor().detach())?;
    let g = pseudo_random(y.shape(), seed ^ 6, DType::F32, &dev)?;
    Ok(Box::new(move || {
        drop((f(x.as_tensor())? * &g)?.sum_all()?.backward()?);
        Ok(())
    }))
}

fn validate(args: &Args) -> anyhow::Result<()> {
    if args.iters == 0 {
        bail!("--iters must be at least 1");
    }
    if args.batch == 0 {
        bail!("--batch must be at least 1");
    }
    if args.cases.is_empty() {
        bail!("--cases is empty: name at least one case");
    }
    Ok(())
}

/// Warm-up, then timed iterations of `case` on this thread; `tick` after each one.
fn measure(
    case: Case,
    s: &Setup,
    args: &Args,
    tick: &(dyn Fn() + Sync),
) -> anyhow::Result<CaseReport> {
    let (mut run, batch, flops) = step(case, s, args)?;
    for _ in 0..args.warmup {
        run()?;
        tick();
    }
    let mut times = Vec::with_capacity(args.iters);
    for _ in 0..args.iters {
        let start = Instant::now();
        run()?;
        times.push(start.elapsed().as_secs_f64());
        tick();
    }
    let mut sorted = times.clone();
    sorted.sort_by(f64::total_cmp);
    Ok(CaseReport {
        name: case.name(),
        what: case.what(),
        size: args.size,
        batch,
        median_s: sorted[sorted.len() / 2],
        min_s: sorted[0],
        times_s: times,
        flops,
    })
}

/// [`measure`] on a thread of its own (on the candle reference path with
/// `--candle-reference`: the switch is per thread).
fn time_case(
    case: Case,
    s: &Setup,
    args: &Args,
    tick: &(dyn Fn() + Sync),
) -> anyhow::Result<CaseReport> {
    std::thread::scope(|scope| {
        scope
            .spawn(|| {
                if args.candle_reference {
                    with_reference_ops(|| measure(case, s, args, tick))
                } else {
                    measure(case, s, args, tick)
                }
            })
            .join()
            .unwrap_or_else(|_| bail!("the benchmark thread of case {} panicked", case.name()))
    })
    .with_context(|| format!("benchmark case {} failed", case.name()))
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    validate(args)?;
    let setup = Setup::new(args).context("cannot build the benchmark's networks")?;
    let total = (args.cases.len() * (args.iters + args.warmup)) as u64;
    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} iterations {msg}")
            .expect("the template is valid")
            .progress_chars("=> "),
    );
    let mut cases = Vec::with_capacity(args.cases.len());
    for &case in &args.cases {
        bar.set_message(case.name());
        cases.push(time_case(case, &setup, args, &|| bar.inc(1))?);
    }
    bar.finish_and_clear();
    let report = Report {
        implementation: "photomat",
        version: format!("photomat {}", env!("CARGO_PKG_VERSION")),
        threads: photomat_kernels::alloc::thread_count(),
        platform: format!("{} {}", std::env::consts::ARCH, std::env::consts::OS),
        kernels: photomat_kernels::simd::SimdFamily::active().name(),
        size: args.size,
        multiplier: args.multiplier,
        batch: args.batch,
        iters: args.iters,
        warmup: args.warmup,
        reference_ops: args.candle_reference,
        parameters: setup.parameters,
        cases,
    };
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
        return Ok(());
    }
    for c in &report.cases {
        let rate = c
            .flops
            .map(|f| format!("  {:7.1} GFLOP/s", f / c.median_s / 1e9))
            .unwrap_or_default();
        writeln!(
            out,
            "{:<12} median {:.4} s  min {:.4} s{rate}",
            c.name, c.median_s, c.min_s
        )?;
    }
    let p = &report.parameters;
    writeln!(
        out,
        "{}, {} threads; parameters G {} (+{} buffers), M {}, D {}, E {}",
        report.version, report.threads, p.g, p.g_buffers, p.m, p.d, p.e
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_case_runs_and_reports_valid_json() -> anyhow::Result<()> {
        let args = Args {
            size: 32,
            multiplier: 1.0 / 64.0,
            batch: 2,
            iters: 1,
            warmup: 0,
            cases: Case::ALL.to_vec(),
            seed: 3,
            json: true,
            candle_reference: false,
        };
        let mut out = Vec::new();
        run(&args, &mut out)?;
        let report: serde_json::Value = serde_json::from_slice(&out)?;
        let cases = report["cases"].as_array().expect("cases array");
        let names: Vec<&str> = cases.iter().map(|c| c["name"].as_str().unwrap()).collect();
        let expected: Vec<&str> = Case::ALL.iter().map(|c| c.name()).collect();
        assert_eq!(names, expected);
        for c in cases {
            let (median, min) = (
                c["median_s"].as_f64().unwrap(),
                c["min_s"].as_f64().unwrap(),
            );
            assert!(min > 0.0 && min <= median, "{c}");
            assert_eq!(c["times_s"].as_array().unwrap().len(), 1);
        }
        // The networks are the configured ones: E's count is the paper's at n = 8, and M's
        // 35→64×7→3 MLP has 35·64 + 6·64·64 + 64·3 weights and 7·64 + 3 biases.
        assert_eq!(report["parameters"]["e"], 5_674_632);
        assert_eq!(
            report["parameters"]["m"],
            35 * 64 + 6 * 64 * 64 + 64 * 3 + 7 * 64 + 3
        );
        assert_eq!(report["parameters"]["g_buffers"], 512);
        assert_eq!(report["reference_ops"], false);

        // The plain-candle baseline runs the same steps.
        let baseline = Args {
            cases: vec![Case::GStep, Case::EStep],
            candle_reference: true,
            ..args
        };
        let mut out = Vec::new();
        run(&baseline, &mut out)?;
        let report: serde_json::Value = serde_json::from_slice(&out)?;
        assert_eq!(report["reference_ops"], true);
        assert_eq!(report["cases"].as_array().map(Vec::len), Some(2));
        Ok(())
    }

    #[test]
    fn bad_options_are_refused() {
        let mut out = Vec::new();
        let mut args = Args {
            size: 48,
            multiplier: 0.25,
            batch: 1,
            iters: 1,
            warmup: 0,
            cases: vec![Case::Sgemm],
            seed: 1,
            json: true,
            candle_reference: false,
        };
        let err = run(&args, &mut out).expect_err("48 is not a power of two");
        assert!(format!("{err:#}").contains("resolution 48"), "{err:#}");
        args.size = 32;
        args.iters = 0;
        assert!(run(&args, &mut out).is_err());
    }
}
