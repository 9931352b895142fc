//! How a photo is fitted: [`CaptureOptions`], every setting of a capture with its default
//! and the measurement that chose it (docs/capture.md, "Fit").

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use photomat_core::MaterialMaps;

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
    /// Set (e.g. by a signal handler) to stop the fit after the current step: the pipeline
    /// then fails with [`Stopped`]. Default none.
    pub stop: Option<Arc<AtomicBool>>,
}

/// The error of a capture whose [`CaptureOptions::stop`] was set: nothing was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stopped;

impl std::fmt::Display for Stopped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("the capture was stopped before it finished")
    }
}

impl std::error::Error for Stopped {}

impl CaptureOptions {
    /// Fails with [`Stopped`] when [`Self::stop`] is set.
    pub fn check_stop(&self) -> anyhow::Result<()> {
        match &self.stop {
            Some(flag) if flag.load(Ordering::SeqCst) => Err(Stopped.into()),
            _ => Ok(()),
        }
    }
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
            stop: None,
        }
    }
}
