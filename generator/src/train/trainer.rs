//! One GAN training step of PhotoMat (paper §3–4) in the order of StyleGAN2-ADA's training loop
//! (`training_loop.py` phases Gmain, Dmain, Dreg; `loss.py` `StyleGAN2Loss`):
//!
//! 1. **G step** — latents z (with style mixing, probability 0.9, one cut-off per batch drawn
//!    in 1 … num_ws − 1), seeded noise, G → F; in tileable mode F is rolled per sample
//!    ([`photomat_train::roll`]); lights drawn like the real crops' ([`TrainingData`]) give
//!    ω; M(F, ω) → image; loss `softplus(−D(image, ω))`; Adam on G and M. The tracked `w_avg`
//!    moves towards the batch's mean w.
//!    A spatial G (training on patches, [`TrainConfig::patches`]) makes each fake at
//!    R + margin cells from its own local latent field and D sees a random R×R window of it
//!    (the roll, then the top-left window).
//!    Every `g_reg_interval` steps, when `pl_weight` > 0, a path-length step on half a batch
//!    ([`super::path_length`]), a second Adam update of G and M.
//! 2. **D step** — fresh latents, noise and lights, fakes without G's graph; real crops with
//!    their ω; loss `softplus(D(fake)) + softplus(−D(real))`, plus `light_mismatch` ×
//!    `softplus(D(real, ω_fake))` (the reals under the fakes' independently drawn lights: a
//!    matching-aware D, [`super::loss`]); Adam on D.
//! 3. **R1 step** every `r1_interval` steps — `mean ‖∇ₓD(x_real, ω)‖² · γ/2 · interval`; Adam
//!    on D (a second D update that step, as in the reference).
//! 4. **EMA** of G into G_ema ([`super::ema`]). The reference keeps an EMA of G only, so M
//!    is shared by G and G_ema: the inference model pairs G_ema with the trained M (whose lr
//!    multiplier of 0.01 already makes it move slowly).
//!
//! Any phase whose loss or gradient is not finite is skipped ([`photomat_train::nan_guard`]).
//!
//! Every random draw comes from a seed of (run seed, step, purpose) ([`super::streams`]):
//! latents via [`GanModel::latents`], noise via [`GanModel::noise_images`] (local fields via
//! [`GanModel::local_fields`]) (fed as
//! [`NoiseInput::Given`]), crops and lights via [`TrainingData`], rolls and mixing via
//! SplitMix64. With the same seed two runs produce identical weights on the CPU, and a run
//! resumed from [`Trainer::save_state`] continues exactly as the uninterrupted one.
//!
//! The R1 and path-length penalties are double backwards: their inner pass keeps the graph of
//! its gradients (`backward_keeping_graph`, `docs/candle-notes.md`, "Second-order
//! gradients"); every other backward pass detaches them, which keeps a D step 5 % faster.

use std::path::Path;
use std::time::Instant;

use candle_core::{DType, Device, Result, Tensor, Var};
use candle_nn::VarMap;
use photomat_core::rng::SplitMix64;
use photomat_train::varmap::{frozen_var_builder, insert_renamed, insert_var};
use photomat_train::{
    Adam, NanGuard, gradients_finite, roll_offsets, roll_per_sample, window_per_sample,
};

use super::config::TrainConfig;
use super::data::{RealBatch, TrainingData, omega_for_placements};
use super::ema::{Ema, ema_beta};
use super::loss::{discriminator_loss, generator_loss, r1_loss};
use super::path_length::{PL_BATCH_SHRINK, PathLengthMean, path_lengths, pl_loss, pl_noise};
use super::state::{Restored, load_state, save_state};
use super::streams::{Stream, stream_seed, stream_seeds};
use crate::model_files::G_PREFIX;
use crate::{Discriminator, GanModel, NoiseInput, is_buffer, mix_styles, seeded_var_builder};

