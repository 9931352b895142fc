//! Whether a relighting shows relief: how much of the detail in the log-ratio of two images of
//! one material, lit from either side of it, follows the derivative of the texture along the
//! lights' axis (`docs/benchmarks/relief.md`, "Does M's relighting show relief?").
//!
//! Relief under a moved light: a texel tilted towards the light brightens, so the change
//! between a light at +y and one at −y is, to first order, `∇h · (ω_a − ω_b)` — the height's
//! derivative along the lights' axis. Where the height follows the texture (grooves are dark,
//! ridges bright, as in most of the simulator's families), the detail of the log-ratio
//! `log I_a − log I_b` follows the texture's derivative along that axis, and not across it. A
//! light dependence that is not relief — the texture's contrast changing with the angle to the
//! light, which is all a per-texel MLP needs to learn to fool a discriminator — makes the
//! log-ratio follow the texture itself, not its derivative.
//!
//! Measure: display images → linear luminance (gamma 2.2, `docs/conventions.md`) → log;
//! detail = the image minus its Gaussian blur (σ = [`DETAIL_SIGMA`] texels, wrapping); in
//! [`WINDOW`]² windows of the central ¾ of the image, the squared correlation (R²) of the
//! log-ratio's detail with (a) the mean log image's detail, (b) its derivative along the lights'
//! axis, (c) its derivative across it, averaged over the windows. (c) is the control: texture
//! derivatives correlate with the ratio only by chance across the axis. Windows, because the
//! sign of a contrast change flips between the halves nearer either light, which a global
//! correlation would cancel.

use candle_core::{DType, Tensor};
use photomat_core::flash::FlashGeometry;
use photomat_core::image_io::PlanarImage;
use photomat_core::{Error, Highlight, MaterialMaps, Result};
use photomat_generator::GanModel;
use photomat_generator::relief::{self, Edges};
use photomat_generator::train::samples::display_tiles;

/// Blur of the detail's high-pass, in texels: detail finer than about 10 texels.
pub const DETAIL_SIGMA: f64 = 4.0;
/// Side of the correlation windows, in texels.
pub const WINDOW: usize = 32;
/// Smoothing of the texture before its derivative, in texels: one texel's noise out.
const DERIVATIVE_SIGMA: f64 = 1.0;
/// Added to linear luminance before the log: an 8-bit black (1/255 display ≈ 5e-6 linear)
/// would otherwise turn quantisation into large log-ratios.
const LOG_FLOOR: f64 = 1e-3;
/// Distance of either light's highlight from the centre, as a fraction of the material's side.
pub const LIGHT_OFFSET: f64 = 0.3;

/// Mean windowed R² of the log-ratio's detail (module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct ReliefSignature {
    /// With the texture's detail itself (contrast that changes with the light).
    pub texture: f64,
    /// With the texture's derivative along the lights' axis (relief).
    pub along: f64,
    /// With its derivative across the axis (the control).
    pub across: f64,
    /// For a model whose M has a relief projection ([`photomat_generator::relief`]): the rms
    /// angle of its normals from +z, in degrees (how much relief M shades with).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub m_relief_rms_degrees: Option<f64>,
}

/// Row-major H×W luminance planes.
struct Plane {
    h: usize,
    w: usize,
    v: Vec<f64>,
}

impl Plane {
    /// ln(linear luminance + [`LOG_FLOOR`]) of a display RGB image in [0, 1].
    fn log_luminance(image: &PlanarImage) -> Result<Self> {
        if image.channels != 3 {
            return Err(Error::Invalid(format!(
                "relief signature: images need 3 channels, got {}",
                image.channels
            )));
        }
        let n = image.height * image.width;
        let weights = [0.2126, 0.7152, 0.0722];
        let v = (0..n)
            .map(|i| {
                let lin: f64 = (0..3)
                    .map(|c| weights[c] * (image.data[c * n + i].clamp(0.0, 1.0) as f64).powf(2.2))
                    .sum();
                (lin + LOG_FLOOR).ln()
            })
            .collect();
        Ok(Self {
            h: image.height,
            w: image.width,
            v,
        })
    }

