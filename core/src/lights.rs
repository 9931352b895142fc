//! Sets of collocated-flash positions: the one home of every light layout photomat renders
//! or relights under (`docs/conventions.md`, "Geometry and radiometry").
//!
//! A [`LightSet`] is an ordered list of [`Highlight`]s (plane coordinates, the material spans
//! [−½, ½]², +y up). The layouts:
//! - [`LightSet::single`]: one flash;
//! - [`LightSet::orbit`]: N highlights evenly spaced on a circle of radius r around the centre,
//!   at θ_k = 2π(k + ½)/N counter-clockwise from +x (N = 4 gives the diagonals 45°, 135°, 225°,
//!   315°);
//! - [`LightSet::reference`]: the reference implementation's five evaluation lights (PhotoMat,
//!   Zhou et al. 2023): the centre, then the four diagonals at [`REFERENCE_LIGHT_RADIUS`];
//! - [`LightSet::uniform`]: `(lx, ly) ~ U(−½, ½)²`, the highlight distribution of training
//!   crops and of the GAN's fakes, drawn from a caller's seeded stream.
//!
//! [`LightSet::geometry`] builds the per-texel [`FlashGeometry`] once; the same geometry feeds
//! the relighting MLP (its ω) and the analytic renderer ([`crate::render::render_with`]).

use candle_core::{DType, Device, Tensor};

use crate::flash::{FlashGeometry, Highlight};
use crate::{Error, Result};

/// Radius of the reference's four diagonal lights: `0.5·(cos θ, sin θ)` in the reference's
/// plane coordinates, which span [−1, 1]; our plane spans [−½, ½], so ¼.
pub const REFERENCE_LIGHT_RADIUS: f64 = 0.25;

/// Default radius of an orbit in the command line's renders and relightings: far enough off
/// centre that the highlight visibly moves, close enough that it stays on the material.
pub const DEFAULT_ORBIT_RADIUS: f64 = 0.35;

/// An ordered set of flash positions.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LightSet {
    highlights: Vec<Highlight>,
}

impl LightSet {
    /// One flash at `highlight`.
    pub fn single(highlight: Highlight) -> Self {
        Self {
            highlights: vec![highlight],
        }
    }

    /// `count` highlights on a circle of radius `radius` at θ_k = 2π(k + ½)/count.
    /// Errors for a radius that is negative or not finite.
    pub fn orbit(count: usize, radius: f64) -> Result<Self> {
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(Error::Invalid(format!(
                "the orbit radius must be a finite number ≥ 0, got {radius}"
            )));
        }
        let highlights = (0..count)
            .map(|k| {
                let theta = std::f64::consts::TAU * (k as f64 + 0.5) / count as f64;
                Highlight::new(radius * theta.cos(), radius * theta.sin())
            })
            .collect();
        Ok(Self { highlights })
    }

    /// The reference's 5 lights: the centre, then the diagonals counter-clockwise from +x at
    /// [`REFERENCE_LIGHT_RADIUS`] (θ = 45°, 135°, 225°, 315°).
    pub fn reference() -> Self {
        let mut highlights = vec![Highlight::CENTER];
        for k in 0..4 {
            let theta = (45.0 + 90.0 * k as f64).to_radians();
            highlights.push(Highlight::new(
                REFERENCE_LIGHT_RADIUS * theta.cos(),
                REFERENCE_LIGHT_RADIUS * theta.sin(),
            ));
        }
        Self { highlights }
    }

    /// `count` highlights `(lx, ly) ~ U(−½, ½)²`, each coordinate `u − ½` for the next value
    /// `u ∈ [0, 1)` of `unit` (x first, then y, highlight after highlight), so a caller's
    /// seeded stream fixes the draws and keeps its own state for what it draws next.
    pub fn uniform(count: usize, mut unit: impl FnMut() -> f64) -> Self {
        let highlights = (0..count)
            .map(|_| {
                let x = unit() - 0.5;
                Highlight::new(x, unit() - 0.5)
            })
            .collect();
        Self { highlights }
    }

    /// Any list of highlights, in order (e.g. the reference five followed by held-out ones).
    pub fn from_highlights(highlights: Vec<Highlight>) -> Self {
        Self { highlights }
    }

    /// The same lights for a material of world side `side` instead of the unit square: every
    /// highlight's plane coordinates times `side`, so each keeps its place relative to the
    /// material (a spatial model's N-texel sample covers N × texel size world units).
    pub fn scaled(&self, side: f64) -> Self {
        Self {
            highlights: self.highlights.iter().map(|h| h.scaled(side)).collect(),
        }
    }

    /// The [`FlashGeometry`] of these lights, each scaled to a material of `size` texels and
    /// world side `side` ([`Self::scaled`]); side 1 is [`Self::geometry`].
    pub fn geometry_on(
        &self,
        size: usize,
        side: f64,
        dtype: DType,
        device: &Device,
    ) -> Result<FlashGeometry> {
        FlashGeometry::with_side(self.scaled(side).highlights(), size, side, dtype, device)
    }

    /// The highlights, in order.
    pub fn highlights(&self) -> &[Highlight] {
        &self.highlights
    }

    /// Number of lights.
    pub fn len(&self) -> usize {
        self.highlights.len()
    }

    /// Whether the set holds no light.
    pub fn is_empty(&self) -> bool {
        self.highlights.is_empty()
    }

    /// Per-texel geometry of every light over an R×R map of the unit square.
    ///
    /// # Shapes
    /// ω (len, 3, R, R), 1/d² (len, 1, R, R).
    pub fn geometry(&self, size: usize, dtype: DType, device: &Device) -> Result<FlashGeometry> {
        FlashGeometry::new(&self.highlights, size, dtype, device)
    }

    /// The f32 ω maps of every light over R×R samples: what the relighting MLP reads.
    ///
    /// # Shapes
    /// → (len, 3, R, R).
    pub fn omega(&self, size: usize, device: &Device) -> Result<Tensor> {
        FlashGeometry::omega_for(&self.highlights, size, device)
    }
}

