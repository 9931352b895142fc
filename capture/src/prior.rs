//! The generator prior of a capture: invert the trained relightable generator M∘G to the photo,
//! then decode the neural material it finds with the estimator E (MaterialGAN's approach, Guo
//! et al. 2020, on PhotoMat's networks; docs/capture.md, "Generator prior").
//!
//! A single photo shows each texel under one light, so maps fitted to it directly can explain
//! the highlight with any mix of albedo, specular, roughness and normal. G only produces
//! neural materials like those it was trained on, whose relighting by M behaves like a
//! material under every light; finding the G input whose relighting matches the photo, and
//! reading its maps with E, gives the refinement a starting point that is a material, not a
//! painted highlight.
//!
//! The inversion optimises, with Adam, the spatial G's inputs and a display-domain gain `g`:
//! the per-layer styles `w+` (B = 1, one `w` per layer, started at G's average `w`) and the
//! local latent field (started from a seeded N(0, 1) draw), minimising
//!
//! `L = mean |e^g · (M(G(field, w+), ω) + 1)/2 − photo|`
//!
//! where ω is the photo's per-texel flash direction and `(M + 1)/2` M's output as display
//! values (docs/conventions.md, "Image values"). G's weights, M and E stay frozen. G has no
//! noise inputs in the bundled model; where it has them they are held at zero.
//!
//! Sizes: G's field has one cell per `cell_size` texels and E halves the resolution five
//! times, so a prior capture's side must be a multiple of both ([`GanPrior::size_multiple`]).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor, Var};
use photomat_core::Brdf;
use photomat_estimator::EstimatorModel;
use photomat_estimator::model_choice::{cost_key, load_estimators};
use photomat_generator::{GanModel, NoiseInput};
use photomat_train::{Adam, AdamConfig};

/// A trained model folder's G, M and the estimators E that decode its neural materials: one
/// for a capture in a named model ([`GanPrior::open`]), all of them for a capture that
/// chooses its model ([`GanPrior::open_all`], `--brdf auto`).
pub struct GanPrior {
    dir: String,
    gan: GanModel,
    /// Cheapest first ([`cost_key`]).
    estimators: Vec<EstimatorModel>,
}

/// How the inversion runs.
#[derive(Debug, Clone, PartialEq)]
pub struct PriorOptions {
    /// Adam steps on w+, the field and the gain. Default 100.
    pub steps: usize,
    /// Adam learning rate. Default 0.02: w+ lives on G's mapped scale (entries of order 1),
    /// and the field is N(0, 1), so steps of 0.02 move either by a few % of its spread.
    pub lr: f64,
    /// Seed of the field's starting draw.
    pub seed: u64,
}

impl Default for PriorOptions {
    fn default() -> Self {
        Self {
            steps: 100,
            lr: 0.02,
            seed: 0,
        }
    }
}

/// What an inversion found.
#[derive(Debug, Clone)]
pub struct Inversion {
    /// G's neural material found: (1, F, N, N) features.
    pub features: Tensor,
    /// The fitted display-domain gain `e^g`.
    pub display_gain: f64,
    /// M's relighting of the found material under the photo's flash, with the gain, display
    /// values: (1, 3, N, N).
    pub relit: Tensor,
    /// Loss after every step.
    pub losses: Vec<f64>,
    /// Wall seconds.
    pub seconds: f64,
}

impl GanPrior {
    /// Opens the model folder `dir` (gan.json + gan.safetensors, and estimators) for captures
    /// in `brdf`. `Ok(None)` when no estimator of the folder decodes into `brdf` (canonical
    /// names compared): the caller then fits from constant maps and says so.
    pub fn open(dir: &Path, brdf: &Brdf, device: &Device) -> anyhow::Result<Option<Self>> {
        let mut prior = Self::open_all(dir, device)?;
        let name = brdf.name();
        prior.retain_estimators(|b| b.name() == name);
        Ok((!prior.estimators.is_empty()).then_some(prior))
    }

    /// Keeps only the estimators whose model `keep` accepts (cheapest first still), e.g. a
    /// model family whatever its arguments: `|b| b.name().starts_with("height(ggx")`.
    pub fn retain_estimators(&mut self, keep: impl Fn(&Brdf) -> bool) {
        self.estimators.retain(|e| keep(e.brdf()));
    }

    /// Opens the model folder `dir` with every estimator it holds, cheapest first: what
    /// [`crate::capture_auto`] chooses from.
    pub fn open_all(dir: &Path, device: &Device) -> anyhow::Result<Self> {
        let gan = GanModel::load(dir, device)
            .with_context(|| format!("cannot load the GAN in '{}'", dir.display()))?;
        if !gan.generator().synthesis().is_spatial() {
            bail!(
                "the GAN in '{}' is a fixed-size generator: the prior needs a spatial one \
                 (any size), trained with `photomat train-gan --spatial`",
                dir.display()
            );
        }
        let mut estimators = load_estimators(dir, gan.config().feature_channels, device)?;
        estimators.sort_by_key(cost_key);
        Ok(Self {
            dir: dir.display().to_string(),
            gan,
            estimators,
        })
    }

