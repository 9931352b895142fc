//! One relief-prior run, step by step: the batch of a step (examples `step·B … step·B + B − 1`
//! of the run's stream, rendered in parallel), the loss, Adam, the NaN guard; the validation
//! score of the current weights on fixed validation photos; and the resumable state (weights,
//! moments and counters in one file, written atomically).

use std::path::Path;

use anyhow::Context;
use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use photomat_core::checkpoint::{load_vars_checked, save_vars_atomic};
use photomat_core::rng::SplitMix64;
use photomat_core::{Brdf, Highlight, MaterialMaps, ParamSpec, lookup};
use photomat_data::simulator::PHOTO_SIDE;
use photomat_library::photos::{Augmentation, LibraryFamily};
use photomat_library::split::Split;
use photomat_train::varmap::{insert_renamed, insert_var};
use photomat_train::{Adam, AdamConfig, NanGuard, gradients_finite};
use serde::{Deserialize, Serialize};

use super::draws::{Draws, Example};
use super::objective::{Batch, LossTerms, loss};
use super::settings::PriorTrainConfig;
use crate::input::prior_input;
use crate::maps::{colour_specs, decode_colour, normals_of_height};
use crate::model_files::PriorModel;

/// The state file of a run folder.
pub const STATE_FILE: &str = "train_state.safetensors";
/// Consecutive steps with a skipped update after which a run stops.
const NAN_LIMIT: usize = 20;
/// Key of the validation photos' stream (fixed per run: scores of successive snapshots
/// compare).
const VALIDATION_KEY: u64 = 0x7661_6c69_6461_7465; // "validate"
/// Key of the rendering loss's lights.
const LIGHTS_KEY: u64 = 0x6c69_6768_7473; // "lights"
/// Flash positions of the rendering loss lie within this share of the square's half side:
/// highlights inside the photo, where the rendering says most about the maps.
const LIGHT_SPREAD: f64 = 0.8;

/// What one step did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepReport {
    /// Steps done after it.
    pub step: u64,
    pub terms: LossTerms,
    /// Whether its update was skipped (a non-finite loss or gradient).
    pub skipped: bool,
}

/// A prior's score on validation photos (materials it never trained on).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ValidationScore {
    /// Mean angle between predicted and true normals, degrees.
    pub normal_degrees: f64,
    /// The same for flat normals: what predicting no relief scores.
    pub flat_normal_degrees: f64,
    /// RMSE of the diffuse albedo (linear), when the model has one.
    pub diffuse_rmse: f64,
    /// RMSE of the roughness, when the model has one.
    pub roughness_rmse: f64,
    /// The loss's terms on the validation photos.
    pub terms: LossTerms,
}

/// A relief-prior training run (module docs).
pub struct PriorTrainer {
    config: PriorTrainConfig,
    model: PriorModel,
    adam: Adam,
    guard: NanGuard,
    steps_done: u64,
    train: Draws,
    validation: Draws,
    specs: Vec<ParamSpec>,
    shading: Brdf,
    ggx: Brdf,
}

impl PriorTrainer {
    /// A fresh run of `config` (weights seeded), its library's train and validation splits
    /// opened.
    pub fn new(config: PriorTrainConfig, device: &Device) -> anyhow::Result<Self> {
        let brdf = lookup(&config.brdf)?;
        let model = PriorModel::new_seeded(
            brdf.clone(),
            config.architecture.clone(),
            config.seed,
            device,
        )?;
        let adam = Adam::for_varmap(model.vars(), |_| true, AdamConfig::kingma(config.lr))?;
        let open = |split| -> anyhow::Result<Draws> {
            let family = LibraryFamily::open(
                &config.library,
                split,
                &config.exclude_licences,
                Augmentation::default(),
            )?
            .keep_in_memory(2 * config.size);
            Ok(Draws::new(family, config.size))
        };
        Ok(Self {
            train: open(Split::Train).context("the library's train split")?,
            validation: open(Split::Validation).context("the library's validation split")?,
            specs: colour_specs(&brdf),
            shading: brdf.innermost(),
            ggx: lookup("ggx")?,
            guard: NanGuard::new(NAN_LIMIT, "resume with a lower --lr"),
            steps_done: 0,
            adam,
            model,
            config,
        })
    }

