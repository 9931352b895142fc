//! The phone camera of the flash-photo simulator: how the light reaching the lens becomes the
//! display values of a photo.
//!
//! A phone flash photo passes through a lens, a sensor and an image signal processor (ISP).
//! [`CameraModel::develop`] follows that order, per texel p and channel c (linear values are
//! relative to the renderer's unit: a flat white Lambertian texel straight under the flash
//! reflects 1):
//!
//! ```text
//! light   L_c(p) = w_c · ( beam(p) · F_c(p)  +  ambient · A_c(p) )
//! lens    s_c(p) = exposure · V(p) · L_c(p)
//! sensor  r_c(p) = clip( s + √(σ²·s + (ρσ)²) · N(0, 1), 0, 1 )
//! ISP     y_c(p) = tone(r_c(p))                       ∈ [0, 1]; 8-bit quantisation on writing
//! ```
//!
//! - `F`: the analytic renderer's radiance (inverse-square and cosine falloff included).
//! - `beam(p) = cos^k β`: angular profile of the flash LED, β the angle at the flash between the
//!   ray to p and the ray to the image centre (the phone points at the centre of its photo);
//!   `k` = `flash_falloff`, 0 for the renderer's isotropic point light.
//! - `ambient · A`: a dim, uniform, white sky of radiance `ambient` (in flash units). A surface
//!   under a uniform sky reflects its directional albedo: exactly `ρ_d` for the Lambert lobe and
//!   ≈ F0 for each GGX lobe (Fresnel rise at grazing angles and multiple-scattering loss
//!   neglected), so `A = diffuse + Σ specular lobes' F0` ([`super::scene`]).
//! - `w`: white-balance error, per-channel gains on the light (the ISP's estimate of the flash
//!   colour is slightly off); applied before the sensor so clipped highlights stay neutral.
//! - `V(p) = 1 − v + v·cos⁴θ`: residual lens vignetting after the ISP's lens-shading correction,
//!   the natural cos⁴ law about the image centre for a camera at the flash height, mixed in with
//!   strength `v` = `vignetting`.
//! - Sensor noise: Poisson–Gaussian in linear space (Foi et al. 2008, "Practical
//!   Poissonian-Gaussian noise modeling"), the Poisson part in its Gaussian approximation:
//!   variance `σ²·s` (shot noise, σ = `noise_sigma` is the noise at full scale) plus a
//!   signal-independent read noise of standard deviation `ρσ`, ρ = [`READ_NOISE_RATIO`]. The
//!   channels' noise is correlated ([`NOISE_CHANNEL_CORRELATION`]): demosaicing spreads each
//!   photosite's noise over R, G and B, and the ISP's chroma denoising leaves mostly grey
//!   grain. The sensor saturates at 1.
//! - `tone`: the ISP's tone curve ([`ToneCurve`]): gamma 2.2 (what PhotoMat assumes photos
//!   are) or the sRGB curve, optionally followed by a mild S-curve.
//!
//! [`CameraModel::ideal`] switches everything but the gamma-2.2 curve off, so an ideal photo is
//! exactly the renderer's [`photomat_core::encode_display`] output. [`PhoneCamera`] draws a
//! plausible camera per photo.

use std::fmt;
use std::str::FromStr;

use photomat_core::flash::texel_center_on;
use photomat_core::image_io::PlanarImage;
use photomat_core::render::{DISPLAY_GAMMA, ENCODE_FLOOR};
use photomat_core::{Error, Highlight, Result};
use rand::Rng;

use super::random::{log_uniform, standard_normal, uniform};

/// Read-noise standard deviation as a fraction of `noise_sigma`: phone sensors at base ISO
/// are shot-noise limited except in the deepest shadows.
pub const READ_NOISE_RATIO: f64 = 0.1;

/// Correlation of the three channels' noise at one pixel (each channel keeps its variance):
/// phone JPEGs show luminance grain with little colour speckle.
pub const NOISE_CHANNEL_CORRELATION: f64 = 0.75;