/// What one step measured.
#[derive(Debug, Clone, PartialEq)]
pub struct StepStats {
    /// Index of the step (0-based: steps done before it; `log.csv` and messages number it
    /// `step + 1`).
    pub step: u64,
    /// G's loss.
    pub loss_g: f64,
    /// D's logistic loss (without R1).
    pub loss_d: f64,
    /// Mean D logit on the real crops.
    pub real_logit: f64,
    /// Mean D logit on the fakes of D's step.
    pub fake_logit: f64,
    /// Mean D logit on the reals under the fakes' (mismatched) lights, when the
    /// light-mismatch term is on: `real_logit − mismatch_logit` is how much D relies on ω.
    pub mismatch_logit: Option<f64>,
    /// Mean R1 penalty ‖∇ₓD‖² on the reals, on R1 steps.
    pub r1: Option<f64>,
    /// Mean path length of the path-length step, when it ran.
    pub path_length: Option<f64>,
    /// Phases skipped because of non-finite values, e.g. `D loss is NaN`.
    pub skipped: Vec<String>,
    /// Wall-clock seconds per phase.
    pub seconds: PhaseSeconds,
}

/// Wall-clock seconds of a step's phases (where a step's time goes).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseSeconds {
    /// G step: generation, D forward, backward, Adam; and the path-length step.
    pub g: f64,
    /// D step without the real crops' loading: generation, D forward on both, backward, Adam.
    pub d: f64,
    /// Loading the real crops.
    pub data: f64,
    /// R1 step (0 on other steps).
    pub r1: f64,
    /// EMA update.
    pub ema: f64,
}

/// Which phase's random streams a generation uses.
#[derive(Debug, Clone, Copy)]
enum Phase {
    G,
    D,
    PathLength,
}

impl Phase {
    /// (latent, mixing latent, noise, mixing decision, roll, lights, local field) streams.
    fn streams(self) -> [Stream; 7] {
        match self {
            Phase::G => [
                Stream::GLatent,
                Stream::GMixLatent,
                Stream::GNoise,
                Stream::GMixing,
                Stream::GRoll,
                Stream::GLights,
                Stream::GField,
            ],
            Phase::D => [
                Stream::DLatent,
                Stream::DMixLatent,
                Stream::DNoise,
                Stream::DMixing,
                Stream::DRoll,
                Stream::DLights,
                Stream::DField,
            ],
            Phase::PathLength => [
                Stream::PlLatent,
                Stream::PlMixLatent,
                Stream::PlNoise,
                Stream::PlMixing,
                Stream::PlRoll,
                Stream::PlLights,
                Stream::PlField,
            ],
        }
    }
}

/// Generated images of a phase.
struct Fakes {
    /// (B, 3, R, R) encoded images.
    images: Tensor,
    /// (B, 3, R, R) their ω.
    omega: Tensor,
    /// (B, latent_dim) the unmixed w (for the `w_avg` update).
    w: Tensor,
}

/// G, M, D, G_ema, their optimisers and the step counter of a training run.
pub struct Trainer {
    config: TrainConfig,
    device: Device,
    /// Training G (`g.*`) and M (`m.*`).
    model: GanModel,
    /// G_ema (`g.*`) and the shared M (`m.*`).
    ema_model: GanModel,
    ema: Ema,
    d_vars: VarMap,
    d: Discriminator,
    opt_g: Adam,
    opt_d: Adam,
    guard: NanGuard,
    /// Running mean path length, when path-length regularisation is on.
    pl_mean: Option<PathLengthMean>,
    step: u64,
    counters: Var,
    state: VarMap,
}

/// D of `config`'s architecture initialised from the run seed ([`seeded_var_builder`]), the
/// variables that hold its weights, and its Adam with the run's D settings (moments zero):
/// what a fresh run trains ([`Trainer::new`]), and where the probes that train D alone start
/// (the data crate's `d_capacity` and `d_relief` examples).
pub fn fresh_discriminator(
    config: &TrainConfig,
    device: &Device,
) -> Result<(VarMap, Discriminator, Adam)> {
    let vars = VarMap::new();
    let d = Discriminator::new(
        &config.generator,
        seeded_var_builder(&vars, config.seed, DType::F32, device),
    )?;
    let adam = Adam::for_varmap(&vars, |name| !is_buffer(name), config.adam_d())?;
    Ok((vars, d, adam))
}

