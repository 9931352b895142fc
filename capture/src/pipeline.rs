//! The three ways into a capture (docs/capture.md): from constant maps ([`capture`]), from
//! the generator prior of a model folder ([`capture_with_prior`]), and with the model chosen
//! among the folder's estimators ([`capture_auto`]). Each prepares the photo ([`crate::input`]),
//! finds where the fit starts and refines it ([`crate::fit`]).

use anyhow::{Context, bail};
use candle_core::{DType, Device};
use photomat_core::render::{DISPLAY_GAMMA, render_radiance_with};
use photomat_core::{Brdf, FlashGeometry, Highlight, encode_display};
use photomat_estimator::model_choice::{Candidate, Selection, choose};

use crate::fit::{Start, refine};
use crate::input::{Input, prepare_input};
use crate::options::CaptureOptions;
use crate::prior::{GanPrior, Inversion, PriorOptions};
use crate::result::Capture;
use crate::square::new_flash_positions;

/// Fits maps of `brdf` to the flash photo `bytes` (a JPEG or PNG file's content; `name` is
/// used in errors) from constant maps. `progress(step, loss)` is called after every step.
pub fn capture(
    bytes: &[u8],
    name: &str,
    brdf: &Brdf,
    options: &CaptureOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Capture> {
    capture_with_prior(bytes, name, brdf, options, None, progress)
}

/// [`capture`], starting from the maps the generator prior finds when `prior` is given
/// (module docs). `progress(step, loss)` counts the inversion's steps first, then the
/// refinement's.
pub fn capture_with_prior(
    bytes: &[u8],
    name: &str,
    brdf: &Brdf,
    options: &CaptureOptions,
    prior: Option<(&GanPrior, &PriorOptions)>,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Capture> {
    let input = prepare_input(bytes, name, options)?;
    let start = match prior {
        None => Start::constant(brdf, input.size)?,
        Some((prior, prior_options)) => {
            let inversion = invert(&input, name, prior, prior_options, progress)?;
            let raw = prior.decode(&inversion, brdf)?.with_context(|| {
                format!("'{}' has no estimator for {}", prior.dir(), brdf.name())
            })?;
            Start::from_prior(brdf, &input, prior, inversion, raw)?
        }
    };
    refine(input, name, brdf, start, options, progress)
}

/// [`capture_with_prior`] in the model the photo needs, chosen among the prior's estimators
/// (`--brdf auto`; docs/capture.md, "Choosing the model"): the generator is inverted once,
/// every estimator decodes the found material, each decoding is rendered under the photo's
/// flash and the eight [`new_flash_positions`] and compared with M's relighting of the found
/// material under the same lights, and the cheapest model whose error is within `tolerance`
/// of the best one's ([`photomat_estimator::model_choice::choose`], linear-radiance L1) is
/// refined. Returns the capture, whose [`Capture::selection`] records every candidate.
pub fn capture_auto(
    bytes: &[u8],
    name: &str,
    options: &CaptureOptions,
    prior: (&GanPrior, &PriorOptions),
    tolerance: f64,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Capture> {
    let (prior, prior_options) = prior;
    if prior.estimators().is_empty() {
        bail!("'{}' has no estimator to choose from", prior.dir());
    }
    let input = prepare_input(bytes, name, options)?;
    let inversion = invert(&input, name, prior, prior_options, progress)?;
    // The photo's flash and the eight new ones: M's relighting of the inverted material is
    // what each decoding must reproduce, under lights the photo did not show as well.
    let (row, col) = input.highlight.pixel;
    let mut lights = vec![Highlight::from_pixel_on(row, col, input.size, input.side)];
    lights.extend(new_flash_positions(input.side));
    let geometry =
        FlashGeometry::with_side(&lights, input.size, input.side, DType::F32, &Device::Cpu)?;
    let target = prior.relight(&inversion, &geometry.omega)?;
    let target_linear = target.powf(DISPLAY_GAMMA)?;
    let radiance_gain = inversion.display_gain.powf(DISPLAY_GAMMA);
    let mut candidates = Vec::new();
    let mut decoded = Vec::new();
    for estimator in prior.estimators() {
        let brdf = estimator.brdf().clone();
        let raw = estimator.estimator().forward(&inversion.features)?.detach();
        let maps = brdf.decode(&raw)?.with_texel_size(Some(input.texel));
        let radiance = (render_radiance_with(brdf.as_ref(), &maps, &geometry)? * radiance_gain)?;
        let l1 = (encode_display(&radiance)? - &target)?
            .abs()?
            .mean_all()?
            .to_scalar::<f32>()? as f64;
        // M's relighting is clamped to the display range; so is the render it is compared to.
        let l1_linear = (radiance.clamp(0.0, 1.0)? - &target_linear)?
            .abs()?
            .mean_all()?
            .to_scalar::<f32>()? as f64;
        candidates.push(Candidate {
            brdf: brdf.name(),
            channels: brdf.channels(),
            l1,
            l1_linear,
        });
        decoded.push((brdf, raw));
    }
    let chosen = choose(&candidates, tolerance)
        .with_context(|| format!("{name}: every model's error is non-finite"))?;
    let (brdf, raw) = decoded.swap_remove(chosen);
    let selection = Selection {
        chosen: brdf.name(),
        tolerance,
        candidates,
    };
    let start = Start::from_prior(&brdf, &input, prior, inversion, raw)?;
    let mut capture = refine(input, name, &brdf, start, options, progress)?;
    capture.selection = Some(selection);
    Ok(capture)
}

/// The generator prior's inversion to the photo of `input`.
fn invert(
    input: &Input,
    name: &str,
    prior: &GanPrior,
    options: &PriorOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Inversion> {
    prior
        .invert(&input.photo, &input.geometry.omega, options, progress)
        .with_context(|| format!("{name}: generator prior"))
}