    fn map2(&self, other: &Plane, f: impl Fn(f64, f64) -> f64) -> Plane {
        Plane {
            h: self.h,
            w: self.w,
            v: self
                .v
                .iter()
                .zip(&other.v)
                .map(|(&a, &b)| f(a, b))
                .collect(),
        }
    }

    /// Separable Gaussian blur of σ texels, wrapping at the edges.
    fn blur(&self, sigma: f64) -> Plane {
        let radius = (3.0 * sigma).ceil() as isize;
        let kernel: Vec<f64> = (-radius..=radius)
            .map(|d| (-(d * d) as f64 / (2.0 * sigma * sigma)).exp())
            .collect();
        let total: f64 = kernel.iter().sum();
        let (h, w) = (self.h as isize, self.w as isize);
        let pass = |src: &[f64], along_rows: bool| -> Vec<f64> {
            let mut out = vec![0.0; src.len()];
            for r in 0..h {
                for c in 0..w {
                    let mut s = 0.0;
                    for (k, d) in (-radius..=radius).enumerate() {
                        let (rr, cc) = if along_rows {
                            ((r + d).rem_euclid(h), c)
                        } else {
                            (r, (c + d).rem_euclid(w))
                        };
                        s += kernel[k] * src[(rr * w + cc) as usize];
                    }
                    out[(r * w + c) as usize] = s / total;
                }
            }
            out
        };
        let v = pass(&pass(&self.v, false), true);
        Plane {
            h: self.h,
            w: self.w,
            v,
        }
    }

    /// The plane minus its blur: detail finer than σ.
    fn detail(&self, sigma: f64) -> Plane {
        self.map2(&self.blur(sigma), |a, b| a - b)
    }

    /// Central differences along rows (`rows = true`) or columns, wrapping.
    fn derivative(&self, rows: bool) -> Plane {
        let (h, w) = (self.h, self.w);
        let v = (0..h * w)
            .map(|i| {
                let (r, c) = (i / w, i % w);
                let (next, prev) = if rows {
                    (((r + 1) % h) * w + c, ((r + h - 1) % h) * w + c)
                } else {
                    (r * w + (c + 1) % w, r * w + (c + w - 1) % w)
                };
                0.5 * (self.v[next] - self.v[prev])
            })
            .collect();
        Plane { h, w, v }
    }
}

/// Squared correlation of `y` and `x` over the window at (r0, c0).
fn window_r2(y: &Plane, x: &Plane, r0: usize, c0: usize) -> f64 {
    let idx = || (r0..r0 + WINDOW).flat_map(move |r| (c0..c0 + WINDOW).map(move |c| r * y.w + c));
    let n = (WINDOW * WINDOW) as f64;
    let (my, mx) = (
        idx().map(|i| y.v[i]).sum::<f64>() / n,
        idx().map(|i| x.v[i]).sum::<f64>() / n,
    );
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for i in idx() {
        let (a, b) = (y.v[i] - my, x.v[i] - mx);
        sxy += a * b;
        sxx += b * b;
        syy += a * a;
    }
    // Flat windows (no detail at all) carry no evidence either way: R² 0.
    if sxx <= 0.0 || syy <= 0.0 {
        0.0
    } else {
        sxy * sxy / (sxx * syy)
    }
}

