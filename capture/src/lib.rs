//! # photomat-capture
//!
//! One phone flash photo → material maps for a BRDF model chosen by name: the library
//! behind `photomat capture` (docs/capture.md).
//!
//! The photo is decoded, oriented and centre-cropped to a square of `size` texels as
//! `photomat prepare` does ([`photomat_data::dataset::photo::prepare_photo`]), its flash
//! highlight is found by the default detector (or given), and the maps are optimised through
//! the differentiable flash renderer so that their render under that flash matches the photo
//! (direct optimisation from constant maps, the baseline of single-image capture in
//! Deschaintre et al. 2018 and MaterialGAN, Guo et al. 2020). The geometry is the training
//! data's: the photo is a square of side 2 world units seen from straight above, with the
//! flash at height 1 above the highlight (docs/conventions.md). The photo's unknown exposure
//! is a fitted global gain, its lens's falloff a fitted vignetting `V`, the room's light a
//! fitted ambient term ([`camera`]).
//!
//! The fit minimises, over the raw (pre-decoding) maps `θ`, the log gain `g`, `V` and the
//! ambient radiance `c`,
//!
//! `L = mean |encode(e^g · V · (render(decode(θ)) + c · A(θ))) − photo| + λ · mean |∇θ|`
//!
//! (`A`: the maps' reflectance of a uniform sky, [`camera`])
//!
//! in the display-encoded domain (what the photo stores; the gamma compresses the highlight
//! as the eye does), with a total-variation prior of weight λ on the raw maps, which keeps
//! what a single light cannot separate (e.g. roughness far from the highlight) smooth rather
//! than noisy. Adam ([`photomat_train::Adam`]) steps all of them.
//!
//! The camera's field of view is an input ([`CaptureOptions::fov_degrees`]; when it is not
//! given, the photo's EXIF focal length, else a phone's main camera: [`field_of_view`]): it
//! sets how wide the photographed square is at the flash's height 1 ([`square_side`];
//! docs/conventions.md, "A photo's field of view"), hence the texel size of the maps and the
//! angles under which each texel saw the flash. [`relight`] renders the fitted maps under
//! new flash positions ([`new_flash_positions`]), which a single photo never showed.
//!
//! With a trained model folder the maps do not start constant: [`capture_with_prior`] first
//! inverts the generator to the photo and decodes what it finds with the estimator
//! ([`prior`]), then refines those maps by the same loss, optionally held near them by an
//! anchor term `μ · mean |θ − θ₀|`. [`capture_auto`] chooses the model as well: the cheapest
//! of the folder's estimators whose decoding of the inverted generator reproduces M's
//! relighting of it, under the photo's flash and eight others, within a tolerance of the best
//! one's (docs/capture.md, "Choosing the model").
//!
//! [`evaluate`] holds the measures of a capture against known maps (docs/capture.md,
//! "Validation on photos this project did not make").
//!
//! A fit from constant maps starts with a uniform warm-up: one value per raw channel, the
//! gain and the lens's vignetting ([`camera`]), fitted to the photo box-filtered to
//! [`WARMUP_SIZE`]² from two starts (the middle of every range and the model's defaults),
//! the better kept. Uniform maps cannot paint the highlight or the falloff in, so the lobe
//! and the vignetting are set by the whole photo before the per-texel refinement starts
//! from them; on simulated and Mitsuba-rendered photos this relit 25 % and 4 % better under
//! held-out flashes (docs/benchmarks/capture.md, "The direct capture's uniform warm-up"). The
//! relief stays flat through the refinement unless [`CaptureOptions::relief`] asks for it,
//! [`CaptureOptions::uniform_maps`] holds other named maps at one value as well, and
//! [`CaptureOptions::known_maps`] holds maps known from elsewhere at their values (`held`).
//!
//! Large fits from constant maps start coarse: the first steps of a capture of at least twice
//! [`CaptureOptions::coarse_min_size`] run on the photo box-filtered to a smaller size
//! ([`coarse_factor`]), whose maps, upsampled, start the last
//! [`CaptureOptions::full_size_steps`] at full size (docs/capture.md, "Fit").
//!
//! Not yet: camera tilt.