impl From<Vec<Highlight>> for LightSet {
    fn from(highlights: Vec<Highlight>) -> Self {
        Self { highlights }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Highlight, (x, y): (f64, f64)) -> bool {
        (a.x - x).abs() < 1e-12 && (a.y - y).abs() < 1e-12
    }

    #[test]
    fn reference_lights_are_the_centre_and_four_diagonals() {
        let lights = LightSet::reference();
        assert_eq!(lights.len(), 5);
        assert_eq!(lights.highlights()[0], Highlight::CENTER);
        let d = REFERENCE_LIGHT_RADIUS / 2f64.sqrt();
        let expected = [(d, d), (-d, d), (-d, -d), (d, -d)];
        for (h, e) in lights.highlights()[1..].iter().zip(expected) {
            assert!(close(*h, e), "{h:?}");
        }
    }

    #[test]
    fn orbit_is_evenly_spaced_on_the_circle() {
        let hs = LightSet::orbit(4, 0.35).unwrap();
        let d = 0.35 / 2f64.sqrt();
        let expected = [(d, d), (-d, d), (-d, -d), (d, -d)];
        for (h, e) in hs.highlights().iter().zip(expected) {
            assert!(close(*h, e), "{h:?}");
        }
        for h in LightSet::orbit(7, 0.2).unwrap().highlights() {
            assert!((h.x.hypot(h.y) - 0.2).abs() < 1e-12);
        }
        assert!(LightSet::orbit(3, -1.0).is_err());
        assert!(LightSet::orbit(3, f64::NAN).is_err());
    }

    #[test]
    fn uniform_draws_x_then_y_shifted_by_a_half() {
        let mut values = [0.0, 0.25, 0.999, 0.5].into_iter();
        let lights = LightSet::uniform(2, || values.next().unwrap());
        assert_eq!(
            lights.highlights(),
            &[Highlight::new(-0.5, -0.25), Highlight::new(0.499, 0.0)]
        );
    }

    #[test]
    fn omega_is_the_geometry_direction() {
        let lights = LightSet::reference();
        let g = lights.geometry(4, DType::F32, &Device::Cpu).unwrap();
        let omega = lights.omega(4, &Device::Cpu).unwrap();
        let diff = (g.omega - omega)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert_eq!(diff, 0.0);
    }
}
