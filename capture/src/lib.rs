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
pub mod fit;
mod held;
pub mod input;
pub mod job;
pub mod options;
pub mod output;
pub mod pipeline;
pub mod prior;
pub mod relief_prior;
pub mod result;
pub mod square;
pub mod warmup;

pub use camera::CameraTerms;
pub use field_of_view::{
    DEFAULT_FOV_DEGREES, FOV_RANGE, FieldOfView, FovSource, TRAINING_FOV_DEGREES,
};
pub use fit::coarse_factor;
pub use input::SIZE_RANGE;
pub use job::{CAPTURE, CaptureJob, CaptureReport, JobOutcome, StartFrom};
pub use options::{CaptureOptions, RELIEF_MAPS, Stopped};
pub use output::{Exports, relight, write_capture};
pub use pipeline::{capture, capture_auto, capture_with_prior};
pub use prior::{GanPrior, Inversion, PriorOptions};
pub use relief_prior::{PRIOR_REFINEMENT_STEPS, capture_from_relief_prior};
pub use result::{Capture, CoarseStage, HighlightUsed, PriorUsed, ReliefPriorUsed};
pub use square::{new_flash_positions, square_side};
pub use warmup::WARMUP_SIZE;