impl Trainer {
    /// A fresh run: G, M and D initialised from the run seed ([`seeded_var_builder`]),
    /// G_ema a copy of G, moments zero, step 0.
    pub fn new(config: TrainConfig, device: &Device) -> Result<Self> {
        config.validate()?;
        let cfg = &config.generator;
        let model = GanModel::new(cfg, config.seed, device)?;
        // G_ema: a copy of G's variables; M's variables are shared.
        let ema_vars = VarMap::new();
        {
            let src = model.vars().data().lock().expect("VarMap lock poisoned");
            let mut dst = ema_vars.data().lock().expect("VarMap lock poisoned");
            for (name, var) in src.iter() {
                let v = if name.starts_with(&format!("{G_PREFIX}.")) {
                    Var::from_tensor(&var.as_tensor().copy()?)?
                } else {
                    var.clone()
                };
                dst.insert(name.clone(), v);
            }
        }
        let ema_model = GanModel::from_vars(cfg, ema_vars, device)?;
        let ema = Ema::new(ema_model.vars(), model.vars(), &format!("{G_PREFIX}."))?;
        let (d_vars, d, opt_d) = fresh_discriminator(&config, device)?;
        let opt_g = Adam::for_varmap(model.vars(), |name| !is_buffer(name), config.adam_g())?;
        let counters = Var::zeros(2, DType::F64, device)?;
        let state = VarMap::new();
        insert_renamed(&state, model.vars(), "", "");
        insert_renamed(&state, ema_model.vars(), &format!("{G_PREFIX}."), "g_ema.");
        insert_renamed(&state, &d_vars, "", "d.");
        insert_renamed(&state, opt_g.state(), "", "opt_g.");
        insert_renamed(&state, opt_d.state(), "", "opt_d.");
        insert_var(&state, "trainer.counters", &counters);
        // Only runs with the regulariser have its state (older state files load unchanged).
        let pl_mean = if config.pl_weight > 0.0 {
            let m = PathLengthMean::new(device)?;
            insert_var(&state, "trainer.pl_mean", m.var());
            Some(m)
        } else {
            None
        };
        Ok(Self {
            guard: NanGuard::new(config.nan_limit, DIVERGED_ADVICE),
            pl_mean,
            config,
            device: device.clone(),
            model,
            ema_model,
            ema,
            d_vars,
            d,
            opt_g,
            opt_d,
            step: 0,
            counters,
            state,
        })
    }

    /// The run's configuration.
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// Steps done (the index of the next step).
    pub fn steps_done(&self) -> u64 {
        self.step
    }

    /// Real images shown to D so far (steps × batch).
    pub fn images_seen(&self) -> u64 {
        self.step * self.config.batch as u64
    }

    /// The training G and M.
    pub fn model(&self) -> &GanModel {
        &self.model
    }

    /// G_ema with M: what the run folder's inference model holds.
    pub fn ema_model(&self) -> &GanModel {
        &self.ema_model
    }

    /// D.
    pub fn discriminator(&self) -> &Discriminator {
        &self.d
    }

    /// D's variables.
    pub fn discriminator_vars(&self) -> &VarMap {
        &self.d_vars
    }

    /// Everything [`Trainer::save_state`] writes, by name (module [`super::state`]).
    pub fn state_vars(&self) -> &VarMap {
        &self.state
    }

    /// Why the current state should not be checkpointed, if it should not: the last step
    /// skipped an update (the run may be diverging; the previous checkpoint is the last good
    /// one), or a variable of the state holds a non-finite value.
    pub fn unsound_state(&self) -> Result<Option<String>> {
        if self.guard.streak() > 0 {
            return Ok(Some(format!(
                "the last {} step(s) skipped an update",
                self.guard.streak()
            )));
        }
        let data = self.state.data().lock().expect("VarMap lock poisoned");
        let mut names: Vec<&String> = data.keys().collect();
        names.sort();
        for name in names {
            let t = data[name].as_tensor();
            // Finite values have |v| < ∞ and NaN fails every comparison, so the indicator's
            // sum counts the finite entries (in f64: exact for any tensor size here).
            let finite = t
                .abs()?
                .lt(f64::INFINITY)?
                .to_dtype(DType::F64)?
                .sum_all()?
                .to_scalar::<f64>()?;
            if (finite as usize) < t.elem_count() {
                return Ok(Some(format!("`{name}` holds non-finite values")));
            }
        }
        Ok(None)
    }