pub mod camera;
pub mod evaluate;
pub mod field_of_view;
mod held;
pub mod prior;

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor, Var};
use photomat_core::image_io::{PlanarImage, PngBits, write_atomic, write_png};
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::render::{DISPLAY_GAMMA, render_radiance_with};
use photomat_core::sheet::grid;
use photomat_core::{Brdf, FlashGeometry, Highlight, MaterialMaps, encode_display};
use photomat_data::dataset::photo::{Framing, prepare_photo};
use photomat_data::highlight::{DetectionStatus, DetectorKind};
use photomat_estimator::sample::choice::{Candidate, Selection, choose};
use photomat_estimator::upsample::clamped_upsample_axis;
use photomat_kernels::fir::separable;
use photomat_train::{Adam, AdamConfig};
use serde::Serialize;

use held::HeldChannels;

pub use camera::CameraTerms;
pub use field_of_view::{FieldOfView, FovSource};
pub use prior::{GanPrior, Inversion, PriorOptions};

/// Smallest and largest side of a capture: below 16 texels there is no highlight to fit,
/// above 2048 one step's render and gradients exceed a few GB.
pub const SIZE_RANGE: (usize, usize) = (16, 2048);

/// Default field of view across a photo's longer side, in degrees: a phone's main camera
/// (26 mm equivalent focal length on a 4:3 sensor: 2·atan(17.3 / 26) ≈ 67°).
pub const DEFAULT_FOV_DEGREES: f64 = 67.0;

pub use photomat_core::flash::TRAINING_FOV_DEGREES;

/// Fields of view a capture accepts, in degrees: below 5° the photo is a telescope's, above
/// 150° a fisheye's, which a pinhole straight down does not describe.
pub const FOV_RANGE: (f64, f64) = (5.0, 150.0);

/// Side, in world units, of the centred square cut from a `width × height` photo taken
/// straight down with a field of view of `fov_degrees` across its longer side, with the
/// camera (and flash) at height 1: `2 · tan(fov / 2) · min(w, h) / max(w, h)`.
pub fn square_side(fov_degrees: f64, width: usize, height: usize) -> f64 {
    let (short, long) = (width.min(height) as f64, width.max(height) as f64);
    2.0 * (fov_degrees.to_radians() / 2.0).tan() * short / long
}

/// Eight flash positions the photo did not show, for renders of the fitted maps: a ring at a
/// quarter of the square's side around its centre, every 45° (the flash at height 1, so the
/// highlight moves across the central half of the square).
pub fn new_flash_positions(side: f64) -> Vec<Highlight> {
    (0..8)
        .map(|k| {
            let angle = k as f64 * std::f64::consts::FRAC_PI_4;
            Highlight::new(0.25 * side * angle.cos(), 0.25 * side * angle.sin())
        })
        .collect()
}

