//! The refinement through the differentiable renderer (module docs of the crate): where it
//! starts ([`Start`]: constant maps, or a prior's), the coarse stage of a large capture and the
//! full-size steps, each a [`Stage`] of Adam steps on the raw maps and the camera terms.

use std::time::Instant;

use anyhow::bail;
use candle_core::{DType, Device, Tensor, Var};
use photomat_core::render::DISPLAY_GAMMA;
use photomat_core::{Brdf, MaterialMaps};
use photomat_estimator::upsample::upsample2x_clamped;
use photomat_train::{Adam, AdamConfig};

use crate::camera::CameraTerms;
use crate::held::HeldChannels;
use crate::input::Input;
use crate::options::{CaptureOptions, RELIEF_MAPS};
use crate::prior::{GanPrior, Inversion};
use crate::result::{Capture, CoarseStage, PriorUsed, ReliefPriorUsed};
use crate::warmup::fit_uniform;

/// How many times the side of a `size`² capture is divided in its coarse stage: the largest
/// power of two `f` that divides `size` with `size / f` ≥ `min_size` (1: no coarse stage).
pub fn coarse_factor(size: usize, min_size: usize) -> usize {
    let mut factor = 1;
    while (size / factor).is_multiple_of(2) && size / factor / 2 >= min_size.max(1) {
        factor *= 2;
    }
    factor
}

/// Where a refinement starts: raw maps, log radiance gain, and the prior that gave them.
pub(crate) struct Start {
    pub(crate) raw: Tensor,
    pub(crate) log_gain: f64,
    pub(crate) prior: Option<PriorUsed>,
    /// The relief prior that gave the start, when one did.
    pub(crate) relief: Option<ReliefPriorUsed>,
}

impl Start {
    /// Constant maps (raw zeros) and gain 1.
    pub(crate) fn constant(brdf: &Brdf, size: usize) -> anyhow::Result<Self> {
        Ok(Self {
            raw: Tensor::zeros((1, brdf.channels(), size, size), DType::F32, &Device::Cpu)?,
            log_gain: 0.0,
            prior: None,
            relief: None,
        })
    }

    /// E's raw maps `raw` of the inverted material, with the inversion's gain.
    pub(crate) fn from_prior(
        brdf: &Brdf,
        input: &Input,
        prior: &GanPrior,
        inversion: Inversion,
        raw: Tensor,
    ) -> anyhow::Result<Self> {
        let maps = brdf
            .decode(&raw)?
            .with_texel_size(Some(input.texel))
            .map_tensors(|t| Ok(t.detach()))?;
        // A display gain d is a radiance gain d^γ under the display gamma.
        let log_gain = DISPLAY_GAMMA * inversion.display_gain.ln();
        Ok(Self {
            raw,
            log_gain,
            relief: None,
            prior: Some(PriorUsed {
                model: prior.dir().to_string(),
                inversion,
                maps,
            }),
        })
    }
}