    /// Writes `train_state.safetensors` and `train.json` into the run folder `dir`.
    pub fn save_state(&self, dir: &Path) -> Result<()> {
        self.counters.set(&Tensor::new(
            &[self.step as f64, self.guard.streak() as f64],
            &self.device,
        )?)?;
        save_state(dir, &self.state, &self.config)
    }

    /// Restores a run folder written by [`Trainer::save_state`] (or
    /// [`super::state::write_without_optimiser`]) for this configuration.
    pub fn load_state(&mut self, dir: &Path) -> Result<Restored> {
        let restored = load_state(dir, &self.state, &self.config)?;
        let c = self.counters.as_tensor().to_vec1::<f64>()?;
        self.step = c[0] as u64;
        self.guard.set_streak(c[1] as usize);
        Ok(restored)
    }

    /// Writes the inference model (G_ema + M, [`GanModel::save`]) into `dir`.
    pub fn save_model(&self, dir: &Path, provenance: serde_json::Value) -> Result<()> {
        self.ema_model.save(dir, provenance)
    }

    /// Fakes of `phase` at `step` from the training G and M.
    fn generate(
        &self,
        phase: Phase,
        step: u64,
        b: usize,
        ws_offset: Option<&Tensor>,
        data: &dyn TrainingData,
    ) -> Result<Fakes> {
        let [latent, mix_latent, noise, mixing, roll, lights, field] = phase.streams();
        let cfg = &self.config.generator;
        let seed = self.config.seed;
        let g = self.model.generator();
        let z = self.model.latents(&stream_seeds(seed, step, latent, b))?;
        let w = g.mapping().forward(&z)?;
        let n = cfg.num_ws();
        let mut ws = w
            .unsqueeze(1)?
            .broadcast_as((b, n, cfg.latent_dim))?
            .contiguous()?;
        let mut rng = SplitMix64(stream_seed(seed, step, mixing, 0));
        if n > 1 && rng.next_unit() < self.config.style_mixing_prob {
            // Uniform in 1 … n − 1 (next_unit() < 1; the min only guards float rounding).
            let cutoff = 1 + ((rng.next_unit() * (n - 1) as f64) as usize).min(n - 2);
            let z2 = self
                .model
                .latents(&stream_seeds(seed, step, mix_latent, b))?;
            ws = mix_styles(&ws, &g.mapping().ws(&z2, 1.0, n)?, cutoff)?;
        }
        if let Some(u) = ws_offset {
            ws = (ws + u)?;
        }
        // Whether F is one whole period of a material (a rolled tileable sample) or a window of
        // a larger field / a non-periodic image: the relief's differences wrap only in the first.
        let (features, whole_period) = match &self.config.patches {
            None => {
                let noise_images = self
                    .model
                    .noise_images(&stream_seeds(seed, step, noise, b))?;
                let features = g
                    .synthesis()
                    .forward(&ws, &NoiseInput::Given(&noise_images))?;
                if cfg.tileable {
                    let offsets = roll_offsets(&stream_seeds(seed, step, roll, b), cfg.resolution);
                    (roll_per_sample(&features, &offsets)?, true)
                } else {
                    (features, false)
                }
            }
            Some(patches) => {
                // A periodic sample of R + margin cells; the roll then the top-left R×R window
                // is a uniformly placed window of its periodic extension.
                let side = cfg.resolution + patches.margin_cells * cfg.cell_size();
                let noise_images = self
                    .model
                    .noise_images_at(&stream_seeds(seed, step, noise, b), side)?;
                let fields = self
                    .model
                    .local_fields(&stream_seeds(seed, step, field, b), side)?;
                let features =
                    g.synthesis()
                        .forward_field(&fields, &ws, &NoiseInput::Given(&noise_images))?;
                let offsets = roll_offsets(&stream_seeds(seed, step, roll, b), side);
                (
                    window_per_sample(&features, &offsets, (cfg.resolution, cfg.resolution))?,
                    false,
                )
            }
        };
        let placements = data.fake_lights(b, stream_seed(seed, step, lights, 0))?;
        let omega = omega_for_placements(&placements, cfg.resolution, &self.device)?;
        let images = if whole_period {
            self.model.relight().forward(&features, &omega)?
        } else {
            self.model.relight().forward_window(&features, &omega)?
        };
        Ok(Fakes { images, omega, w })
    }