/// How a photo is fitted.
#[derive(Debug, Clone)]
pub struct CaptureOptions {
    /// Side of the square the photo is resampled to, and of the maps. Default 256.
    pub size: usize,
    /// Adam steps. Default 400.
    pub steps: usize,
    /// Adam learning rate on the raw maps and the log gain. Default 0.05 (raw maps are
    /// unconstrained and decode through tanh-like maps, so steps of 0.05 move a map by a few
    /// % of its range).
    pub lr: f64,
    /// Weight λ of the total-variation prior on the raw maps. Default 0.002.
    pub smoothness: f64,
    /// The highlight in continuous pixel `(row, col)` of the square image, instead of
    /// detecting it.
    pub highlight: Option<(f64, f64)>,
    /// Field of view across the photo's longer side, in degrees; with the camera straight
    /// down it sets the square's side ([`square_side`]). `None` (the default): the photo's
    /// EXIF 35 mm equivalent focal length, else [`DEFAULT_FOV_DEGREES`]
    /// ([`field_of_view::field_of_view`]).
    pub fov_degrees: Option<f64>,
    /// Weight μ of the anchor `mean |θ − θ₀|` that holds the refined raw maps near the
    /// prior's; no effect without a prior. Default 0.05: on simulated photos it relit better
    /// than 0 on two of three families tried, and better on their mean (docs/benchmarks/capture.md,
    /// "`photomat capture` with the generator prior").
    pub anchor: f64,
    /// Steps of the uniform warm-up that a fit from constant maps starts with (module docs):
    /// one value per raw channel, the gain and the vignetting, fitted at [`WARMUP_SIZE`]², so
    /// that the lobe's width and strength and the lens's falloff are set by the whole photo
    /// before any texel may paint the highlight in. Default 100; 0 turns it off. No effect
    /// with a prior, which starts from E's maps.
    pub warmup_steps: usize,
    /// Fit the lens's vignetting ([`camera`]) in the warm-up and the refinement after it;
    /// otherwise, or when there is no warm-up (0 steps, or a prior), the photo is taken as
    /// free of it. Default on: free maps absorb a falloff texel by texel, uniform maps
    /// cannot, so only a warm-up identifies it (docs/benchmarks/capture.md, "The direct capture's
    /// uniform warm-up").
    pub vignetting: bool,
    /// Fit a dim, uniform ambient light ([`camera`]) in the warm-up and the refinement after
    /// it, as [`Self::vignetting`]; otherwise the photo is taken in a dark room. No effect on
    /// a model without diffuse or specular maps. Default off: with the vignetting it is not
    /// identifiable on a uniform material (both change the falloff's quadratic term), and on
    /// 8 simulated photos it relit 0.0750 → 0.0708 under held-out flashes, better on car
    /// paint, worse on stone; on 8 Mitsuba photos lit by the flash alone, 0.0398 → 0.0401
    /// (docs/benchmarks/capture.md, "A fitted ambient term").
    pub ambient: bool,
    /// Maps of the model fitted as one value over the whole square (e.g. `specular`,
    /// `roughness` of a material that varies in colour and relief only), so that they cannot
    /// paint the highlight in. Names the model lacks are an error.
    pub uniform_maps: Vec<String>,
    /// Maps known from elsewhere (e.g. a diffuse albedo from a cross-polarised photo), each
    /// (1, channels, N, N) at the capture's [`Self::size`] and named as the model's maps:
    /// held at these values through the whole fit, so that the photo sets only the others.
    /// With the true diffuse, specular and roughness maps this measures how well one photo
    /// determines the relief (docs/benchmarks/relief.md, "The relief of one photo with the
    /// reflectance known"). Names the model lacks, or a map also in
    /// [`Self::uniform_maps`], are errors. Default none.
    pub known_maps: Option<MaterialMaps>,
    /// Fit the maps that shape the shading normal ([`RELIEF_MAPS`]) texel by texel in a fit
    /// from constant maps. Default off: they are held uniform (flat normals), which relit
    /// simulated and Mitsuba-rendered photos 7 % and 20 % better under held-out flashes, and
    /// on the Mitsuba photos gave normals closer to the truth (12.6° against 18.1°) than
    /// the relief one flash paints in (docs/benchmarks/capture.md, "The direct capture's uniform
    /// warm-up"). A capture with a prior keeps refining E's relief either way.
    pub relief: bool,
    /// Of the [`Self::steps`], how many run at the full size when the capture has a coarse
    /// stage (a fit from constant maps of at least twice [`Self::coarse_min_size`]); the
    /// others run on the photo box-filtered to a smaller size ([`coarse_factor`]), a quarter
    /// of the texels per halving, and their maps, upsampled, start the full-size steps.
    /// Default 100.
    pub full_size_steps: usize,
    /// Smallest side of the coarse stage: the side is halved while the half is at least this
    /// and the side is even. Default 512 (1024² → 512², 2048² → 512²): at 512² a step took
    /// a fifth of a 1024² one's time on this project's 2-core machine, and the highlight's
    /// lobe and the texture are still drawn (docs/benchmarks/capture.md, "`photomat capture` at
    /// 1024² with a coarse stage").
    pub coarse_min_size: usize,
}

/// How many times the side of a `size`² capture is divided in its coarse stage: the largest
/// power of two `f` that divides `size` with `size / f` ≥ `min_size` (1: no coarse stage).
pub fn coarse_factor(size: usize, min_size: usize) -> usize {
    let mut factor = 1;
    while (size / factor).is_multiple_of(2) && size / factor / 2 >= min_size.max(1) {
        factor *= 2;
    }
    factor
}

/// The maps that shape the shading normal, by their shared names (docs/conventions.md,
/// "Parameter maps"): [`CaptureOptions::relief`] holds those a model has.
pub const RELIEF_MAPS: [&str; 2] = ["height", "normal"];

impl Default for CaptureOptions {
    fn default() -> Self {
        Self {
            size: 256,
            steps: 400,
            lr: 0.05,
            smoothness: 0.002,
            highlight: None,
            fov_degrees: None,
            anchor: 0.05,
            warmup_steps: 100,
            vignetting: true,
            ambient: false,
            uniform_maps: Vec::new(),
            known_maps: None,
            relief: false,
            full_size_steps: 100,
            coarse_min_size: 512,
        }
    }
}