/// The refinement of the module docs, from `start`: the uniform warm-up of a fit from constant
/// maps, a coarse stage when the capture is large, then the full-size steps.
pub(crate) fn refine(
    input: Input,
    name: &str,
    brdf: &Brdf,
    start: Start,
    options: &CaptureOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Capture> {
    let prior_used = start.prior;
    let relief_used = start.relief;
    // A start from a prior's maps skips the warm-up and the coarse stage, refines the relief
    // and is held near its maps.
    let from_prior = prior_used.is_some() || relief_used.is_some();
    let (start_raw, terms) = warm_start(
        &input,
        brdf,
        start.raw,
        start.log_gain,
        !from_prior,
        options,
    )?;
    let offset = prior_used.as_ref().map_or(0, |p| p.inversion.losses.len());
    let known = options.known_maps.as_ref();
    let held = held_maps(brdf, options, from_prior);
    let tie = HeldChannels::new(brdf, &held, known, input.size, 1)?;
    let clock = Instant::now();
    let mut losses = Vec::with_capacity(options.steps);
    let mut record = |step: usize, loss: f64| {
        losses.push(loss);
        progress(offset + step, loss);
    };
    // A fit from constant maps spends its first steps on a smaller photo (a prior's maps
    // start at full size, where E decoded them).
    let factor = if !from_prior {
        coarse_factor(input.size, options.coarse_min_size)
    } else {
        1
    };
    let coarse_steps = options.steps.saturating_sub(options.full_size_steps);
    let (start_raw, coarse) = if factor > 1 && coarse_steps > 0 {
        let coarse_tie = HeldChannels::new(brdf, &held, known, input.size, factor)?;
        let coarse = CoarseRun {
            input: &input,
            brdf,
            terms: &terms,
            options,
            factor,
            steps: coarse_steps,
            tie: &coarse_tie,
        };
        let (raw, stage) = coarse.run(&start_raw, name, &mut record)?;
        (
            raw,
            Some(CoarseStage {
                seconds: clock.elapsed().as_secs_f64(),
                ..stage
            }),
        )
    } else {
        (start_raw, None)
    };
    let start_raw = tie.apply(&start_raw)?;
    let done = coarse.map_or(0, |c| c.steps);
    let stage = Stage {
        input: &input,
        brdf,
        tie: &tie,
        terms: &terms,
        anchor: from_prior
            .then_some((&start_raw, options.anchor))
            .filter(|(_, weight)| *weight > 0.0),
        options,
    };
    let fitted = stage.descend(&start_raw, options.steps - done, name, &mut |step, loss| {
        record(done + step, loss)
    })?;
    let (maps, render) = stage.predict(&fitted)?;
    let Input {
        photo,
        highlight,
        side,
        fov,
        ..
    } = input;
    Ok(Capture {
        brdf: brdf.clone(),
        maps: maps.map_tensors(|t| Ok(t.detach()))?,
        photo,
        render: render.detach(),
        highlight,
        gain: terms.log_gain()?.exp(),
        vignetting: terms.vignetting()?,
        ambient: terms.ambient()?,
        side,
        fov,
        losses,
        seconds: clock.elapsed().as_secs_f64(),
        coarse,
        prior: prior_used,
        relief_prior: relief_used,
        selection: None,
        known_maps: known.map_or_else(Vec::new, |k| {
            k.names().into_iter().map(String::from).collect()
        }),
    })
}

/// Where the per-texel fit starts: for a fit from constant maps with a warm-up, the uniform
/// warm-up's values broadcast over `raw`'s shape and its camera terms; otherwise `raw` and the
/// gain `log_gain` with no vignetting or ambient light.
fn warm_start(
    input: &Input,
    brdf: &Brdf,
    raw: Tensor,
    log_gain: f64,
    from_constant: bool,
    options: &CaptureOptions,
) -> anyhow::Result<(Tensor, CameraTerms)> {
    if from_constant && options.warmup_steps > 0 {
        let warm = fit_uniform(input, brdf, options)?;
        let raw = warm.raw.broadcast_as(raw.shape())?.contiguous()?;
        let terms = CameraTerms::new(warm.log_gain, warm.vignetting, warm.ambient)?;
        Ok((raw, terms))
    } else {
        Ok((raw, CameraTerms::new(log_gain, None, None)?))
    }
}

/// The maps a fit holds at one value: the ones asked for and, in a fit from constant maps
/// without [`CaptureOptions::relief`], the relief (unless it is known: a known relief stays
/// at its values rather than flat).
fn held_maps(brdf: &Brdf, options: &CaptureOptions, from_prior: bool) -> Vec<String> {
    let mut held = options.uniform_maps.clone();
    if !options.relief && !from_prior {
        let known = options.known_maps.as_ref();
        let is_known = |n: &str| known.is_some_and(|k| k.contains(n));
        held.extend(
            brdf.params()
                .iter()
                .map(|p| p.name)
                .filter(|n| RELIEF_MAPS.contains(n) && !is_known(n))
                .map(String::from),
        );
    }
    held
}

/// The coarse stage of a large fit from constant maps: `steps` on the photo box-filtered by
/// `factor`, whose maps, upsampled, start the full-size steps.
struct CoarseRun<'a> {
    input: &'a Input,
    brdf: &'a Brdf,
    terms: &'a CameraTerms,
    options: &'a CaptureOptions,
    factor: usize,
    steps: usize,
    tie: &'a HeldChannels,
}

impl CoarseRun<'_> {
    /// Runs the stage from the uniform `start` (1, C, N, N); returns the upsampled maps and the
    /// stage's record (its seconds left for the caller's clock). `step(k, loss)` from k = 1.
    fn run(
        &self,
        start: &Tensor,
        name: &str,
        step: &mut dyn FnMut(usize, f64),
    ) -> anyhow::Result<(Tensor, CoarseStage)> {
        let small = self.input.box_filtered(self.factor)?;
        let (_, c, _, _) = start.dims4()?;
        // The warm-up's start is uniform, so it is the same at any size.
        let uniform = start.narrow(2, 0, 1)?.narrow(3, 0, 1)?;
        let raw = uniform.broadcast_as((1, c, small.size, small.size))?;
        let stage = Stage {
            input: &small,
            brdf: self.brdf,
            tie: self.tie,
            terms: self.terms,
            anchor: None,
            options: self.options,
        };
        let fitted = stage.descend(&raw, self.steps, name, step)?;
        let record = CoarseStage {
            size: small.size,
            steps: self.steps,
            seconds: 0.0,
        };
        Ok((upsample_clamped(&fitted, self.factor)?, record))
    }
}

