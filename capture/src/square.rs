//! The photographed square: its side in world units from the camera's field of view, and the
//! flash positions a capture is relit under that the photo did not show (docs/conventions.md,
//! "A photo's field of view"; docs/capture.md, "Validation").

use photomat_core::Highlight;

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