    /// The model folder, as given.
    pub fn dir(&self) -> &str {
        &self.dir
    }

    /// The estimators, cheapest first.
    pub fn estimators(&self) -> &[EstimatorModel] {
        &self.estimators
    }

    /// E's raw (pre-decoding) maps of the inverted material for `brdf`, (1, C, N, N); `None`
    /// when no estimator of the folder decodes into `brdf`.
    pub fn decode(&self, inversion: &Inversion, brdf: &Brdf) -> anyhow::Result<Option<Tensor>> {
        let name = brdf.name();
        self.estimators
            .iter()
            .find(|e| e.brdf().name() == name)
            .map(|e| Ok(e.estimator().forward(&inversion.features)?.detach()))
            .transpose()
    }

    /// M's relighting of the inverted material under every light of `omega` (L, 3, N, N),
    /// with the inversion's gain, as display values clamped to [0, 1]: (L, 3, N, N). One
    /// light at a time, so memory stays that of one relighting.
    pub fn relight(&self, inversion: &Inversion, omega: &Tensor) -> anyhow::Result<Tensor> {
        let lights = omega.dim(0)?;
        let mut relit = Vec::with_capacity(lights);
        for k in 0..lights {
            let encoded = self
                .gan
                .relight()
                .forward(&inversion.features, &omega.narrow(0, k, 1)?)?;
            relit.push((encoded.affine(0.5, 0.5)? * inversion.display_gain)?.clamp(0f32, 1f32)?);
        }
        Ok(Tensor::cat(&relit, 0)?)
    }

    /// Sides a prior capture may have are multiples of this: G's cell size and the
    /// estimators' total stride, whichever is largest (all are powers of two).
    pub fn size_multiple(&self) -> usize {
        self.estimators
            .iter()
            .map(|e| e.estimator().config().total_stride())
            .fold(self.gan.config().cell_size(), usize::max)
    }

    /// Inverts M∘G to `photo` (1, 3, N, N display values) under the per-texel flash
    /// directions `omega` (1, 3, N, N). `progress(step, loss)` after every step; [`Self::decode`]
    /// reads the found material's maps.
    pub fn invert(
        &self,
        photo: &Tensor,
        omega: &Tensor,
        options: &PriorOptions,
        progress: &mut dyn FnMut(usize, f64),
    ) -> anyhow::Result<Inversion> {
        let (_, _, n, _) = photo.dims4()?;
        let multiple = self.size_multiple();
        if n % multiple != 0 {
            bail!(
                "a capture with the generator prior needs a side that is a multiple of \
                 {multiple} (G's cell size and E's stride), got {n}; choose --size {} or {}, \
                 or fit from constant maps (without --prior and --model)",
                (n / multiple).max(1) * multiple,
                (n / multiple + 1) * multiple
            );
        }
        let generator = self.gan.generator();
        let synthesis = generator.synthesis();
        let num_ws = synthesis.num_ws();
        let w_avg = generator.mapping().w_avg().detach();
        let w_dim = w_avg.dim(0)?;
        let ws = Var::from_tensor(&w_avg.reshape((1, 1, w_dim))?.repeat((1, num_ws, 1))?)?;
        let field = Var::from_tensor(&self.gan.local_fields(&[options.seed], n)?)?;
        let log_gain = Var::zeros(1, DType::F32, photo.device())?;
        let mut adam = Adam::new(
            vec![
                ("ws".into(), ws.clone()),
                ("field".into(), field.clone()),
                ("log_gain".into(), log_gain.clone()),
            ],
            AdamConfig::kingma(options.lr),
        )?;
        let relight = |ws: &Tensor, field: &Tensor, log_gain: &Tensor| -> anyhow::Result<_> {
            let features = synthesis.forward_field(field, ws, &NoiseInput::Zero)?;
            let encoded = self.gan.relight().forward(&features, omega)?;
            // (M + 1)/2 unclamped: a clamp would stop the gradient of every saturated texel.
            let display = encoded.affine(0.5, 0.5)?.broadcast_mul(&log_gain.exp()?)?;
            Ok((features, display))
        };
        let start = Instant::now();
        let mut losses = Vec::with_capacity(options.steps);
        for step in 0..options.steps {
            let (_, display) = relight(ws.as_tensor(), field.as_tensor(), log_gain.as_tensor())?;
            let loss = (display - photo)?.abs()?.mean_all()?;
            let value = loss.to_scalar::<f32>()? as f64;
            if !value.is_finite() {
                bail!("the inversion diverged at step {} (loss {value})", step + 1);
            }
            adam.step(&loss.backward()?)?;
            losses.push(value);
            progress(step + 1, value);
        }
        let (features, display) = relight(ws.as_tensor(), field.as_tensor(), log_gain.as_tensor())?;
        let display_gain = log_gain.as_tensor().exp()?.to_vec1::<f32>()?[0] as f64;
        Ok(Inversion {
            features: features.detach(),
            display_gain,
            relit: display.clamp(0f32, 1f32)?.detach(),
            losses,
            seconds: start.elapsed().as_secs_f64(),
        })
    }
}