/// One size of a refinement: the photo at that size and what the loss holds fixed.
struct Stage<'a> {
    input: &'a Input,
    brdf: &'a Brdf,
    tie: &'a HeldChannels,
    /// Shared by the stages: the gain and vignetting carry over from one size to the next.
    terms: &'a CameraTerms,
    /// The prior's raw maps and the weight μ of the term holding the fit near them.
    anchor: Option<(&'a Tensor, f64)>,
    /// The learning rate, smoothness weight and stop flag.
    options: &'a CaptureOptions,
}

impl Stage<'_> {
    /// [`Input::predict`] with this stage's model and camera terms.
    pub(crate) fn predict(&self, raw: &Tensor) -> anyhow::Result<(MaterialMaps, Tensor)> {
        self.input.predict(self.brdf, self.terms, raw)
    }

    /// `steps` Adam steps of the loss (module docs) on the raw maps from `start` (1, C, N, N)
    /// and on the camera terms; `step(k, loss)` after every step (k from 1). Returns the
    /// fitted raw maps, the held channels tied.
    fn descend(
        &self,
        start: &Tensor,
        steps: usize,
        name: &str,
        step: &mut dyn FnMut(usize, f64),
    ) -> anyhow::Result<Tensor> {
        let raw = Var::from_tensor(&start.contiguous()?)?;
        let mut vars = vec![("raw".to_string(), raw.clone())];
        vars.extend(self.terms.vars());
        let mut adam = Adam::new(vars, AdamConfig::kingma(self.options.lr))?;
        for k in 1..=steps {
            self.options.check_stop()?;
            let fitted = self.tie.apply(raw.as_tensor())?;
            let (_, predicted) = self.predict(&fitted)?;
            let mut loss = (predicted - &self.input.photo)?.abs()?.mean_all()?;
            if self.options.smoothness > 0.0 {
                loss = (loss + (total_variation(&fitted)? * self.options.smoothness)?)?;
            }
            if let Some((anchor, weight)) = self.anchor {
                let drift = (&fitted - anchor)?.abs()?.mean_all()?;
                loss = (loss + (drift * weight)?)?;
            }
            let value = loss.to_scalar::<f32>()? as f64;
            if !value.is_finite() {
                bail!("{name}: the fit diverged at step {k} (loss {value})");
            }
            adam.step(&loss.backward()?)?;
            step(k, value);
        }
        Ok(self.tie.apply(raw.as_tensor())?)
    }
}

/// `x` (B, C, N, N) upsampled `factor`× (a power of two) by repeated ×2 bilinear
/// interpolation (`align_corners = False`), the border texels repeated beyond the edge (a
/// photo's maps do not wrap around): (B, C, factor·N, factor·N).
fn upsample_clamped(x: &Tensor, factor: usize) -> anyhow::Result<Tensor> {
    let mut x = x.clone();
    let mut f = factor;
    while f > 1 {
        x = upsample2x_clamped(&x)?;
        f /= 2;
    }
    Ok(x)
}

/// Mean absolute difference of neighbouring texels (wrap-around) of a (B, C, H, W) tensor.
fn total_variation(x: &Tensor) -> candle_core::Result<Tensor> {
    let dx = (x.roll(-1, 3)? - x)?.abs()?.mean_all()?;
    let dy = (x.roll(-1, 2)? - x)?.abs()?.mean_all()?;
    dx + dy
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_factor_halves_even_sizes_down_to_the_minimum() {
        for (size, factor) in [
            (1024, 2),
            (2048, 4),
            (1536, 2),
            (1000, 1),
            (512, 1),
            (1023, 1),
        ] {
            assert_eq!(coarse_factor(size, 512), factor, "{size}");
        }
        assert_eq!(coarse_factor(64, 16), 4);
        assert_eq!(coarse_factor(64, 0), 64);
    }

    #[test]
    fn clamped_upsampling_keeps_constants_and_interpolates_ramps() {
        // 2 × 3 planes of a constant and of a ramp along x: ×2 keeps the constant exactly,
        // samples the ramp at (o + ½)/2 − ½ inside and clamps it at the edges.
        let device = Device::Cpu;
        let (h, w) = (2usize, 3usize);
        let mut values = vec![0.7f64; h * w];
        values.extend((0..h * w).map(|i| (i % w) as f64));
        let x = Tensor::from_vec(values, (1, 2, h, w), &device).unwrap();
        let up = upsample_clamped(&x, 2).unwrap();
        assert_eq!(up.dims4().unwrap(), (1, 2, 2 * h, 2 * w));
        let planes: Vec<Vec<Vec<f64>>> = up.squeeze(0).unwrap().to_vec3().unwrap();
        for row in &planes[0] {
            for &v in row {
                assert!((v - 0.7).abs() < 1e-15, "{v}");
            }
        }
        let expected = [0.0, 0.25, 0.75, 1.25, 1.75, 2.0];
        for row in &planes[1] {
            for (v, e) in row.iter().zip(expected) {
                assert!((v - e).abs() < 1e-15, "{row:?}");
            }
        }
    }
}