/// The result of [`capture`].
#[derive(Clone)]
pub struct Capture {
    /// The model the maps are for.
    pub brdf: Brdf,
    /// The fitted maps (1, C, N, N), with their texel size.
    pub maps: MaterialMaps,
    /// The photo as fitted: (1, 3, N, N) display values.
    pub photo: Tensor,
    /// The maps' render under the photo's flash, with the fitted gain: (1, 3, N, N).
    pub render: Tensor,
    /// Where the flash was, and how it was found.
    pub highlight: HighlightUsed,
    /// The fitted exposure gain.
    pub gain: f64,
    /// The fitted vignetting strength ([`camera`]), when it was fitted.
    pub vignetting: Option<f64>,
    /// The fitted ambient radiance ([`camera`]), in the flash's units, when it was fitted.
    pub ambient: Option<f64>,
    /// Side of the photographed square in world units, at flash height 1 ([`square_side`]).
    pub side: f64,
    /// The field of view it was computed from, and where that came from.
    pub fov: FieldOfView,
    /// Loss after every refinement step.
    pub losses: Vec<f64>,
    /// Wall seconds of the refinement, its coarse stage included.
    pub seconds: f64,
    /// The refinement's coarse stage, when it had one ([`CaptureOptions::full_size_steps`]);
    /// its steps are the first of [`Self::losses`].
    pub coarse: Option<CoarseStage>,
    /// The generator prior, when one was used.
    pub prior: Option<PriorUsed>,
    /// How the model was chosen, for a capture in `auto` ([`capture_auto`]).
    pub selection: Option<Selection>,
    /// The maps held at known values ([`CaptureOptions::known_maps`]).
    pub known_maps: Vec<String>,
}

/// The coarse stage of a refinement: its side, steps and wall seconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CoarseStage {
    pub size: usize,
    pub steps: usize,
    pub seconds: f64,
}

/// What the generator prior of a capture did.
#[derive(Clone)]
pub struct PriorUsed {
    /// The model folder.
    pub model: String,
    /// The inversion's result, E's maps included.
    pub inversion: Inversion,
    /// E's maps of the inverted material, before refinement (1, C, N, N per map).
    pub maps: MaterialMaps,
}

/// The highlight a capture used.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HighlightUsed {
    /// Continuous pixel `(row, col)` in the square image.
    pub pixel: (f64, f64),
    /// `given`, or the detector's name.
    pub source: String,
    /// The detector's reason, when it gave one (e.g. which estimate it chose).
    pub note: Option<String>,
}

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
/// of the best one's ([`photomat_estimator::sample::choice::choose`], linear-radiance L1) is
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

/// A photo ready to be fitted: resampled, its highlight found, its flash geometry.
struct Input {
    /// (1, 3, N, N) display values.
    photo: Tensor,
    size: usize,
    highlight: HighlightUsed,
    /// The field of view the square's side comes from.
    fov: FieldOfView,
    side: f64,
    texel: f64,
    /// The photo's flash, on the square of side `side`.
    light: Highlight,
    geometry: FlashGeometry,
    /// Squared distance of every texel from the centre, for the vignetting ([`camera`]).
    rho2: Tensor,
}

impl Input {
    /// The maps of `brdf` decoded from `raw` (1, C, N, N) at this photo's texel size, and
    /// their display render under its flash, exposed by `terms`: (1, 3, N, N).
    fn predict(
        &self,
        brdf: &Brdf,
        terms: &CameraTerms,
        raw: &Tensor,
    ) -> anyhow::Result<(MaterialMaps, Tensor)> {
        let maps = brdf.decode(raw)?.with_texel_size(Some(self.texel));
        let radiance = render_radiance_with(brdf.as_ref(), &maps, &self.geometry)?;
        // The sum of the reflecting maps is built only where the ambient term reads it.
        let reflectance = if terms.fits_ambient() {
            maps.ambient_reflectance()?
        } else {
            None
        };
        let exposed = terms.expose(&radiance, reflectance.as_ref(), &self.rho2)?;
        Ok((maps, encode_display(&exposed)?))
    }