    pub fn config(&self) -> &PriorTrainConfig {
        &self.config
    }

    pub fn model(&self) -> &PriorModel {
        &self.model
    }

    pub fn steps_done(&self) -> u64 {
        self.steps_done
    }

    /// The batch of examples `indices` of `draws` in stream `seed`.
    fn batch(&self, draws: &Draws, seed: u64, indices: &[u64]) -> anyhow::Result<Batch> {
        draws.prepare(seed, indices)?;
        let examples: Vec<Example> = indices
            .iter()
            .map(|&i| draws.example(seed, i))
            .collect::<anyhow::Result<_>>()?;
        draws.forget(seed, indices);
        let photos: Vec<&Tensor> = examples.iter().map(|e| &e.photo).collect();
        let highlights: Vec<Highlight> = examples.iter().map(|e| e.highlight).collect();
        let input = prior_input(&Tensor::cat(&photos, 0)?, &highlights, PHOTO_SIDE)?;
        let mut truth = MaterialMaps::new();
        for name in examples[0].truth.names() {
            let maps: Vec<&Tensor> = examples
                .iter()
                .map(|e| e.truth.get(name))
                .collect::<photomat_core::Result<_>>()?;
            truth.insert(name, Tensor::cat(&maps, 0)?);
        }
        let heights: Vec<&Tensor> = examples.iter().map(|e| &e.height).collect();
        let n = draws.size();
        let render_lights = indices
            .iter()
            .map(|&i| {
                let mut rng = SplitMix64(seed ^ LIGHTS_KEY ^ i.wrapping_mul(0x9e37_79b9_7f4a_7c15));
                (0..self.config.render_lights)
                    .map(|_| {
                        let r = LIGHT_SPREAD * PHOTO_SIDE / 2.0;
                        Highlight::new(
                            r * (2.0 * rng.next_unit() - 1.0),
                            r * (2.0 * rng.next_unit() - 1.0),
                        )
                    })
                    .collect()
            })
            .collect();
        Ok(Batch {
            input,
            truth: truth.with_texel_size(Some(PHOTO_SIDE / n as f64)),
            height: Tensor::cat(&heights, 0)?,
            texel: PHOTO_SIDE / n as f64,
            side: PHOTO_SIDE,
            render_lights,
        })
    }

    /// One training step (module docs).
    pub fn step(&mut self) -> anyhow::Result<StepReport> {
        let b = self.config.batch as u64;
        let indices: Vec<u64> = (self.steps_done * b..(self.steps_done + 1) * b).collect();
        let batch = self.batch(&self.train, self.config.seed, &indices)?;
        let out = self.model.net().forward(&batch.input)?;
        let (total, terms) = loss(
            &out,
            &batch,
            &self.specs,
            &self.shading,
            &self.ggx,
            &self.config.weights,
        )?;
        let grads = total.backward()?;
        let vars: Vec<candle_core::Var> = self.model.vars().all_vars();
        let finite = gradients_finite(&grads, vars.iter())?;
        let apply = self.guard.allow("prior", terms.total, finite);
        if apply {
            self.adam.step(&grads)?;
        }
        self.steps_done += 1;
        let skipped = !self.guard.end_step(self.steps_done)?.is_empty();
        Ok(StepReport {
            step: self.steps_done,
            terms,
            skipped,
        })
    }