/// Rec. 709 luminance weights, used by the exposure meter.
const LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Base curve of a [`ToneCurve`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ToneKind {
    /// `x^(1/2.2)`, with the renderer's [`ENCODE_FLOOR`]: PhotoMat's assumption for photos.
    Gamma22,
    /// The sRGB transfer function (IEC 61966-2-1): linear toe below 0.0031308, then
    /// `1.055·x^(1/2.4) − 0.055`.
    Srgb,
}

/// The ISP's tone curve: a base curve followed by the S-curve
/// `y + c·y·(1 − y)·(2y − 1)` of contrast `c` (fixes 0, ½ and 1; midtone slope `1 + c/2`,
/// monotone for c < 1).
///
/// Written in `simulation.json` as a string: `gamma2.2`, `srgb`, or with an S-curve
/// `srgb+s0.12` (base, `+s`, contrast).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(into = "String", try_from = "String")]
pub struct ToneCurve {
    pub kind: ToneKind,
    /// S-curve contrast c ∈ [0, 1); 0 for none.
    pub contrast: f64,
}

impl ToneCurve {
    /// Plain gamma 2.2, PhotoMat's display encoding.
    pub const GAMMA22: ToneCurve = ToneCurve {
        kind: ToneKind::Gamma22,
        contrast: 0.0,
    };

    /// Plain sRGB.
    pub const SRGB: ToneCurve = ToneCurve {
        kind: ToneKind::Srgb,
        contrast: 0.0,
    };

    /// Display value of the linear value `x` (clamped to [0, 1] first).
    pub fn apply(&self, x: f64) -> f64 {
        let base = match self.kind {
            // The floor keeps the curve identical to `encode_display` (see ENCODE_FLOOR).
            ToneKind::Gamma22 => x.clamp(ENCODE_FLOOR, 1.0).powf(1.0 / DISPLAY_GAMMA),
            ToneKind::Srgb => {
                let x = x.clamp(0.0, 1.0);
                if x <= 0.003_130_8 {
                    12.92 * x
                } else {
                    1.055 * x.powf(1.0 / 2.4) - 0.055
                }
            }
        };
        base + self.contrast * base * (1.0 - base) * (2.0 * base - 1.0)
    }

    fn validate(&self) -> Result<()> {
        if !(0.0..1.0).contains(&self.contrast) {
            return Err(Error::Invalid(format!(
                "tone curve contrast must lie in [0, 1) (the S-curve is monotone there), got {}",
                self.contrast
            )));
        }
        Ok(())
    }
}

impl fmt::Display for ToneCurve {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let base = match self.kind {
            ToneKind::Gamma22 => "gamma2.2",
            ToneKind::Srgb => "srgb",
        };
        if self.contrast == 0.0 {
            write!(f, "{base}")
        } else {
            write!(f, "{base}+s{}", self.contrast)
        }
    }
}

impl FromStr for ToneCurve {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Self, String> {
        let (base, contrast) = match text.split_once("+s") {
            Some((base, c)) => (
                base,
                c.parse::<f64>()
                    .map_err(|_| format!("tone curve '{text}': '{c}' is not a contrast"))?,
            ),
            None => (text, 0.0),
        };
        let kind = match base {
            "gamma2.2" => ToneKind::Gamma22,
            "srgb" => ToneKind::Srgb,
            other => {
                return Err(format!(
                    "unknown tone curve '{other}' (known: gamma2.2, srgb, optionally +sC)"
                ));
            }
        };
        let curve = ToneCurve { kind, contrast };
        curve.validate().map_err(|e| e.to_string())?;
        Ok(curve)
    }
}

impl From<ToneCurve> for String {
    fn from(curve: ToneCurve) -> String {
        curve.to_string()
    }
}

impl TryFrom<String> for ToneCurve {
    type Error = String;

    fn try_from(text: String) -> std::result::Result<Self, String> {
        text.parse()
    }
}

/// What reaches the lens: the flash-lit radiance and what the ambient light needs.
///
/// # Shapes
/// `flash` and `ambient_reflectance`: (3, S, S) planar images over a centred square of side
/// `side` (2 for a whole photo, docs/datasets.md), flash at `highlight`, height 1.
#[derive(Debug, Clone)]
pub struct SceneRadiance {
    /// Linear radiance under the flash, from the analytic renderer.
    pub flash: PlanarImage,
    /// Reflectance under a uniform white sky (see the module docs).
    pub ambient_reflectance: PlanarImage,
    /// Flash position in plane coordinates.
    pub highlight: Highlight,
    /// Side of the photographed square in world units.
    pub side: f64,
}