    /// The central `n·factor` texels of the photo (`n = size / factor`; the centre moves by
    /// half a texel at most) box-filtered by `factor` in linear light, as a sensor of n²
    /// pixels would have seen them, with the flash geometry of that smaller square.
    fn box_filtered(&self, factor: usize) -> anyhow::Result<Input> {
        let n = self.size / factor;
        let start = (self.size - n * factor) / 2;
        let photo = encode_display(
            &self
                .photo
                .narrow(2, start, n * factor)?
                .narrow(3, start, n * factor)?
                .powf(DISPLAY_GAMMA)?
                .avg_pool2d(factor)?,
        )?;
        let side = self.side * (n * factor) as f64 / self.size as f64;
        let geometry = FlashGeometry::with_side(&[self.light], n, side, DType::F32, &Device::Cpu)?;
        Ok(Input {
            photo,
            size: n,
            highlight: self.highlight.clone(),
            fov: self.fov,
            side,
            texel: side / n as f64,
            light: self.light,
            geometry,
            rho2: camera::rho_squared(n)?,
        })
    }
}

/// Checks the options, decodes and resamples the photo and finds its highlight.
fn prepare_input(bytes: &[u8], name: &str, options: &CaptureOptions) -> anyhow::Result<Input> {
    let (lo, hi) = SIZE_RANGE;
    if !(lo..=hi).contains(&options.size) {
        bail!("capture size {} is outside {lo} … {hi}", options.size);
    }
    let n = options.size;
    let framing = Framing {
        size: n,
        reject_non_square: false,
    };
    let prepared = prepare_photo(bytes, framing).map_err(|r| anyhow::anyhow!("{name}: {}", r.0))?;
    let highlight = match options.highlight {
        Some(pixel) => HighlightUsed {
            pixel,
            source: "given".into(),
            note: None,
        },
        None => {
            let kind = DetectorKind::default();
            let d = kind.build().detect(&prepared.image)?;
            if d.status == DetectionStatus::FallbackCentre {
                bail!(
                    "{name}: no flash highlight found ({}); give it with --highlight ROW,COL",
                    d.reason.unwrap_or_default()
                );
            }
            HighlightUsed {
                pixel: d.pixel(),
                source: kind.name().into(),
                note: d.reason,
            }
        }
    };
    let device = Device::Cpu;
    let photo = prepared.image.to_tensor(&device)?;
    let [width, height] = prepared.source_size;
    let fov = field_of_view::field_of_view(options.fov_degrees, bytes, width, height)
        .with_context(|| name.to_string())?;
    let side = square_side(fov.degrees, width, height);
    let (row, col) = highlight.pixel;
    let light = Highlight::from_pixel_on(row, col, n, side);
    let geometry = FlashGeometry::with_side(&[light], n, side, DType::F32, &device)?;
    Ok(Input {
        photo,
        size: n,
        highlight,
        fov,
        side,
        texel: side / n as f64,
        light,
        geometry,
        rho2: camera::rho_squared(n)?,
    })
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

/// Where a refinement starts: raw maps, log radiance gain, and the prior that gave them.
struct Start {
    raw: Tensor,
    log_gain: f64,
    prior: Option<PriorUsed>,
}

impl Start {
    /// Constant maps (raw zeros) and gain 1.
    fn constant(brdf: &Brdf, size: usize) -> anyhow::Result<Self> {
        Ok(Self {
            raw: Tensor::zeros((1, brdf.channels(), size, size), DType::F32, &Device::Cpu)?,
            log_gain: 0.0,
            prior: None,
        })
    }

    /// E's raw maps `raw` of the inverted material, with the inversion's gain.
    fn from_prior(
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
            prior: Some(PriorUsed {
                model: prior.dir().to_string(),
                inversion,
                maps,
            }),
        })
    }
}