/// The signature of two display images of one material, `lit_up` under a light at +y (up)
/// and `lit_down` under its mirror image at −y (module docs).
///
/// # Shapes
/// two (3, S, S) images, S ≥ 2·[`WINDOW`].
pub fn relief_signature(lit_up: &PlanarImage, lit_down: &PlanarImage) -> Result<ReliefSignature> {
    let (a, b) = (
        Plane::log_luminance(lit_up)?,
        Plane::log_luminance(lit_down)?,
    );
    if (a.h, a.w) != (b.h, b.w) || a.h != a.w || a.h < 2 * WINDOW {
        return Err(Error::Invalid(format!(
            "relief signature: two square images of one size ≥ {} needed, got {}×{} and {}×{}",
            2 * WINDOW,
            a.h,
            a.w,
            b.h,
            b.w
        )));
    }
    let ratio = a.map2(&b, |x, y| x - y).detail(DETAIL_SIGMA);
    let texture = a.map2(&b, |x, y| 0.5 * (x + y)).detail(DETAIL_SIGMA);
    let smooth = texture.blur(DERIVATIVE_SIGMA);
    // The lights differ along y; rows run along −y, so the row derivative is the one along.
    let (along, across) = (smooth.derivative(true), smooth.derivative(false));
    let (lo, hi) = (a.h / 8, a.h - a.h / 8);
    let mut sum = ReliefSignature::default();
    let mut windows = 0usize;
    for r0 in (lo..hi.saturating_sub(WINDOW - 1)).step_by(WINDOW) {
        for c0 in (lo..hi.saturating_sub(WINDOW - 1)).step_by(WINDOW) {
            sum.texture += window_r2(&ratio, &texture, r0, c0);
            sum.along += window_r2(&ratio, &along, r0, c0);
            sum.across += window_r2(&ratio, &across, r0, c0);
            windows += 1;
        }
    }
    let n = windows.max(1) as f64;
    Ok(ReliefSignature {
        texture: sum.texture / n,
        along: sum.along / n,
        across: sum.across / n,
        m_relief_rms_degrees: None,
    })
}

/// `maps` without relief: a +z normal map, or a flat height map (whichever the model takes);
/// every other map unchanged.
pub fn without_relief(maps: &MaterialMaps) -> Result<MaterialMaps> {
    let mut flat = maps.clone();
    if let Ok(normal) = maps.get("normal") {
        let z = normal.narrow(1, 2, 1)?.ones_like()?;
        flat.insert(
            "normal",
            Tensor::cat(&[z.zeros_like()?, z.zeros_like()?, z], 1)?,
        );
    }
    if let Ok(height) = maps.get("height") {
        flat.insert("height", height.ones_like()?.affine(0.5, 0.0)?);
    }
    Ok(flat)
}

/// The two lights of a signature on a material of side `side` world units: highlights at
/// (0, ±[`LIGHT_OFFSET`]·side).
pub fn signature_lights(side: f64) -> [Highlight; 2] {
    let y = LIGHT_OFFSET * side;
    [Highlight { x: 0.0, y }, Highlight { x: 0.0, y: -y }]
}