impl SceneRadiance {
    fn validate(&self) -> Result<usize> {
        let (f, a) = (&self.flash, &self.ambient_reflectance);
        if f.channels != 3 || f.height != f.width {
            return Err(Error::Invalid(format!(
                "the camera needs a square RGB radiance image, got {}×{}×{} (C×H×W)",
                f.channels, f.height, f.width
            )));
        }
        if (a.channels, a.height, a.width) != (f.channels, f.height, f.width) {
            return Err(Error::Invalid(format!(
                "ambient reflectance of {}×{}×{} for a radiance image of {}×{}×{} (C×H×W)",
                a.channels, a.height, a.width, f.channels, f.height, f.width
            )));
        }
        if !(self.side.is_finite() && self.side > 0.0) {
            return Err(Error::Invalid(format!(
                "the photographed square needs a positive side, got {}",
                self.side
            )));
        }
        Ok(f.height)
    }
}

/// One photo's camera settings: every parameter of the module's pipeline. Serialised as the
/// `camera` record of `simulation.json` (docs/datasets.md).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraModel {
    /// Linear gain from radiance to sensor signal (1: the renderer's unit fills the sensor).
    pub exposure: f64,
    /// Gains on the light's R, G, B (the white-balance error); G is 1 for a phone camera.
    pub white_balance: [f64; 3],
    /// Strength v ∈ [0, 1] of the cos⁴ vignetting.
    pub vignetting: f64,
    /// Exponent k ≥ 0 of the flash's cos^k beam profile (0: isotropic).
    pub flash_falloff: f64,
    /// Radiance of the uniform ambient sky, in flash units (0: dark room).
    pub ambient: f64,
    /// Sensor noise standard deviation at full-scale signal (0: noiseless).
    pub noise_sigma: f64,
    /// The ISP's tone curve.
    pub tone_curve: ToneCurve,
}

impl CameraModel {
    /// A perfect camera: exposure 1, neutral white balance, no vignetting, isotropic flash, no
    /// ambient light, no noise, plain gamma 2.2. Its photos are the renderer's display
    /// encoding (up to the 8-bit quantisation of the file).
    pub fn ideal() -> Self {
        Self {
            exposure: 1.0,
            white_balance: [1.0; 3],
            vignetting: 0.0,
            flash_falloff: 0.0,
            ambient: 0.0,
            noise_sigma: 0.0,
            tone_curve: ToneCurve::GAMMA22,
        }
    }

    /// Check every parameter's range; errors name the parameter.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str, v: f64| {
            Err(Error::Invalid(format!(
                "camera {what} = {v} is out of range"
            )))
        };
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return bad("exposure (must be positive)", self.exposure);
        }
        if let Some(&w) = self
            .white_balance
            .iter()
            .find(|w| !(w.is_finite() && **w > 0.0))
        {
            return bad("white balance gain (must be positive)", w);
        }
        if !(0.0..=1.0).contains(&self.vignetting) {
            return bad("vignetting (must lie in [0, 1])", self.vignetting);
        }
        if !(self.flash_falloff.is_finite() && self.flash_falloff >= 0.0) {
            return bad("flash_falloff (must be ≥ 0)", self.flash_falloff);
        }
        if !(self.ambient.is_finite() && self.ambient >= 0.0) {
            return bad("ambient (must be ≥ 0)", self.ambient);
        }
        if !(self.noise_sigma.is_finite() && self.noise_sigma >= 0.0) {
            return bad("noise_sigma (must be ≥ 0)", self.noise_sigma);
        }
        self.tone_curve.validate()
    }

    /// The photo's display values in [0, 1]: the module's pipeline applied to `scene`, noise
    /// drawn from `rng` (nothing is drawn when `noise_sigma` is 0).
    ///
    /// # Shapes
    /// (3, S, S) in, (3, S, S) out.
    pub fn develop(&self, scene: &SceneRadiance, rng: &mut impl Rng) -> Result<PlanarImage> {
        self.validate()?;
        let size = scene.validate()?;
        let plane = size * size;
        let flash_pos = scene.highlight.flash_position();
        // Beam axis: from the flash towards the image centre (the origin).
        let axis = (-flash_pos).normalize();
        let mut out = PlanarImage::filled(3, size, size, 0.0);
        for row in 0..size {
            for col in 0..size {
                let p = texel_center_on(row, col, size, scene.side);
                let t = row * size + col;
                let cos_beam = (p - flash_pos).normalize().dot(axis);
                // A texel behind the beam's axis plane gets no flash light (never the case for
                // highlights inside the photo: every texel lies within 90° of the axis).
                let beam = if self.flash_falloff == 0.0 {
                    1.0
                } else {
                    cos_beam.max(0.0).powf(self.flash_falloff)
                };
                let h2 = photomat_core::flash::FLASH_HEIGHT.powi(2);
                let cos2 = h2 / (h2 + p.x * p.x + p.y * p.y);
                let vignette = 1.0 - self.vignetting + self.vignetting * cos2 * cos2;
                // Unit-variance noise per channel with correlation NOISE_CHANNEL_CORRELATION:
                // a shared draw plus an independent one per channel (none drawn when noiseless).
                let noise: [f64; 3] = if self.noise_sigma > 0.0 {
                    let corr = NOISE_CHANNEL_CORRELATION;
                    let shared = corr.sqrt() * standard_normal(rng);
                    let own = (1.0 - corr).sqrt();
                    [(); 3].map(|_| shared + own * standard_normal(rng))
                } else {
                    [0.0; 3]
                };
                for (c, (&gain, &z)) in self.white_balance.iter().zip(&noise).enumerate() {
                    let i = c * plane + t;
                    let light = gain
                        * (beam * scene.flash.data[i] as f64
                            + self.ambient * scene.ambient_reflectance.data[i] as f64);
                    // Radiance is ≥ 0; the max only guards the square root against a
                    // plugin's −0 or rounding.
                    let signal = (self.exposure * vignette * light).max(0.0);
                    let sigma2 = self.noise_sigma * self.noise_sigma;
                    let std = (sigma2 * (signal + READ_NOISE_RATIO * READ_NOISE_RATIO)).sqrt();
                    // The sensor saturates at full scale and counts no negative light.
                    let sensed = (signal + std * z).clamp(0.0, 1.0);
                    out.data[i] = self.tone_curve.apply(sensed) as f32;
                }
            }
        }
        Ok(out)
    }
}