/// The refinement of the module docs, from `start`.
fn refine(
    input: Input,
    name: &str,
    brdf: &Brdf,
    start: Start,
    options: &CaptureOptions,
    progress: &mut dyn FnMut(usize, f64),
) -> anyhow::Result<Capture> {
    let Start {
        raw: start_raw,
        log_gain: start_log_gain,
        prior: prior_used,
    } = start;
    let (start_raw, start_log_gain, start_vignetting, start_ambient) =
        if prior_used.is_none() && options.warmup_steps > 0 {
            let warm = fit_uniform(&input, brdf, options)?;
            let raw = warm.raw.broadcast_as(start_raw.shape())?.contiguous()?;
            (raw, warm.log_gain, warm.vignetting, warm.ambient)
        } else {
            (start_raw, start_log_gain, None, None)
        };
    let offset = prior_used.as_ref().map_or(0, |p| p.inversion.losses.len());
    let known = options.known_maps.as_ref();
    let mut held = options.uniform_maps.clone();
    if !options.relief && prior_used.is_none() {
        let relief = brdf.params().iter().map(|p| p.name);
        // A known relief stays at its values rather than flat.
        let is_known = |n: &str| known.is_some_and(|k| k.contains(n));
        held.extend(
            relief
                .filter(|n| RELIEF_MAPS.contains(n) && !is_known(n))
                .map(String::from),
        );
    }
    let tie = HeldChannels::new(brdf, &held, known, input.size, 1)?;
    let terms = CameraTerms::new(start_log_gain, start_vignetting, start_ambient)?;
    let start = Instant::now();
    let mut losses = Vec::with_capacity(options.steps);
    // A fit from constant maps spends its first steps on a smaller photo (a prior's maps
    // start at full size, where E decoded them).
    let factor = if prior_used.is_none() {
        coarse_factor(input.size, options.coarse_min_size)
    } else {
        1
    };
    let coarse_steps = options.steps.saturating_sub(options.full_size_steps);
    let (start_raw, coarse) = if factor > 1 && coarse_steps > 0 {
        let small = input.box_filtered(factor)?;
        let (_, c, _, _) = start_raw.dims4()?;
        // The warm-up's start is uniform, so it is the same at any size.
        let uniform = start_raw.narrow(2, 0, 1)?.narrow(3, 0, 1)?;
        let raw = uniform.broadcast_as((1, c, small.size, small.size))?;
        let coarse_tie = HeldChannels::new(brdf, &held, known, input.size, factor)?;
        let stage = Stage {
            input: &small,
            brdf,
            tie: &coarse_tie,
            terms: &terms,
            anchor: None,
            lr: options.lr,
            smoothness: options.smoothness,
        };
        let fitted = stage.descend(&raw, coarse_steps, name, &mut |step, loss| {
            losses.push(loss);
            progress(offset + step, loss);
        })?;
        let coarse = CoarseStage {
            size: small.size,
            steps: coarse_steps,
            seconds: start.elapsed().as_secs_f64(),
        };
        (upsample_clamped(&fitted, factor)?, Some(coarse))
    } else {
        (start_raw, None)
    };
    let start_raw = tie.apply(&start_raw)?;
    let done = losses.len();
    let stage = Stage {
        input: &input,
        brdf,
        tie: &tie,
        terms: &terms,
        anchor: prior_used
            .is_some()
            .then_some((&start_raw, options.anchor))
            .filter(|(_, weight)| *weight > 0.0),
        lr: options.lr,
        smoothness: options.smoothness,
    };
    let fitted = stage.descend(&start_raw, options.steps - done, name, &mut |step, loss| {
        losses.push(loss);
        progress(offset + done + step, loss);
    })?;
    let (maps, render) = stage.predict(&fitted)?;
    let Input {
        photo,
        highlight,
        side,
        ..
    } = input;
    let gain = terms.log_gain()?.exp();
    Ok(Capture {
        brdf: brdf.clone(),
        maps: maps.map_tensors(|t| Ok(t.detach()))?,
        photo,
        render: render.detach(),
        highlight,
        gain,
        vignetting: terms.vignetting()?,
        ambient: terms.ambient()?,
        side,
        fov: input.fov,
        losses,
        seconds: start.elapsed().as_secs_f64(),
        coarse,
        prior: prior_used,
        selection: None,
        known_maps: known.map_or_else(Vec::new, |k| {
            k.names().into_iter().map(String::from).collect()
        }),
    })
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
    lr: f64,
    smoothness: f64,
}