    /// D with the current weights as constant tensors (sharing the variables' storage, so
    /// building it copies no weights).
    fn frozen_discriminator(&self) -> Result<Discriminator> {
        let vb = frozen_var_builder(&self.d_vars, DType::F32, &self.device);
        Discriminator::new(&self.config.generator, vb)
    }

    /// Runs one training step (module docs) on `data`. Errors: data or numerical failures,
    /// and [`NanGuard`]'s stop after `nan_limit` consecutive skipped steps.
    pub fn step(&mut self, data: &dyn TrainingData) -> Result<StepStats> {
        let step = self.step;
        let (seed, b) = (self.config.seed, self.config.batch);
        let mut seconds = PhaseSeconds::default();
        let mut clock = Instant::now();
        let mut lap = || {
            let t = clock.elapsed().as_secs_f64();
            clock = Instant::now();
            t
        };

        let loss_g = self.generator_phase(step, data)?;
        // The running mean is a variable: its clone shares it.
        let path_length = match self.pl_mean.clone() {
            Some(mean) if step.is_multiple_of(self.config.g_reg_interval as u64) => {
                Some(self.path_length_phase(step, data, &mean)?)
            }
            _ => None,
        };
        seconds.g = lap();
        let reals = data.reals(b, stream_seed(seed, step, Stream::Crops, 0), &self.device)?;
        seconds.data = lap();
        let d = self.discriminator_phase(step, data, &reals)?;
        seconds.d = lap();
        let r1 =
            if step.is_multiple_of(self.config.r1_interval as u64) && self.config.r1_gamma > 0.0 {
                Some(self.r1_phase(&reals)?)
            } else {
                None
            };
        seconds.r1 = lap();
        // Phase 4, G_ema.
        let beta = ema_beta(
            b,
            self.config.ema_kimg,
            self.config.ema_rampup,
            self.images_seen(),
        );
        self.ema.update(beta)?;
        seconds.ema = lap();

        let skipped = self.guard.end_step(step + 1)?;
        self.step += 1;
        Ok(StepStats {
            step,
            loss_g,
            loss_d: d.loss,
            real_logit: d.real_logit,
            fake_logit: d.fake_logit,
            mismatch_logit: d.mismatch_logit,
            r1,
            path_length,
            skipped,
            seconds,
        })
    }

    /// Phase 1, G and M, judged by D with its weights as constants: this phase steps G and M only,
    /// so D's weight gradients would be thrown away (StyleGAN2-ADA freezes D here too); D's
    /// convolutions then compute input gradients alone. Returns G's loss.
    fn generator_phase(&mut self, step: u64, data: &dyn TrainingData) -> Result<f64> {
        let fakes = self.generate(Phase::G, step, self.config.batch, None, data)?;
        let logits = self
            .frozen_discriminator()?
            .forward(&fakes.images, &fakes.omega)?;
        let loss = generator_loss(&logits)?;
        let loss_g = scalar(&loss)?;
        let grads = loss.backward()?;
        let finite = gradients_finite(&grads, self.opt_g.vars().map(|(_, v)| v))?;
        if self.guard.allow("G", loss_g, finite) {
            self.opt_g.step(&grads)?;
            self.model.generator().mapping().update_w_avg(&fakes.w)?;
        }
        Ok(loss_g)
    }

