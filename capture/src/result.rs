//! What a capture found: the fitted maps and camera terms, the photo as fitted, how the
//! highlight was found, and what a prior or an automatic choice of model did.

use candle_core::Tensor;
use photomat_core::{Brdf, MaterialMaps};
use photomat_estimator::model_choice::Selection;
use serde::Serialize;

use crate::field_of_view::FieldOfView;
use crate::prior::Inversion;

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
    /// The relief prior, when one gave the start.
    pub relief_prior: Option<ReliefPriorUsed>,
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

/// What the relief prior of a capture predicted.
#[derive(Clone)]
pub struct ReliefPriorUsed {
    /// The prior's folder.
    pub model: String,
    /// Its maps of the photo, before refinement (1, C, N, N), in the capture's model.
    pub maps: MaterialMaps,
    /// The exposure gain that fits its maps' render to the photo.
    pub gain: f64,
    /// Wall seconds of its prediction.
    pub seconds: f64,
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