/// A distribution of phone cameras: [`PhoneCamera::sample`] draws one [`CameraModel`] per
/// photo. Ranges are inclusive; "log" ranges are drawn log-uniformly. Defaults describe a
/// phone with a flash LED at 10–30 cm from the material, in a dim room.
#[derive(Debug, Clone, PartialEq)]
pub struct PhoneCamera {
    /// Auto-exposure: the meter scales the exposure by `(target / m)^strength`, m the mean
    /// luminance of the light over the central half of the frame (centre-weighted metering),
    /// gain clamped to [`Self::metering_gain_range`]. Default target 0.25: a mid-grey (ρ ≈ 0.3)
    /// material meters to exposure ≈ 1.
    pub metering_target: f64,
    /// Metering strength (0: fixed exposure 1; 1: full compensation). Default 0.5: phones
    /// brighten dark materials and darken white ones, but not all the way.
    pub metering_strength: f64,
    /// Clamp of the metering gain (default [¼, 4]: a black material meters m ≈ 0, whose gain
    /// would be unbounded).
    pub metering_gain_range: (f64, f64),
    /// Log range of the random exposure error on top of the meter (default 0.8–1.25).
    pub exposure_jitter: (f64, f64),
    /// Half-width of the uniform R and B white-balance gains around 1 (default 0.05).
    pub white_balance_jitter: f64,
    /// Range of the vignetting strength v (default 0.1–0.45: 20–40 % residual corner falloff).
    pub vignetting: (f64, f64),
    /// Range of the beam-profile exponent k (default 0–1.5).
    pub flash_falloff: (f64, f64),
    /// Range of the ambient sky radiance (default 0–0.04: the flash dominates).
    pub ambient: (f64, f64),
    /// Log range of the full-scale noise σ (default 0.003–0.02: base ISO to a dim-room ISO).
    pub noise_sigma: (f64, f64),
    /// Probability of the sRGB base curve rather than gamma 2.2 (default 0.5).
    pub srgb_probability: f64,
    /// Range of the S-curve contrast (default 0–0.2: mild).
    pub contrast: (f64, f64),
}

impl Default for PhoneCamera {
    fn default() -> Self {
        Self {
            metering_target: 0.25,
            metering_strength: 0.5,
            metering_gain_range: (0.25, 4.0),
            exposure_jitter: (0.8, 1.25),
            white_balance_jitter: 0.05,
            vignetting: (0.1, 0.45),
            flash_falloff: (0.0, 1.5),
            ambient: (0.0, 0.04),
            noise_sigma: (0.003, 0.02),
            srgb_probability: 0.5,
            contrast: (0.0, 0.2),
        }
    }
}

