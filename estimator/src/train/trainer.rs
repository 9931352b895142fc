//! One estimator training run (PhotoMat §3 "Material map estimator", §4; `docs/neural-models.md`,
//! "Training E"): E learns to decode the frozen generator's neural materials into a BRDF plugin's
//! maps, step by step, with checkpoints that resume bit-identically.
//!
//! Each step draws its batch from the run seed and the step index ([`StepDraws`]): materials
//! (z and noise of G_ema per material seed, [`GanModel::features_for_seeds`]), one flash per
//! material, rolls for the fine-tune. The loss is the [`Objective`] of the step's [`Stage`];
//! Adam (`photomat_train::adam`, PyTorch's update) optimises E's parameters only.
//! The fine-tune starts with a fresh optimiser at its own learning rate (moments reset), as
//! the reference's fine-tune is a new optimisation from the stage-1 weights. A step whose loss
//! is not finite is skipped ([`NanGuard`], shared with the GAN trainer).

use std::path::Path;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::VarMap;
use photomat_core::checkpoint::{load_vars_checked, save_vars_atomic};
use photomat_core::{Error, Highlight, MaterialMaps, Result};
use photomat_generator::GanModel;
use photomat_train::varmap::{insert_renamed, insert_var};
use photomat_train::{Adam, AdamConfig, NanGuard};

use super::config::{Stage, TrainConfig};
use super::draws::StepDraws;
use super::objective::Objective;
use super::state::{TRAIN_STATE_FILE, TrainManifest};
use crate::EstimatorModel;
use crate::loss::{FeatureExtractor, load_vgg19, random_features};

/// Outcome of one step.
#[derive(Debug, Clone, PartialEq)]
pub struct StepReport {
    /// Steps done after this one (1 for the first step).
    pub step: u64,
    /// The stage the step belonged to.
    pub stage: Stage,
    /// Unweighted L1 term.
    pub l1: f64,
    /// Unweighted Gram term.
    pub gram: f64,
    /// Weighted total.
    pub total: f64,
    /// True when the loss was not finite and no update was made.
    pub skipped: bool,
}

/// A relighting of one material for inspection (training panels).
#[derive(Debug, Clone)]
pub struct Preview {
    /// M's image, display-encoded in [0, 1]: (1, 3, R, R).
    pub neural: Tensor,
    /// The analytic render of E's maps, display-encoded in [0, 1]: (1, 3, R, R).
    pub analytic: Tensor,
    /// E's decoded maps, batch 1.
    pub maps: MaterialMaps,
}

/// An estimator training run in memory.
pub struct EstimatorTrainer {
    gan: GanModel,
    model: EstimatorModel,
    extractor: Box<dyn FeatureExtractor>,
    config: TrainConfig,
    adam: Adam,
    adam_stage: Stage,
    steps_done: u64,
    guard: NanGuard,
}

impl EstimatorTrainer {
    /// A run training `model` against the frozen `gan` with `config`; the Gram features are
    /// VGG19 from `config.vgg19` or the seeded random bank.
    pub fn new(gan: GanModel, model: EstimatorModel, config: TrainConfig) -> Result<Self> {
        let device = gan.device().clone();
        let extractor: Box<dyn FeatureExtractor> = match &config.vgg19 {
            Some(path) => Box::new(load_vgg19(path, DType::F32, &device)?),
            None => Box::new(random_features(config.feature_seed, DType::F32, &device)?),
        };
        Self::with_extractor(gan, model, config, extractor)
    }

    /// [`EstimatorTrainer::new`] with a given feature extractor.
    pub fn with_extractor(
        gan: GanModel,
        model: EstimatorModel,
        config: TrainConfig,
        extractor: Box<dyn FeatureExtractor>,
    ) -> Result<Self> {
        let resolution = gan.config().resolution;
        config.validate(resolution)?;
        let arch = model.estimator().config();
        let stride = arch.total_stride();
        if !resolution.is_multiple_of(stride) {
            return Err(Error::Invalid(format!(
                "the GAN's resolution {resolution} is not divisible by the estimator's total \
                 stride {stride} ({} levels): use a GAN of a multiple of {stride} texels or an \
                 estimator with fewer levels",
                arch.encoder_channels.len()
            )));
        }
        gan.config().world_side(resolution)?;
        let features = gan.config().feature_channels;
        if arch.in_channels != features {
            return Err(Error::Invalid(format!(
                "the estimator takes {} feature channels but the GAN's neural materials have \
                 {features}",
                arch.in_channels
            )));
        }
        let stage = config.stage_at(0);
        let adam = new_adam(&model, &config, stage)?;
        let guard = NanGuard::new(config.max_nan_steps as usize, DIVERGED_ADVICE);
        Ok(Self {
            gan,
            model,
            extractor,
            config,
            adam,
            adam_stage: stage,
            steps_done: 0,
            guard,
        })
    }