/// The mean signature of M's relighting over `count` materials of `model` sampled at `size`
/// texels (a spatial model; at the photos' texel scale), seeds derived from `seed`.
pub fn model_relief_signature(
    model: &GanModel,
    size: usize,
    count: usize,
    seed: u64,
) -> Result<ReliefSignature> {
    let config = model.config();
    let Some(texel) = config.spatial.as_ref().and_then(|s| s.texel_size) else {
        return Err(Error::Invalid(
            "the relief signature needs a spatial GAN that records its texel size".into(),
        ));
    };
    if count == 0 {
        return Err(Error::Invalid(
            "the relief signature needs a material".into(),
        ));
    }
    let side = texel * size as f64;
    let lights = signature_lights(side);
    let omega = FlashGeometry::with_side(&lights, size, side, DType::F32, model.device())?.omega;
    let mut sum = ReliefSignature::default();
    let mut squared_angles = 0.0;
    for i in 0..count as u64 {
        let features = model.features_for_seeds_at(&[seed.wrapping_add(i)], 1.0, size)?;
        if let Some(relief) = model.relight().relief() {
            let normals = relief::normals(&relief.height(&features)?, Edges::Wrap)?;
            let nz = normals
                .narrow(1, 2, 1)?
                .flatten_all()?
                .to_dtype(DType::F64)?;
            let nz = nz.to_vec1::<f64>()?;
            // acos of n_z ∈ (0, 1]; the clamp only guards rounding above 1.
            squared_angles += nz
                .iter()
                .map(|z| z.clamp(-1.0, 1.0).acos().powi(2))
                .sum::<f64>()
                / nz.len() as f64;
        }
        let images = model
            .relight()
            .forward(&features.repeat((2, 1, 1, 1))?, &omega)?;
        let tiles = display_tiles(&images)?;
        let s = relief_signature(&tiles[0], &tiles[1])?;
        sum.texture += s.texture;
        sum.along += s.along;
        sum.across += s.across;
    }
    let n = count as f64;
    Ok(ReliefSignature {
        texture: sum.texture / n,
        along: sum.along / n,
        across: sum.across / n,
        m_relief_rms_degrees: model
            .relight()
            .relief()
            .map(|_| (squared_angles / n).sqrt().to_degrees()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A display image (3, S, S) of grey `value(row, col)`.
    fn grey(size: usize, value: impl Fn(usize, usize) -> f64) -> PlanarImage {
        let plane: Vec<f32> = (0..size * size)
            .map(|i| value(i / size, i % size).clamp(0.0, 1.0) as f32)
            .collect();
        let data = [plane.clone(), plane.clone(), plane].concat();
        PlanarImage::new(3, size, size, data).unwrap()
    }

    /// A periodic bumpy texture in [−1, 1], sums of products of row and column waves, so that
    /// its derivatives along and across are uncorrelated.
    fn pattern(r: usize, c: usize, size: usize) -> f64 {
        let t = std::f64::consts::TAU / size as f64;
        ((7.0 * t * r as f64).sin() * (5.0 * t * c as f64).cos()
            + 0.5 * (11.0 * t * r as f64).cos() * (13.0 * t * c as f64).sin())
            / 1.5
    }

    #[test]
    fn lambertian_relief_follows_the_derivative_along_the_lights() {
        // Height = the texture; shading n·l with l tilted ±0.5 along y (rows grow to −y):
        // brightness 0.5·albedo·(1 − 0.5·∂h/∂y ± …) with albedo following the texture too.
        let size = 128;
        let slope = 0.8;
        let image = |sign: f64| {
            grey(size, |r, c| {
                let h = |r: usize| pattern(r % size, c, size);
                // ∂h/∂y = (h[r−1] − h[r+1]) / 2 in texels (rows grow towards −y).
                let dy = 0.5 * (h(r + size - 1) - h(r + 1));
                let (ny, nz) = (-slope * dy, 1.0);
                let l = (0.0, sign * 0.5, 1.0);
                let shade = (ny * l.1 + nz * l.2) / ((ny * ny + 1.0).sqrt() * 1.25f64.sqrt());
                let albedo = 0.5 + 0.2 * pattern(r, c, size);
                (albedo * shade.max(0.0)).powf(1.0 / 2.2)
            })
        };
        let s = relief_signature(&image(1.0), &image(-1.0)).unwrap();
        assert!(s.along > 0.8, "{s:?}");
        assert!(s.across < 0.2, "{s:?}");
    }

    #[test]
    fn contrast_that_changes_with_the_light_follows_the_texture() {
        // No relief: the texture's contrast is stronger under one light than the other.
        let size = 128;
        let image = |contrast: f64| {
            grey(size, |r, c| {
                (0.4 * (1.0 + contrast * pattern(r, c, size))).powf(1.0 / 2.2)
            })
        };
        let s = relief_signature(&image(0.5), &image(0.2)).unwrap();
        assert!(s.texture > 0.9, "{s:?}");
        assert!(s.along < 0.2 && s.across < 0.2, "{s:?}");
    }

    #[test]
    fn images_too_small_or_unmatched_are_refused() {
        let small = grey(32, |_, _| 0.5);
        assert!(relief_signature(&small, &small).is_err());
        let (a, b) = (grey(64, |_, _| 0.5), grey(96, |_, _| 0.5));
        assert!(relief_signature(&a, &b).is_err());
    }
}