impl Stage<'_> {
    /// [`Input::predict`] with this stage's model and camera terms.
    fn predict(&self, raw: &Tensor) -> anyhow::Result<(MaterialMaps, Tensor)> {
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
        let mut adam = Adam::new(vars, AdamConfig::kingma(self.lr))?;
        for k in 1..=steps {
            let fitted = self.tie.apply(raw.as_tensor())?;
            let (_, predicted) = self.predict(&fitted)?;
            let mut loss = (predicted - &self.input.photo)?.abs()?.mean_all()?;
            if self.smoothness > 0.0 {
                loss = (loss + (total_variation(&fitted)? * self.smoothness)?)?;
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
        let (_, _, h, w) = x.dims4()?;
        x = separable(&x, &clamped_upsample_axis(h)?, &clamped_upsample_axis(w)?)?;
        f /= 2;
    }
    Ok(x)
}

/// Side of the uniform warm-up's image ([`CaptureOptions::warmup_steps`]): 64² box-filtered
/// texels still draw a highlight's lobe (a tenth of the photo is 6 texels) while a step
/// costs a sixteenth of a 256² one.
pub const WARMUP_SIZE: usize = 64;

/// What the uniform warm-up found: raw values (1, C, 1, 1), log gain, and the vignetting
/// strength and ambient radiance when they are fitted.
struct UniformFit {
    raw: Tensor,
    log_gain: f64,
    vignetting: Option<f64>,
    ambient: Option<f64>,
}

/// The uniform warm-up: one raw value per channel of `brdf` (constant maps) and the log
/// gain (and the vignetting and ambient light, when they are fitted), fitted by the
/// refinement's data term to the photo box-filtered to [`WARMUP_SIZE`]² (or its own size when
/// smaller) under the photo's flash, from each of [`warmup_starts`] with gain 1,
/// [`camera::START_VIGNETTING`] and [`camera::START_AMBIENT`]; the start that ends with the
/// lowest loss wins.
fn fit_uniform(input: &Input, brdf: &Brdf, options: &CaptureOptions) -> anyhow::Result<UniformFit> {
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

/// The fitted maps rendered under `lights` (flash positions on the captured square, e.g.
/// [`new_flash_positions`]), with the fitted gain, as display values: (L, 3, N, N).
pub fn relight(capture: &Capture, lights: &[Highlight]) -> anyhow::Result<Tensor> {
    render_on_square(capture, &capture.maps, capture.gain, lights)
}

/// `maps` of the capture's model rendered under `lights` on the captured square, times
/// `gain`, as display values: (L, 3, N, N).
fn render_on_square(
    capture: &Capture,
    maps: &MaterialMaps,
    gain: f64,
    lights: &[Highlight],
) -> anyhow::Result<Tensor> {
    let (_, _, n, _) = capture.photo.dims4()?;
    let geometry = FlashGeometry::with_side(lights, n, capture.side, DType::F32, &Device::Cpu)?;
    let radiance = render_radiance_with(capture.brdf.as_ref(), maps, &geometry)?;
    Ok(encode_display(&(radiance * gain)?)?)
}

/// Mean absolute difference of neighbouring texels (wrap-around) of a (B, C, H, W) tensor.
fn total_variation(x: &Tensor) -> candle_core::Result<Tensor> {
    let dx = (x.roll(-1, 3)? - x)?.abs()?.mean_all()?;
    let dy = (x.roll(-1, 2)? - x)?.abs()?.mean_all()?;
    dx + dy
}

/// What `capture.json` records.
#[derive(Debug, Serialize)]
struct CaptureRecord<'a> {
    brdf: String,
    size: usize,
    fov_degrees: f64,
    /// Where the field of view came from (given, EXIF, default).
    fov_source: FovSource,
    side: f64,
    texel_size: f64,
    highlight: &'a HighlightUsed,
    gain: f64,
    /// The fitted vignetting strength, when it was fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    vignetting: Option<f64>,
    /// The fitted ambient radiance, in the flash's units, when it was fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    ambient: Option<f64>,
    steps: usize,
    loss_first: Option<f64>,
    loss_last: Option<f64>,
    l1_encoded: f64,
    seconds: f64,
    /// The refinement's coarse stage (size, steps, seconds), when it had one.
    #[serde(skip_serializing_if = "Option::is_none")]
    coarse: Option<CoarseStage>,
    prior: Option<PriorRecord>,
    /// How the model was chosen (`--brdf auto`): every candidate's error, the tolerance.
    #[serde(skip_serializing_if = "Option::is_none")]
    selection: Option<serde_json::Value>,
    /// The maps held at values known from elsewhere, when any were.
    #[serde(skip_serializing_if = "<[String]>::is_empty")]
    known_maps: &'a [String],
}

/// What `capture.json` records of the generator prior.
#[derive(Debug, Serialize)]
struct PriorRecord {
    model: String,
    steps: usize,
    loss_first: Option<f64>,
    loss_last: Option<f64>,
    /// L1 of E's maps rendered under the photo's flash, before refinement, encoded domain.
    l1_encoded_before_refinement: f64,
    display_gain: f64,
    seconds: f64,
}

/// The renderer documents [`write_capture`] writes beside the texture set in `out/export/`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Exports {
    /// `export/material.gltf` (glTF 2.0 with `KHR_materials_specular`).
    pub gltf: bool,
    /// `export/material.mtlx` (MaterialX, `UsdPreviewSurface`).
    pub mtlx: bool,
}