    /// Runs one training step (the next one); an error when every step is done.
    pub fn step(&mut self) -> Result<StepReport> {
        let index = self.steps_done;
        if self.is_done() {
            return Err(Error::Invalid(format!(
                "training is complete: {index} of {} steps done",
                self.config.total_steps()
            )));
        }
        let stage = self.config.stage_at(index);
        if stage != self.adam_stage {
            self.adam = new_adam(&self.model, &self.config, stage)?;
            self.adam_stage = stage;
        }
        let resolution = self.gan.config().resolution;
        let draws = StepDraws::new(self.config.seed, index, self.config.batch, resolution);
        let features = self
            .gan
            .features_for_seeds(&draws.material_seeds, self.config.psi)?;
        let terms = self
            .objective()
            .loss(self.model.estimator(), &features, &draws, stage)?;
        let value = |t: &Tensor| -> Result<f64> { Ok(t.to_dtype(DType::F64)?.to_scalar()?) };
        let (l1, gram, total) = (value(&terms.l1)?, value(&terms.gram)?, value(&terms.total)?);
        let apply = self
            .guard
            .allow_terms(&[("L1", l1), ("Gram", gram), ("total", total)]);
        self.guard.end_step(index + 1)?;
        if apply {
            self.adam.step(&terms.total.backward()?)?;
        }
        self.steps_done += 1;
        Ok(StepReport {
            step: self.steps_done,
            stage,
            l1,
            gram,
            total,
            skipped: !apply,
        })
    }