    /// Phase 1b, lazy path-length regularisation of G (a run with a path-length weight). Returns
    /// the batch's mean path length.
    fn path_length_phase(
        &mut self,
        step: u64,
        data: &dyn TrainingData,
        mean: &PathLengthMean,
    ) -> Result<f64> {
        let pb = (self.config.batch / PL_BATCH_SHRINK).max(1);
        // candle keeps gradients only for variables: the lengths are taken with respect to a
        // zero variable added to ws (the same derivative), so that the penalty still reaches
        // the mapping network through ws, as in the reference.
        let cfg = &self.config.generator;
        let offset = Var::zeros((pb, cfg.num_ws(), cfg.latent_dim), DType::F32, &self.device)?;
        let fakes = self.generate(Phase::PathLength, step, pb, Some(offset.as_tensor()), data)?;
        let noise = pl_noise(
            fakes.images.dims4()?,
            stream_seed(self.config.seed, step, Stream::PlImageNoise, 0),
            &self.device,
        )?;
        let lengths = path_lengths(&fakes.images, offset.as_tensor(), &noise)?;
        let batch_mean = scalar(&lengths.mean_all()?)?;
        let target = if batch_mean.is_finite() {
            mean.update(batch_mean)?
        } else {
            mean.value()?
        };
        let loss = pl_loss(
            &lengths,
            target,
            self.config.pl_weight,
            self.config.g_reg_interval,
        )?;
        let value = scalar(&loss)?;
        let grads = loss.backward()?;
        let finite = gradients_finite(&grads, self.opt_g.vars().map(|(_, v)| v))?;
        if self.guard.allow("PL", value, finite) {
            self.opt_g.step(&grads)?;
        }
        Ok(batch_mean)
    }

    /// Phase 2, D on fresh fakes and on `reals`, with the light-mismatch term when weighted.
    fn discriminator_phase(
        &mut self,
        step: u64,
        data: &dyn TrainingData,
        reals: &RealBatch,
    ) -> Result<DiscriminatorPhase> {
        let fakes = self.generate(Phase::D, step, self.config.batch, None, data)?;
        let fake_logits = self.d.forward(&fakes.images.detach(), &fakes.omega)?;
        let real_logits = self.d.forward(&reals.images, &reals.omega)?;
        // The fakes' lights were drawn independently of the reals': for the reals they are
        // mismatched lights from the same distribution (loss module docs).
        let weight = self.config.light_mismatch;
        let mismatch_logits = if weight > 0.0 {
            Some(self.d.forward(&reals.images, &fakes.omega)?)
        } else {
            None
        };
        let loss = discriminator_loss(
            &real_logits,
            &fake_logits,
            mismatch_logits.as_ref().map(|l| (l, weight)),
        )?;
        let loss_d = scalar(&loss)?;
        let grads = loss.backward()?;
        let finite = gradients_finite(&grads, self.opt_d.vars().map(|(_, v)| v))?;
        if self.guard.allow("D", loss_d, finite) {
            self.opt_d.step(&grads)?;
        }
        Ok(DiscriminatorPhase {
            loss: loss_d,
            real_logit: scalar(&real_logits.mean_all()?)?,
            fake_logit: scalar(&fake_logits.mean_all()?)?,
            mismatch_logit: mismatch_logits
                .map(|l| scalar(&l.mean_all()?))
                .transpose()?,
        })
    }

    /// Phase 3, lazy R1 on the same reals. Returns the mean penalty.
    fn r1_phase(&mut self, reals: &RealBatch) -> Result<f64> {
        let penalty = self.d.r1_penalty(&reals.images, &reals.omega)?;
        let loss = r1_loss(&penalty, self.config.r1_gamma, self.config.r1_interval)?;
        let value = scalar(&loss)?;
        let grads = loss.backward()?;
        let finite = gradients_finite(&grads, self.opt_d.vars().map(|(_, v)| v))?;
        if self.guard.allow("R1", value, finite) {
            self.opt_d.step(&grads)?;
        }
        scalar(&penalty.mean_all()?)
    }
}

/// What D's phase of a step measured.
struct DiscriminatorPhase {
    loss: f64,
    /// Mean logits on the reals, the fakes and the reals under the fakes' lights.
    real_logit: f64,
    fake_logit: f64,
    mismatch_logit: Option<f64>,
}

/// How the error of a diverged run ends (after the step and the non-finite losses).
const DIVERGED_ADVICE: &str =
    "the run has diverged — resume from the last checkpoint with a lower --lr";

/// A scalar tensor's value as f64.
fn scalar(t: &Tensor) -> Result<f64> {
    t.to_dtype(DType::F64)?.to_scalar::<f64>()
}