impl PhoneCamera {
    /// Draw the camera of one photo of `scene` (the meter looks at the scene). Draw order is
    /// fixed: ambient, exposure error, white balance, vignetting, beam, noise, tone curve.
    pub fn sample(&self, scene: &SceneRadiance, rng: &mut impl Rng) -> Result<CameraModel> {
        let size = scene.validate()?;
        let ambient = uniform(rng, self.ambient);
        let jitter = log_uniform(rng, self.exposure_jitter);
        let wb_range = (-self.white_balance_jitter, self.white_balance_jitter);
        let red = 1.0 + uniform(rng, wb_range);
        let blue = 1.0 + uniform(rng, wb_range);
        let white_balance = [red, 1.0, blue];
        let vignetting = uniform(rng, self.vignetting);
        let flash_falloff = uniform(rng, self.flash_falloff);
        let noise_sigma = log_uniform(rng, self.noise_sigma);
        let kind = if rng.random::<f64>() < self.srgb_probability {
            ToneKind::Srgb
        } else {
            ToneKind::Gamma22
        };
        // Rounded to 0.001: the curve's name in simulation.json stays short (`srgb+s0.126`).
        let contrast = (uniform(rng, self.contrast) * 1000.0).round() / 1000.0;

        // Centre-weighted metering: mean luminance over the central half of the frame.
        let (lo, hi) = (size / 4, size - size / 4);
        let plane = size * size;
        let mut sum = 0.0;
        for row in lo..hi {
            for col in lo..hi {
                let t = row * size + col;
                sum += (0..3)
                    .map(|c| {
                        LUMINANCE[c]
                            * (scene.flash.data[c * plane + t] as f64
                                + ambient * scene.ambient_reflectance.data[c * plane + t] as f64)
                    })
                    .sum::<f64>();
            }
        }
        let mean = sum / ((hi - lo) * (hi - lo)).max(1) as f64;
        let (gain_lo, gain_hi) = self.metering_gain_range;
        // A mean of 0 (black material) gives an infinite ratio that the clamp bounds.
        let gain = (self.metering_target / mean)
            .powf(self.metering_strength)
            .clamp(gain_lo, gain_hi);
        let camera = CameraModel {
            exposure: gain * jitter,
            white_balance,
            vignetting,
            flash_falloff,
            ambient,
            noise_sigma,
            tone_curve: ToneCurve { kind, contrast },
        };
        camera.validate()?;
        Ok(camera)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::random::photo_rng;

    fn flat_scene(size: usize, value: f32) -> SceneRadiance {
        SceneRadiance {
            flash: PlanarImage::filled(3, size, size, value),
            ambient_reflectance: PlanarImage::filled(3, size, size, 1.0),
            highlight: Highlight::CENTER,
            side: 2.0,
        }
    }

    #[test]
    fn tone_curve_names_round_trip() {
        for text in ["gamma2.2", "srgb", "srgb+s0.125", "gamma2.2+s0.05"] {
            let curve: ToneCurve = text.parse().unwrap();
            assert_eq!(curve.to_string(), text);
        }
        assert!("srgb+s1.5".parse::<ToneCurve>().is_err());
        assert!("linear".parse::<ToneCurve>().unwrap_err().contains("known"));
    }

    #[test]
    fn tone_curves_fix_black_and_white_and_are_monotone() {
        for curve in [
            ToneCurve::GAMMA22,
            ToneCurve::SRGB,
            ToneCurve {
                kind: ToneKind::Srgb,
                contrast: 0.2,
            },
        ] {
            assert!(curve.apply(0.0) < 0.01, "{curve}");
            assert!((curve.apply(1.0) - 1.0).abs() < 1e-12, "{curve}");
            let values: Vec<f64> = (0..=1000).map(|i| curve.apply(i as f64 / 1000.0)).collect();
            assert!(values.windows(2).all(|w| w[1] > w[0]), "{curve}");
        }
        // The S-curve raises contrast around mid-grey: darker below ½, brighter above.
        let s = ToneCurve {
            kind: ToneKind::Gamma22,
            contrast: 0.2,
        };
        let x_low = 0.3f64.powf(2.2);
        assert!(s.apply(x_low) < ToneCurve::GAMMA22.apply(x_low));
        let x_high = 0.7f64.powf(2.2);
        assert!(s.apply(x_high) > ToneCurve::GAMMA22.apply(x_high));
    }

    #[test]
    fn ideal_camera_is_the_display_encoding_and_draws_nothing() {
        let scene = flat_scene(4, 0.3);
        let mut rng = photo_rng(0, 0);
        let photo = CameraModel::ideal().develop(&scene, &mut rng).unwrap();
        let expected = 0.3f64.powf(1.0 / 2.2) as f32;
        assert!(photo.data.iter().all(|&v| (v - expected).abs() < 1e-6));
        // No noise drawn: the stream is untouched.
        assert_eq!(rng.random::<u64>(), photo_rng(0, 0).random::<u64>());
    }

    #[test]
    fn camera_vignetting_darkens_corners_only() {
        let scene = flat_scene(16, 0.5);
        let camera = CameraModel {
            vignetting: 0.4,
            ..CameraModel::ideal()
        };
        let photo = camera.develop(&scene, &mut photo_rng(0, 0)).unwrap();
        let centre = photo.get(0, 8, 8);
        let corner = photo.get(0, 0, 0);
        assert!(corner < centre - 0.05, "corner {corner}, centre {centre}");
        // Near the centre the cos⁴ law is flat: within 1 % of the ideal value.
        let ideal = 0.5f32.powf(1.0 / 2.2);
        assert!((centre - ideal).abs() < 0.01 * ideal, "{centre} vs {ideal}");
    }

    #[test]
    fn camera_noise_variance_follows_the_signal() {
        // Linear-space variance σ²·(s + ρ²) measured through gamma 1 (contrast 0, x → x^(1/2.2)
        // inverted exactly below).
        let sigma = 0.02;
        let camera = CameraModel {
            noise_sigma: sigma,
            ..CameraModel::ideal()
        };
        for signal in [0.05f32, 0.5] {
            let photo = camera
                .develop(&flat_scene(128, signal), &mut photo_rng(1, 0))
                .unwrap();
            let linear: Vec<f64> = photo
                .data
                .iter()
                .map(|&y| (y as f64).powf(DISPLAY_GAMMA))
                .collect();
            let n = linear.len() as f64;
            let mean = linear.iter().sum::<f64>() / n;
            let var = linear.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
            let expected = sigma * sigma * (signal as f64 + READ_NOISE_RATIO.powi(2));
            // 49 152 samples: the variance estimate's relative standard error is √(2/n) ≈ 0.6 %.
            assert!(
                (var / expected - 1.0).abs() < 0.05,
                "signal {signal}: variance {var}, expected {expected}"
            );
            assert!((mean - signal as f64).abs() < 1e-3);
            // Channels share NOISE_CHANNEL_CORRELATION of their noise (16 384 pixels: the
            // estimate's standard error is (1 − ρ²)/√n ≈ 0.004).
            let plane = linear.len() / 3;
            let (r, g) = (&linear[..plane], &linear[plane..2 * plane]);
            let cov = r
                .iter()
                .zip(g)
                .map(|(a, b)| (a - mean) * (b - mean))
                .sum::<f64>();
            let norm = |x: &[f64]| x.iter().map(|a| (a - mean).powi(2)).sum::<f64>().sqrt();
            let corr = cov / (norm(r) * norm(g));
            assert!(
                (corr - NOISE_CHANNEL_CORRELATION).abs() < 0.03,
                "signal {signal}: channel correlation {corr}"
            );
        }
    }

    #[test]
    fn phone_camera_meters_dark_materials_brighter() {
        let phone = PhoneCamera {
            exposure_jitter: (1.0, 1.0),
            ambient: (0.0, 0.0),
            ..PhoneCamera::default()
        };
        let dark = phone
            .sample(&flat_scene(8, 0.02), &mut photo_rng(0, 0))
            .unwrap();
        let bright = phone
            .sample(&flat_scene(8, 0.8), &mut photo_rng(0, 0))
            .unwrap();
        assert!(dark.exposure > 1.5 && bright.exposure < 1.0);
        let black = phone
            .sample(&flat_scene(8, 0.0), &mut photo_rng(0, 0))
            .unwrap();
        assert_eq!(black.exposure, phone.metering_gain_range.1);
    }
}