/// Writes `out/material/` (the maps: PNG + EXR + material.json), `out/export/` (the
/// renderer textures of [`photomat_export::write_textures`]: base colour, roughness,
/// specular colour and, unless the normals are flat, a tangent-space `normal.png`, which a
/// height model derives from its height; plus the documents `exports` asks for),
/// `out/sheet.png` (photo | re-render | ×4 absolute error; with a prior, M's relighting of
/// the inverted material and the render of E's maps before refinement come between the
/// photo and the re-render), `out/relit.png` (the maps under the eight
/// [`new_flash_positions`], in a row) and `out/capture.json`. Returns the texture set.
pub fn write_capture(
    capture: &Capture,
    out: &Path,
    exports: Exports,
) -> anyhow::Result<photomat_export::TextureSet> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create '{}'", out.display()))?;
    let selection = capture
        .selection
        .as_ref()
        .map(serde_json::to_value)
        .transpose()?;
    save_maps(
        &out.join("material"),
        capture.brdf.as_ref(),
        &capture.maps,
        &SaveOptions {
            selection: selection.clone(),
            ..SaveOptions::default()
        },
    )?;
    let export = out.join("export");
    let textures = photomat_export::write_textures(&export, capture.brdf.as_ref(), &capture.maps)?;
    if exports.gltf {
        photomat_export::write_gltf(&export, "material", &textures)?;
    }
    if exports.mtlx {
        photomat_export::write_materialx(&export, "material", &textures)?;
    }
    let error = (&capture.render - &capture.photo)?.abs()?;
    let l1 = error.mean_all()?.to_scalar::<f32>()? as f64;
    // ×4: errors of a few % of the range must show.
    let mut panels = vec![capture.photo.clone()];
    let mut prior_record = None;
    if let Some(prior) = &capture.prior {
        let inversion = &prior.inversion;
        let (_, _, n, _) = capture.photo.dims4()?;
        let (row, col) = capture.highlight.pixel;
        let photo_flash = Highlight::from_pixel_on(row, col, n, capture.side);
        let before = render_on_square(
            capture,
            &prior.maps,
            inversion.display_gain.powf(DISPLAY_GAMMA),
            &[photo_flash],
        )?;
        let l1_before = (&before - &capture.photo)?
            .abs()?
            .mean_all()?
            .to_scalar::<f32>()? as f64;
        panels.push(inversion.relit.clone());
        panels.push(before);
        prior_record = Some(PriorRecord {
            model: prior.model.clone(),
            steps: inversion.losses.len(),
            loss_first: inversion.losses.first().copied(),
            loss_last: inversion.losses.last().copied(),
            l1_encoded_before_refinement: l1_before,
            display_gain: inversion.display_gain,
            seconds: inversion.seconds,
        });
    }
    panels.push(capture.render.clone());
    panels.push((error * 4.0)?.clamp(0.0, 1.0)?);
    let row = panels
        .iter()
        .map(|t| PlanarImage::from_tensor(&t.squeeze(0)?))
        .collect::<photomat_core::Result<Vec<_>>>()?;
    write_png(&out.join("sheet.png"), &grid(&[row], 0.0)?, PngBits::Eight)?;
    let relit = relight(capture, &new_flash_positions(capture.side))?.clamp(0.0, 1.0)?;
    let relit = PlanarImage::batch_from_tensor(&relit)?;
    write_png(
        &out.join("relit.png"),
        &grid(&[relit], 0.0)?,
        PngBits::Eight,
    )?;
    let (_, _, n, _) = capture.photo.dims4()?;
    let record = CaptureRecord {
        brdf: capture.brdf.name(),
        size: n,
        fov_degrees: capture.fov.degrees,
        fov_source: capture.fov.source,
        side: capture.side,
        texel_size: capture.side / n as f64,
        highlight: &capture.highlight,
        gain: capture.gain,
        vignetting: capture.vignetting,
        ambient: capture.ambient,
        steps: capture.losses.len(),
        loss_first: capture.losses.first().copied(),
        loss_last: capture.losses.last().copied(),
        l1_encoded: l1,
        seconds: capture.seconds,
        coarse: capture.coarse,
        prior: prior_record,
        selection,
        known_maps: &capture.known_maps,
    };
    write_atomic(
        &out.join("capture.json"),
        &serde_json::to_vec_pretty(&record)?,
    )?;
    Ok(textures)
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
