//! A capture that starts from the relief prior (docs/capture.md, "Starting from the relief
//! prior"): the prior ([`photomat_prior::PriorModel`], trained on photos of artist-made
//! materials) predicts the photo's maps, relief included, in one forward pass; the refinement
//! then starts from them, held near them by the anchor, and fits the rest the photo says.
//!
//! The capture's model is the prior's with the relief's scale set by the prediction (a height
//! model `height(·, scale=S)` whose `S` is the predicted relief's range, so that nothing
//! clips; recorded in `material.json`). The exposure gain starts where the prior's maps,
//! rendered under the photo's flash, have the photo's mean radiance (the prior reads photos
//! with their exposure divided out).

use std::time::Instant;

use anyhow::Context;
use candle_core::Tensor;
use photomat_core::render::{DISPLAY_GAMMA, render_radiance_with};
use photomat_core::{Brdf, Highlight};
use photomat_prior::PriorModel;

use crate::fit::{Start, refine};
use crate::input::{Input, prepare_input};
use crate::options::CaptureOptions;
use crate::result::{Capture, ReliefPriorUsed};

/// Refinement steps of a capture from the relief prior unless asked otherwise: a short
/// refinement, as long per-texel fits from a learned start drift away from it (Deschaintre et
/// al. 2019; Look-Ahead, Zhou & Kalantari 2022) while the first steps fit the photo's exposure
/// and what the prior missed.
pub const PRIOR_REFINEMENT_STEPS: usize = 100;

/// Fits maps of the prior's model to the flash photo `bytes` (`name` in errors), starting from
/// the prior's prediction (module docs). The capture's side must be a multiple of the prior's
/// stride (32 for the default architecture).
pub fn capture_from_relief_prior(
    bytes: &[u8],
    name: &str,
    prior: &PriorModel,
    prior_dir: &str,
    options: &CaptureOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Capture> {
    let stride = prior.net().config().total_stride();
    if !options.size.is_multiple_of(stride) {
        anyhow::bail!(
            "the relief prior reads sides that are multiples of {stride}: use --size {}",
            options.size.div_ceil(stride) * stride
        );
    }
    let input = prepare_input(bytes, name, options)?;
    let (brdf, start) = start_from(&input, prior, prior_dir)?;
    refine(input, name, &brdf, start, options, progress)
}

/// The prior's prediction for `input` as a refinement's start, and the capture's model.
fn start_from(input: &Input, prior: &PriorModel, prior_dir: &str) -> anyhow::Result<(Brdf, Start)> {
    let clock = Instant::now();
    let (row, col) = input.highlight.pixel;
    let flash = Highlight::from_pixel_on(row, col, input.size, input.side);
    let predicted = prior
        .predict(&input.photo, flash, input.side)
        .context("the relief prior")?;
    let maps = predicted.maps.with_texel_size(Some(input.texel));
    let brdf = predicted.brdf;
    let raw = raw_maps(&brdf, &maps)?;
    // The render's mean radiance against the photo's: the gain that gives the prior's maps
    // the photo's exposure.
    let radiance = render_radiance_with(brdf.as_ref(), &maps, &input.geometry)?;
    let photo_linear = input.photo.clamp(0.0, 1.0)?.powf(DISPLAY_GAMMA)?;
    let mean = |t: &Tensor| -> anyhow::Result<f64> { Ok(t.mean_all()?.to_scalar::<f32>()? as f64) };
    // A black render (no radiance at all) keeps gain 1: there is nothing to scale.
    let ratio = mean(&photo_linear)? / mean(&radiance)?.max(f64::MIN_POSITIVE);
    let gain = if ratio.is_finite() && ratio > 0.0 {
        ratio
    } else {
        1.0
    };
    let relief = ReliefPriorUsed {
        model: prior_dir.to_string(),
        maps: maps.map_tensors(|t| Ok(t.detach()))?,
        gain,
        seconds: clock.elapsed().as_secs_f64(),
    };
    let start = Start {
        raw,
        log_gain: gain.ln(),
        prior: None,
        relief: Some(relief),
    };
    Ok((brdf, start))
}

/// The raw (pre-decoding) maps (1, C, N, N) that decode to `maps` under `brdf`, in its channel
/// order.
fn raw_maps(brdf: &Brdf, maps: &photomat_core::MaterialMaps) -> anyhow::Result<Tensor> {
    let parts = brdf
        .params()
        .iter()
        .map(|spec| Ok(spec.raw_for_map(maps.get(spec.name)?)?))
        .collect::<anyhow::Result<Vec<Tensor>>>()?;
    Ok(Tensor::cat(&parts, 1)?)
}