    fn objective(&self) -> Objective<'_> {
        Objective {
            brdf: self.model.brdf().as_ref(),
            relight: self.gan.relight(),
            extractor: self.extractor.as_ref(),
            config: &self.config,
            side: self.material_side(),
            texel_size: self.gan.config().map_texel_size(),
        }
    }

    /// World side of the GAN's R×R materials (1 for a fixed-size GAN, R × texel size for a
    /// spatial one; [`Self::with_extractor`] checked that it is known).
    fn material_side(&self) -> f64 {
        let config = self.gan.config();
        config
            .world_side(config.resolution)
            .unwrap_or(photomat_core::flash::PLANE_SIDE)
    }

    /// True once both stages are done.
    pub fn is_done(&self) -> bool {
        self.steps_done >= self.config.total_steps()
    }

    /// Steps done so far.
    pub fn steps_done(&self) -> u64 {
        self.steps_done
    }

    /// The stage of the next step.
    pub fn stage(&self) -> Stage {
        self.config.stage_at(self.steps_done)
    }

    /// The settings.
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// The estimator being trained.
    pub fn model(&self) -> &EstimatorModel {
        &self.model
    }

    /// The frozen GAN.
    pub fn gan(&self) -> &GanModel {
        &self.gan
    }

    /// The Gram loss's feature extractor.
    pub fn extractor(&self) -> &dyn FeatureExtractor {
        self.extractor.as_ref()
    }

    /// The optimiser of the current stage.
    pub fn adam(&self) -> &Adam {
        &self.adam
    }

    /// M's relighting and the analytic render of E's maps for the material of `material_seed`
    /// under `highlight` (plane coordinates of the unit square, scaled to the material's
    /// world side).
    pub fn preview(&self, material_seed: u64, highlight: Highlight) -> Result<Preview> {
        let features = self
            .gan
            .features_for_seeds(&[material_seed], self.config.psi)?
            .detach();
        let maps = self
            .model
            .estimate(&features)?
            .with_texel_size(self.gan.config().map_texel_size());
        let (_, _, r, _) = features.dims4()?;
        let side = self.material_side();
        let light = highlight.scaled(side);
        let (target, analytic) = self.objective().images(&features, &maps, &[light], r)?;
        Ok(Preview {
            neural: target.affine(0.5, 0.5)?,
            analytic,
            maps,
        })
    }

    /// Provenance recorded in the estimator's manifest.
    pub fn provenance(&self, gan_dir: &Path) -> serde_json::Value {
        serde_json::json!({
            "trainer": "photomat train-estimator",
            "gan": gan_dir.display().to_string(),
            "steps_done": self.steps_done,
            "stage": self.stage().name(),
            "feature_extractor": self.extractor.describe(),
            "config": self.config,
        })
    }

    /// Writes the resumable state, E's model files and `train.json` into `dir` (see
    /// [`super::state`]), each atomically, the training state first.
    pub fn save_checkpoint(&self, dir: &Path, gan_dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::file(dir, format!("cannot create: {e}")))?;
        let step = Var::from_tensor(&Tensor::new(&[self.steps_done as f64], &Device::Cpu)?)?;
        let stage = Var::from_tensor(&Tensor::new(&[stage_code(self.adam_stage)], &Device::Cpu)?)?;
        save_vars_atomic(&self.state_map(step, stage), &dir.join(TRAIN_STATE_FILE))?;
        self.model.save(dir, self.provenance(gan_dir))?;
        TrainManifest {
            brdf: self.model.brdf().name(),
            architecture: self.model.estimator().config().clone(),
            config: self.config.clone(),
            gan: gan_dir.to_path_buf(),
            step: self.steps_done,
        }
        .save(dir)
    }

    /// Restores the state saved by [`EstimatorTrainer::save_checkpoint`] in `dir`: E's
    /// weights, the optimiser (moments and step count) and the step counter. The file must
    /// come from the same architecture; the error names the mismatching tensor.
    pub fn load_checkpoint(&mut self, dir: &Path) -> Result<()> {
        let path = dir.join(TRAIN_STATE_FILE);
        // The optimiser of the stage the checkpoint's moments belong to: read the stage first.
        let stored_stage = read_scalar(&path, "train.adam_stage")?;
        let stage = match stored_stage as u8 {
            0 => Stage::Aligned,
            1 => Stage::Finetune,
            other => {
                return Err(Error::file(
                    &path,
                    format!("train.adam_stage is {other}, expected 0 or 1"),
                ));
            }
        };
        let adam = new_adam(&self.model, &self.config, stage)?;
        let previous = std::mem::replace(&mut self.adam, adam);
        let step_var = Var::zeros(1, DType::F64, &Device::Cpu)?;
        let stage_var = Var::zeros(1, DType::F64, &Device::Cpu)?;
        let map = self.state_map(step_var.clone(), stage_var);
        if let Err(e) = load_vars_checked(&map, &path) {
            self.adam = previous;
            return Err(e);
        }
        self.adam_stage = stage;
        self.steps_done = step_var.as_tensor().to_vec1::<f64>()?[0] as u64;
        Ok(())
    }

    /// E's parameters (`e.`), the optimiser state (`adam.`) and the counters in one map whose
    /// variables are the live ones (loading into it restores the run).
    fn state_map(&self, step: Var, stage: Var) -> VarMap {
        let map = VarMap::new();
        insert_renamed(&map, self.model.vars(), "", "e.");
        insert_renamed(&map, self.adam.state(), "", "adam.");
        insert_var(&map, "train.step", &step);
        insert_var(&map, "train.adam_stage", &stage);
        map
    }
}

/// The value of the one-element tensor `name` in the safetensors file `path`.
fn read_scalar(path: &Path, name: &str) -> Result<f64> {
    // SAFETY: mapped read-only for this call; concurrent modification is outside the contract
    // (as for `load_vars_checked`).
    let file = unsafe { candle_core::safetensors::MmapedSafetensors::new(path) }
        .map_err(|e| Error::file(path, format!("cannot read the training state: {e}")))?;
    let value = file
        .load(name, &Device::Cpu)
        .and_then(|t| t.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>())
        .map_err(|e| Error::file(path, format!("tensor `{name}`: {e}")))?;
    value
        .first()
        .copied()
        .ok_or_else(|| Error::file(path, format!("tensor `{name}` is empty")))
}

/// 0 for stage 1, 1 for the fine-tune (the code stored in `train.adam_stage`).
fn stage_code(stage: Stage) -> f64 {
    match stage {
        Stage::Aligned => 0.0,
        Stage::Finetune => 1.0,
    }
}

/// How the error of a run stopped by the [`NanGuard`] ends.
const DIVERGED_ADVICE: &str = "lower the learning rate or check the GAN model";

/// Adam's ε: PyTorch's default, which the reference keeps.
const ADAM_EPS: f64 = 1e-8;

/// A fresh Adam over every parameter of E at the learning rate of `stage`.
fn new_adam(model: &EstimatorModel, config: &TrainConfig, stage: Stage) -> Result<Adam> {
    let cfg = AdamConfig {
        lr: config.lr_of(stage),
        beta1: config.beta1,
        beta2: config.beta2,
        eps: ADAM_EPS,
    };
    // E has no buffers: every variable is trained.
    Ok(Adam::for_varmap(model.vars(), |_| true, cfg)?)
}
