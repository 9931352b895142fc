//! The uniform warm-up of a fit from constant maps: one value per raw channel, the gain and
//! the lens's vignetting (and ambient light) fitted to the photo box-filtered to
//! [`WARMUP_SIZE`]², from two starts, before any texel may paint the highlight in
//! (docs/capture.md, "Fit").

use anyhow::Context;
use candle_core::{Device, Tensor, Var};
use photomat_core::Brdf;
use photomat_train::{Adam, AdamConfig};

use crate::camera::{self, CameraTerms};
use crate::input::Input;
use crate::options::CaptureOptions;

/// Side of the uniform warm-up's image ([`CaptureOptions::warmup_steps`]): 64² box-filtered
/// texels still draw a highlight's lobe (a tenth of the photo is 6 texels) while a step
/// costs a sixteenth of a 256² one.
pub const WARMUP_SIZE: usize = 64;

/// What the uniform warm-up found: raw values (1, C, 1, 1), log gain, and the vignetting
/// strength and ambient radiance when they are fitted.
pub(crate) struct UniformFit {
    pub(crate) raw: Tensor,
    pub(crate) log_gain: f64,
    pub(crate) vignetting: Option<f64>,
    pub(crate) ambient: Option<f64>,
}

/// The uniform warm-up: one raw value per channel of `brdf` (constant maps) and the log
/// gain (and the vignetting and ambient light, when they are fitted), fitted by the
/// refinement's data term to the photo box-filtered to [`WARMUP_SIZE`]² (or its own size when
/// smaller) under the photo's flash, from each of [`warmup_starts`] with gain 1,
/// [`camera::START_VIGNETTING`] and [`camera::START_AMBIENT`]; the start that ends with the
/// lowest loss wins.
pub(crate) fn fit_uniform(
    input: &Input,
    brdf: &Brdf,
    options: &CaptureOptions,
) -> anyhow::Result<UniformFit> {
    let device = Device::Cpu;
    let small = input.box_filtered((input.size / WARMUP_SIZE).max(1))?;
    let n = small.size;
    let channels = brdf.channels();
    let mut best: Option<(f64, UniformFit)> = None;
    for raw_start in warmup_starts(brdf) {
        let raw = Var::from_tensor(&Tensor::from_vec(raw_start, (1, channels, 1, 1), &device)?)?;
        let terms = CameraTerms::new(
            0.0,
            options.vignetting.then_some(camera::START_VIGNETTING),
            options.ambient.then_some(camera::START_AMBIENT),
        )?;
        let loss = || -> anyhow::Result<Tensor> {
            let uniform = raw.as_tensor().broadcast_as((1, channels, n, n))?;
            let (_, predicted) = small.predict(brdf, &terms, &uniform)?;
            Ok((predicted - &small.photo)?.abs()?.mean_all()?)
        };
        let mut vars = vec![("raw".to_string(), raw.clone())];
        vars.extend(terms.vars());
        let mut adam = Adam::new(vars, AdamConfig::kingma(options.lr))?;
        for _ in 0..options.warmup_steps {
            adam.step(&loss()?.backward()?)?;
        }
        let last = loss()?.to_scalar::<f32>()? as f64;
        // A start that diverged (NaN) never wins; the first finite one always can.
        if last.is_finite() && best.as_ref().is_none_or(|(b, _)| last < *b) {
            let fit = UniformFit {
                raw: raw.as_tensor().detach(),
                log_gain: terms.log_gain()?,
                vignetting: terms.vignetting()?,
                ambient: terms.ambient()?,
            };
            best = Some((last, fit));
        }
    }
    let (_, fit) = best.context("the uniform warm-up diverged from every start")?;
    Ok(fit)
}

/// Where the uniform warm-up starts: the middle of every map's range (raw 0: diffuse and
/// specular 0.22, roughness 0.5 for the common maps) and the model's own defaults
/// ([`photomat_core::ParamSpec::default`], e.g. the 0.04 specular of a dielectric). On a
/// Mitsuba-rendered brick photo the fit from the middle alone settled on a broad, strong
/// lobe (specular ≈ 0.2, roughness 0.73) where a narrow, weak one fitted better
/// (docs/benchmarks/capture.md, "The direct capture's uniform warm-up"). Each start is C raw
/// values, in the model's channel order.
fn warmup_starts(brdf: &Brdf) -> Vec<Vec<f32>> {
    let middle = vec![0.0; brdf.channels()];
    let defaults = brdf
        .params()
        .iter()
        .flat_map(|p| p.raw_for(p.default))
        .collect();
    vec![middle, defaults]
}
