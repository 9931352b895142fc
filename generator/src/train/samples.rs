//! The sample grid a training run writes every few steps (`RUN/samples/step-NNNNNN.png`):
//! [`SAMPLE_ROWS`] fixed materials of G_ema (fixed seeds, their own noise, ψ = 1), each under
//! the four [`SAMPLE_LIGHTS`] (scaled to the data's sample side, so that a patch-trained
//! model is lit as its patches are), followed by a real crop or patch of the data set (fixed
//! draw) for comparison: a 5 × 5 [`contact_sheet`], one material per row.
//!
//! The seeds and the real crops depend only on the run seed, so grids of successive steps
//! show the same materials and crops.

use candle_core::{Device, Result, Tensor};
use photomat_core::Highlight;
use photomat_core::image_io::PlanarImage;
use photomat_core::sheet::contact_sheet;

use super::data::{FlashPlacement, TrainingData, omega_for_placements};
use super::streams::{Stream, stream_seed, stream_seeds};
use crate::GanModel;

/// Materials (rows) per grid.
pub const SAMPLE_ROWS: usize = 5;

/// The four light positions of every row: `¼·(cos θ, sin θ)` for θ = 45°, 135°, 225°, 315°
/// (the reference's relighting positions `½·(cos θ, sin θ)` on its [−1, 1] plane, in the
/// unit-square plane coordinates of docs/conventions.md), in units of the sample's side.
pub const SAMPLE_LIGHTS: [(f64, f64); 4] = [
    (0.176_776_695_296_636_9, 0.176_776_695_296_636_9),
    (-0.176_776_695_296_636_9, 0.176_776_695_296_636_9),
    (-0.176_776_695_296_636_9, -0.176_776_695_296_636_9),
    (0.176_776_695_296_636_9, -0.176_776_695_296_636_9),
];

/// Grey between the tiles (display value).
const BACKGROUND: f32 = 0.5;

/// Encoded [−1, 1] images → display tiles in [0, 1] ([`crate::relight::to_display`]).
///
/// # Shapes
/// (B, 3, R, R) → B tiles of (3, R, R).
pub fn display_tiles(images: &Tensor) -> Result<Vec<PlanarImage>> {
    let display = crate::relight::to_display(images)?;
    PlanarImage::batch_from_tensor(&display).map_err(candle_core::Error::wrap)
}

/// The grid of `model` (G_ema + M) with real crops of `data`, for the run seeded `run_seed`.
///
/// # Shapes
/// → (3, 5R + 16, 5R + 16) (four 4-pixel gaps each way).
pub fn sample_grid(
    model: &GanModel,
    data: &dyn TrainingData,
    run_seed: u64,
    device: &Device,
) -> Result<PlanarImage> {
    let r = model.config().resolution;
    let seeds = stream_seeds(run_seed, 0, Stream::Fixed, SAMPLE_ROWS);
    let features = model.features_for_seeds(&seeds, 1.0)?;
    let side = data.sample_side();
    let mut per_light = Vec::with_capacity(SAMPLE_LIGHTS.len());
    for &(x, y) in &SAMPLE_LIGHTS {
        let placement = FlashPlacement {
            highlight: Highlight::new(x * side, y * side),
            side,
        };
        let omega = omega_for_placements(&[placement; SAMPLE_ROWS], r, device)?;
        per_light.push(display_tiles(&model.relight().forward(&features, &omega)?)?);
    }
    let reals = data.reals(
        SAMPLE_ROWS,
        stream_seed(run_seed, 0, Stream::Fixed, u64::MAX),
        device,
    )?;
    let reals = display_tiles(&reals.images)?;
    let mut tiles = Vec::with_capacity(SAMPLE_ROWS * (SAMPLE_LIGHTS.len() + 1));
    for (row, real) in reals.into_iter().enumerate() {
        for light in &per_light {
            tiles.push(light[row].clone());
        }
        tiles.push(real);
    }
    contact_sheet(&tiles, BACKGROUND).map_err(candle_core::Error::wrap)
}