    /// The current weights' [`ValidationScore`] on `count` fixed validation photos.
    pub fn validate(&self, count: usize) -> anyhow::Result<ValidationScore> {
        let mut sums = [0.0f64; 4];
        let mut terms = LossTerms::default();
        let seed = self.config.seed ^ VALIDATION_KEY;
        for i in 0..count as u64 {
            let batch = self.batch(&self.validation, seed, &[i])?;
            let out = self.model.net().forward(&batch.input)?;
            let (_, t) = loss(
                &out,
                &batch,
                &self.specs,
                &self.shading,
                &self.ggx,
                &self.config.weights,
            )?;
            terms.maps += t.maps;
            terms.normal += t.normal;
            terms.render += t.render;
            terms.total += t.total;
            let predicted = normals_of_height(&out.height, batch.texel)?;
            let truth = normals_of_height(&batch.height, batch.texel)?;
            sums[0] += mean_angle_degrees(&predicted, &truth)?;
            sums[1] += mean_angle_degrees(&flat_like(&truth)?, &truth)?;
            let colour = decode_colour(&self.specs, &out.colour)?;
            for (k, name) in [(2, "diffuse"), (3, "roughness")] {
                if let (Ok(p), Ok(t)) = (colour.get(name), batch.truth.get(name)) {
                    sums[k] += rmse(p, t)?;
                }
            }
        }
        let n = count.max(1) as f64;
        let scale = |t: f64| t / n;
        Ok(ValidationScore {
            normal_degrees: sums[0] / n,
            flat_normal_degrees: sums[1] / n,
            diffuse_rmse: sums[2] / n,
            roughness_rmse: sums[3] / n,
            terms: LossTerms {
                maps: scale(terms.maps),
                normal: scale(terms.normal),
                render: scale(terms.render),
                total: scale(terms.total),
            },
        })
    }

    /// The state map: the prior's weights under `prior.`, Adam's under `adam.`, the counters.
    fn state_map(&self) -> anyhow::Result<VarMap> {
        let map = VarMap::new();
        insert_renamed(&map, self.model.vars(), "", "prior.");
        insert_renamed(&map, self.adam.state(), "", "adam.");
        let counters = candle_core::Var::from_tensor(&Tensor::new(
            &[self.steps_done as f64, self.guard.streak() as f64],
            &Device::Cpu,
        )?)?;
        insert_var(&map, "trainer.counters", &counters);
        Ok(map)
    }

    /// Writes the state into `dir/train_state.safetensors` atomically.
    pub fn save_state(&self, dir: &Path) -> anyhow::Result<()> {
        save_vars_atomic(&self.state_map()?, &dir.join(STATE_FILE))?;
        Ok(())
    }

    /// Restores the state saved in `dir` (the same configuration's); errors name the file and
    /// the tensor that does not fit.
    pub fn load_state(&mut self, dir: &Path) -> anyhow::Result<()> {
        let map = self.state_map()?;
        load_vars_checked(&map, &dir.join(STATE_FILE))?;
        let counters = map
            .get(
                (2,),
                "trainer.counters",
                candle_nn::Init::Const(0.0),
                DType::F64,
                &Device::Cpu,
            )?
            .to_vec1::<f64>()?;
        self.steps_done = counters[0] as u64;
        self.guard.set_streak(counters[1] as usize);
        Ok(())
    }
}

/// +z normals shaped like `normals` (B, 3, H, W).
fn flat_like(normals: &Tensor) -> candle_core::Result<Tensor> {
    let (b, _, h, w) = normals.dims4()?;
    let zeros = Tensor::zeros((b, 2, h, w), DType::F32, normals.device())?;
    let ones = Tensor::ones((b, 1, h, w), DType::F32, normals.device())?;
    Tensor::cat(&[zeros, ones], 1)
}

/// Mean angle between unit normals `a` and `b` (B, 3, H, W), in degrees.
pub fn mean_angle_degrees(a: &Tensor, b: &Tensor) -> anyhow::Result<f64> {
    // Rounding can put a dot product of unit vectors a hair above 1: clamped for acos.
    let dot = (a * b)?.sum_keepdim(1)?.clamp(-1.0, 1.0)?;
    let angles: Vec<f32> = dot.flatten_all()?.to_vec1()?;
    let sum: f64 = angles.iter().map(|&c| (c as f64).acos().to_degrees()).sum();
    Ok(sum / angles.len().max(1) as f64)
}

/// Root mean square of `a − b`.
fn rmse(a: &Tensor, b: &Tensor) -> anyhow::Result<f64> {
    let mse = (a - b)?.sqr()?.mean_all()?.to_scalar::<f32>()? as f64;
    Ok(mse.sqrt())
}
