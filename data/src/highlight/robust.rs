//! `robust`: a highlight detector that fits the physics of a collocated flash photo.
//!
//! The paper's centroid (§"Dataset collection", [`super::paper`]) is pulled towards the image
//! centre by lens vignetting, by ambient light and by the image border cutting the flash lobe.
//! This detector instead fits what a flash photo of a flat sample looks like
//! (`docs/conventions.md`, "Radiance"; `docs/datasets.md`: the photo spans a square of side 2,
//! flash and camera at height 1).
//!
//! # Model
//! With `s = |p − l|` the distance of a plane point `p` from the point `l` under the flash, the
//! collocated flash sees every point at `cos θ = 1/√(1+s²)` and distance² `1 + s²`, so any
//! isotropic BRDF gives a radiance that depends on `s` only. Two profiles span what materials do:
//! - diffuse: `g_d(s) = cos θ / d² = (1+s²)^(−3/2)`, exact for Lambert;
//! - specular: the GGX lobe `D(θ)·cos θ` normalised to 1 at s = 0,
//!   `g_s(s; α) = (α²/(α²+s²))² · (1+s²)^(3/2)` (`tan θ = s`; Fresnel and shadowing vary by
//!   less than 2 % within the photo and are left out).
//!
//! The camera multiplies by two factors centred on the image centre rather than on `l`, which
//! are what pull the paper's centroid: the cos⁴ law of lens vignetting, mixed in with strength
//! v (`1 − v + v·cos⁴θ_c`, θ_c the angle off the optical axis), and the flash LED's beam
//! profile `cos^k β` (β the angle at the flash between the rays to p and to the image centre,
//! where the phone aims). Ambient light adds a constant. So
//!
//! `Y(p) ≈ [1 − v + v·cos⁴θ_c(p)] · cos^k β(p; l) · (a·g_d + b·g_s(α)) + c`,   a, b, c ≥ 0.
//!
//! For fixed (l, α, v, k) the model is linear in (a, b, c), solved exactly by weighted
//! non-negative least squares (variable projection); only (lₓ, l_y, ln α, v, k) are searched,
//! by Nelder–Mead from the best of a 9×9 grid of positions over the central half of the photo
//! plus three data-driven starts (brightest blurred cell, the paper's centroid, the centroid of
//! saturated cells), each with 7 lobe widths.
//!
//! # Data and weights
//! Y is the paper's intensity (linear min(R,G,B)) averaged over blocks of a
//! ~[`RobustDetector::grid`]² grid. A saturated block's mean is only a lower bound on its
//! true intensity (clipping lowers pixels, never raises them), so it enters as censored data:
//! it costs nothing where the model lies above it and the squared shortfall where the model
//! lies below. Leaving such blocks out instead let a clipped highlight's core, which carries no
//! magnitude, be explained by any bright texture nearby (a stone vein 15 % of the width away).
//! Residuals are weighted as photon noise (variance ∝ signal: weight 1/Y, which lets a bright,
//! sparse lobe such as a brushed-metal streak outweigh a dim background) and down-weighted with
//! Cauchy weights re-estimated every round (IRLS), so grout lines, dark specks and sparkles do
//! not drag the fit. The first three rounds fit the whole photo; the last two only the largest
//! square centred on the estimate that lies inside it (at least [`MIN_DOMAIN_HALF`] wide), so a
//! lobe whose shape the model does not match (two-lobe car paint, bumpy normals) is still
//! centred: a radial profile fitted on a domain symmetric about its centre has no reason to
//! shift towards the larger side. A polishing round that moves the estimate by more than
//! 2.5 % of the width is discarded.
//!
//! # Clipped highlights
//! When the fitted lobe is compact (α ≤ 0.25), distinct (its peak at least half the diffuse +
//! ambient level) and at least 4 saturated cells lie within 3α of it, the model cannot see the
//! lobe's core. The position is then refined by mean shift on the full-resolution specular
//! residual (intensity minus the fitted diffuse and ambient part): the centroid of its top half
//! within a square window of half-side 3α, re-centred until it moves less than 0.01 pixel.
//!
//! # Accuracy (mean / max error, % of the width)
//! `photomat simulate --count 64 --size 512` (seed 0, jitter σ = 4 %), then `prepare` and
//! `eval-detector`: robust 0.63 / 4.5, paper 1.41 / 4.6. By family, robust vs paper:
//! brushed metal 1.27 / 1.17 (the streak of sparse glints is the model's weak case), car paint
//! 0.10 / 0.56, fabric 0.72 / 1.65, leather 0.18 / 0.44, paint 0.33 / 1.84, stone 0.95 / 2.26,
//! tiles 1.30 / 1.82 (wavy glaze tilts the specular spot off the flash point), wood 0.16 / 1.54.
//! On 320 photos of each kind (docs/benchmarks/highlight-detector.md, "Highlight detector: censored
//! clipping and a blended second opinion"): overhead simulator 0.73 / 4.9 against
//! 1.71 / 14.8, the phone-pose simulator 1.05 / 9.5 against 1.88 / 14.3, Mitsuba renders of
//! texture photos (48) 1.51 / 4.5 against 1.99 / 4.3.
//! Test `robust_beats_paper_on_simulated_photos` (independent camera model, 48 photos at 512²):
//! robust 0.54, paper 1.49.
//!
//! # Second opinion
//! The model is a single radial lobe over a flat plane. Photos that break it (a normal-mapped
//! relief whose rough lobe the fit widens until it explains the texture, a sparkle the fit
//! mistakes for a mirror-sharp lobe) send the fit far from the highlight, where the paper's
//! centroid, with its own bias towards the centre, stays within a few % of the width. So
//! when the two are more than [`RobustDetector::max_disagreement`] apart, the answer moves
//! towards the position whose 8 %-of-the-width neighbourhood stands out more from its
//! surroundings (three times as wide): the flash highlight is a bright region brighter than
//! what surrounds it, which a textured patch or a vignetted centre is not. When the two stand
//! out within 15 % of each other the measure cannot tell them apart, and the answer lies
//! between them in proportion (halfway at a tie), rather than on one side by a coin flip. A
//! fit whose lobe collapsed to the narrowest width searched (a single bright texel) or spread
//! as wide as the photo (the diffuse falloff again) loses to the centroid without that test,
//! and a fit that explains the photo within noise (relative misfit below 0.5 %) keeps its
//! place without it. On photos rendered by Mitsuba from texture photos (`validation/`) the
//! second opinion takes the largest error from 13.7 % to 4.5 % of the width
//! (docs/benchmarks/highlight-detector.md, "Highlight detector: censored clipping and a blended
//! second opinion").
//!
//! # Failure rule
//! Falls back to the image centre, with the reason, when the flash does not dominate: the
//! fitted flash part is less than [`RobustDetector::min_flash_share`] of the mean intensity
//! (ambient or black photos), so there is no highlight to find. Takes the paper detector's
//! centroid instead, with the reason (the centre only if that detector falls back too), when
//! the fit is implausible:
//! - the highlight is too far: more than [`RobustDetector::max_offset`] of the width from the
//!   centre, where too little of the lobe is inside the photo to pin it down (on the
//!   independent set, a rough lobe on normal-mapped grass fitted 46 % out: centre 4.1 %,
//!   centroid 0.9 %);
//! - the fit does not converge to a finite position.

use photomat_core::Result;
use photomat_core::image_io::PlanarImage;

use super::intensity::min_rgb_linear;
use super::{Detection, HighlightDetector, PHOTO_SIDE};

/// Configuration of the robust detector; every field has a documented default.
#[derive(Debug, Clone)]
pub struct RobustDetector {
    /// Approximate cells per side of the fitting grid (default 64: blocks of 8×8 pixels at 512²,
    /// 1/64 of the width, enough to sample a lobe of α ≥ 0.03 and fast: ~4 k residuals).
    pub grid: usize,
    /// Largest accepted distance of the highlight from the centre, fraction of the width
    /// (default 0.4: at least 10 % of the width between highlight and border, so the symmetric
    /// fitting domain still holds a lobe's core).
    pub max_offset: f64,
    /// Smallest accepted share of the flash in the mean intensity of the fitting domain
    /// (default 0.25: the paper asks for photos in which the flash dominates; below a quarter,
    /// ambient light or a black sample leaves too little falloff to localise).
    pub min_flash_share: f64,
    /// Largest distance, as a fraction of the width, between the fit and the paper detector's
    /// centroid that is accepted without a second look (default 0.03, chosen with
    /// [`ARBITER_TIE`] on the simulated sets; 0 turns the second opinion off). Beyond
    /// it the position that stands out more wins, or both meet halfway ("Second opinion").
    pub max_disagreement: f64,
}

impl Default for RobustDetector {
    fn default() -> Self {
        Self {
            grid: 64,
            max_offset: 0.4,
            min_flash_share: 0.25,
            max_disagreement: 0.03,
        }
    }
}

/// Side of the box, as a fraction of the width, whose mean intensity over that of a box three
/// times as wide compares the fit's and the centroid's positions: 8 %, wider than a sparkle
/// or a grout line, narrower than any flash lobe the photos show.
const ARBITER_BOX: f64 = 0.08;

/// Relative difference of the two positions' local contrasts below which the second opinion
/// cannot tell them apart ([`centroid_share`]): 15 %, chosen on the simulated sets, where
/// 15–20 % give the same errors and 10 % leaves one photo beyond 5 % of the width
/// (docs/benchmarks/highlight-detector.md, "Highlight detector: censored clipping and a blended
/// second opinion").
const ARBITER_TIE: f64 = 0.15;

/// Relative misfit ([`FlashFit::misfit`]) below which the model explains the photo and the
/// fit needs no second opinion: 0.5 %, between noise-free renders of the model itself (up to
/// 0.4 % at 128², the grid's averaging of narrow lobes) and every simulated photo (texture and
/// noise: 0.8 % and up).
const EXPLAINED_MISFIT: f64 = 0.005;

/// Fitted lobe width at or below which the lobe counts as collapsed: within 20 % of the
/// search's lower bound [`ALPHA_MIN`], where the mirror-like lobes of simulated car paint
/// (α ≈ 0.007 at 512²) are not.
const COLLAPSED_ALPHA: f64 = 1.2 * ALPHA_MIN;

/// Fitted lobe width at or above which the lobe is as wide as the photo's half-side (the
/// photo spans ±1 at flash height 1): indistinguishable from the diffuse falloff, so its
/// centre follows the texture rather than the flash.
const BROAD_ALPHA: f64 = 1.0;

/// Smallest half-side of the fitting square, plane units (the photo spans [−1, 1]²): 0.5 keeps
/// at least a quarter of the photo in the fit when the highlight is near the border.
pub const MIN_DOMAIN_HALF: f64 = 0.5;

/// Linear intensity at or above which a block counts as saturated: an 8-bit 255 linearises to 1,
/// the mid-point to 254 to (254.5/255)^2.2 = 0.9957.
const SATURATED: f64 = 0.995;

/// Starting lobe widths α for the search: from a mirror-like lobe of a few pixels to a rough
/// one wider than the photo, a factor ≈2 apart so one of them is within the basin.
const ALPHA_STARTS: [f64; 7] = [0.015, 0.03, 0.06, 0.12, 0.25, 0.5, 1.0];

/// α is searched in [ALPHA_MIN, ALPHA_MAX]: below 0.005 the lobe is far narrower than one grid
/// cell, above 3 it is flatter than the diffuse profile and indistinguishable from it.
const ALPHA_MIN: f64 = 0.005;
const ALPHA_MAX: f64 = 3.0;

/// Largest flash-beam exponent k searched: cos⁴ already halves the light 33° off the beam axis,
/// narrower than any phone flash LED (Lambertian emitters are k ≈ 1).
const BEAM_MAX: f64 = 4.0;

/// Cauchy tuning constant (95 % efficiency under Gaussian noise, Holland & Welsch 1977).
const CAUCHY_C: f64 = 2.385;

/// IRLS rounds: weights and fitting domain are re-estimated this often; the position moves by
/// less than 0.01 pixel after the third round on every simulated family.
const IRLS_ROUNDS: usize = 5;

/// Starting positions per axis of the initial grid search.
const GRID_STARTS: usize = 9;

/// Largest move of a symmetric-domain round, plane units (2.5 % of the width).
const MAX_POLISH: f64 = 0.05;

/// Of the IRLS rounds, how many fit on the domain symmetric about the estimate (the rest use
/// the whole photo).
const SYMMETRIC_ROUNDS: usize = 2;

/// The fitted flash model of one photo (module docs, "Model").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlashFit {
    /// Highlight in plane coordinates of the side-2 photo (x right, y up).
    pub lx: f64,
    pub ly: f64,
    /// Width α of the specular lobe.
    pub alpha: f64,
    /// Vignetting strength v of `1 − v + v·cos⁴θ`.
    pub vignetting: f64,
    /// Exponent k of the flash beam `cos^k β`.
    pub beam: f64,
    /// Coefficients of the diffuse profile, the specular profile and the ambient constant.
    pub coefficients: [f64; 3],
    /// Share of the flash in the fitted intensity over the fitting domain.
    pub flash_share: f64,
    /// Robust scale of the relative residuals over the photo: 0 for a photo of the model
    /// itself, the texture's relative contrast for a real one.
    pub misfit: f64,
}

impl FlashFit {
    /// The highlight as a continuous pixel position (row, col) of an h×w photo.
    pub fn pixel(&self, h: usize, w: usize) -> (f64, f64) {
        let scale = w as f64 / PHOTO_SIDE;
        (
            h as f64 / 2.0 - self.ly * scale,
            w as f64 / 2.0 + self.lx * scale,
        )
    }
}

/// Nonlinear parameters: lₓ, l_y, ln α, v, k.
type Params = [f64; 5];

/// One grid cell: plane position, cos⁴ of its angle off the optical axis, mean linear
/// intensity, whether it is usable.
#[derive(Debug, Clone, Copy)]
struct Cell {
    x: f64,
    y: f64,
    cos4: f64,
    y_lin: f64,
    usable: bool,
}

/// A fitted model: nonlinear parameters, linear coefficients and weighted cost.
#[derive(Debug, Clone, Copy)]
struct Fit {
    p: Params,
    coef: [f64; 3],
    cost: f64,
}

impl Fit {
    fn alpha(&self) -> f64 {
        self.p[2].exp().clamp(ALPHA_MIN, ALPHA_MAX)
    }
}

impl HighlightDetector for RobustDetector {
    fn name(&self) -> &'static str {
        "robust"
    }

    fn detect(&self, image: &PlanarImage) -> Result<Detection> {
        let (h, w) = (image.height, image.width);
        let intensity = min_rgb_linear(image)?;
        let Some(fit) = self.fit_intensity(&intensity, h, w)? else {
            return Ok(Detection::fallback(
                h,
                w,
                "no usable pixels: the image is black or saturated",
            ));
        };
        if !(fit.lx.is_finite() && fit.ly.is_finite()) {
            return self.paper_or_centre(image, "the flash model fit did not converge".into());
        }
        if fit.flash_share < self.min_flash_share {
            return Ok(Detection::fallback(
                h,
                w,
                format!(
                    "the flash does not dominate: it explains {:.0} % of the intensity around \
                     the highlight (limit {:.0} %); ambient light or a black sample",
                    100.0 * fit.flash_share,
                    100.0 * self.min_flash_share
                ),
            ));
        }
        let (row, col) = fit.pixel(h, w);
        let offset = fit.lx.hypot(fit.ly) / PHOTO_SIDE;
        if offset > self.max_offset {
            return self.paper_or_centre(
                image,
                format!(
                    "fitted highlight ({row:.1}, {col:.1}) is {:.0} % of the width from the centre \
                     (limit {:.0} %)",
                    100.0 * offset,
                    100.0 * self.max_offset
                ),
            );
        }
        let own = Detection::detected(row, col, h, w);
        // The second opinion is for photos that break the model; one it explains within
        // noise does not.
        if fit.misfit < EXPLAINED_MISFIT {
            return Ok(own);
        }
        // A lobe at the narrowest width searched is a single bright texel, and one as wide as
        // the photo is the diffuse falloff again: neither pins the flash down.
        let implausible = fit.alpha <= COLLAPSED_ALPHA || fit.alpha >= BROAD_ALPHA;
        self.second_opinion(image, &intensity, own, implausible)
    }
}

impl RobustDetector {
    /// `own` (a detection of `image`, whose intensity is `intensity`), or the paper detector's
    /// centroid when the two are more than [`Self::max_disagreement`] apart and either the
    /// fit's lobe is `implausible` or the centroid's neighbourhood stands out more (module
    /// docs, "Second opinion").
    fn second_opinion(
        &self,
        image: &PlanarImage,
        intensity: &[f64],
        own: Detection,
        implausible: bool,
    ) -> Result<Detection> {
        if self.max_disagreement <= 0.0 {
            return Ok(own);
        }
        let paper = super::PaperDetector::default().detect(image)?;
        let (h, w) = (image.height, image.width);
        let apart = own.error_px(paper.row, paper.col) / w as f64;
        if paper.status != super::DetectionStatus::Detected || apart <= self.max_disagreement {
            return Ok(own);
        }
        let contrast = |row, col| local_contrast(intensity, h, w, row, col);
        let (fit_level, centroid_level) =
            (contrast(own.row, own.col), contrast(paper.row, paper.col));
        let share = if implausible {
            1.0
        } else {
            centroid_share(centroid_level / fit_level.max(f64::MIN_POSITIVE))
        };
        if share == 0.0 {
            return Ok(own);
        }
        let why = if implausible {
            "its lobe collapsed to a point (a sparkle) or spread over the whole photo: the \
             centroid is used"
                .to_string()
        } else if share == 1.0 {
            format!(
                "stands out less from its surroundings ({fit_level:.3} vs {centroid_level:.3}): \
                 the centroid is used"
            )
        } else {
            format!(
                "stands out about as much ({fit_level:.3} vs {centroid_level:.3}): the answer \
                 lies {:.0} % of the way from the fit to the centroid",
                100.0 * share
            )
        };
        Ok(Detection {
            row: own.row + share * (paper.row - own.row),
            col: own.col + share * (paper.col - own.col),
            reason: Some(format!(
                "the flash-model fit ({:.1}, {:.1}) is {:.1} % of the width from the paper \
                 detector's centroid and {why}",
                own.row,
                own.col,
                100.0 * apart
            )),
            ..paper
        })
    }

    /// Where the far fit of an implausible flash model ends up: the paper detector's
    /// centroid of `image` when that found a highlight (the issue's "fall back to the paper's
    /// detector"), else the image centre; `why` says what was wrong with the fit.
    fn paper_or_centre(&self, image: &PlanarImage, why: String) -> Result<Detection> {
        let paper = super::PaperDetector::default().detect(image)?;
        if paper.status == super::DetectionStatus::Detected {
            return Ok(Detection {
                reason: Some(format!("{why}: the paper detector's centroid is used")),
                ..paper
            });
        }
        Ok(Detection::fallback(image.height, image.width, why))
    }

    /// The second opinion's measure at pixel (`row`, `col`) of `image`: the mean intensity of
    /// its [`ARBITER_BOX`]-wide neighbourhood over that of a box three times as wide (module
    /// docs, "Second opinion"). Above 1 where a lobe stands out.
    pub fn local_contrast(&self, image: &PlanarImage, row: f64, col: f64) -> Result<f64> {
        let intensity = min_rgb_linear(image)?;
        Ok(local_contrast(
            &intensity,
            image.height,
            image.width,
            row,
            col,
        ))
    }

    /// The fitted flash model of `image`, or `None` when it has too few usable (non-black,
    /// unsaturated) pixels to fit. [`HighlightDetector::detect`] applies the failure rule to it.
    pub fn fit(&self, image: &PlanarImage) -> Result<Option<FlashFit>> {
        let intensity = min_rgb_linear(image)?;
        self.fit_intensity(&intensity, image.height, image.width)
    }

    /// [`Self::fit`] on the intensity (row-major `h`×`w`) of the image.
    fn fit_intensity(&self, intensity: &[f64], h: usize, w: usize) -> Result<Option<FlashFit>> {
        let cells = self.cells(intensity, h, w);
        let usable = cells.iter().filter(|c| c.usable).count();
        let mean = cells
            .iter()
            .filter(|c| c.usable)
            .map(|c| c.y_lin)
            .sum::<f64>()
            / usable.max(1) as f64;
        // 16 cells: twice the model's 8 unknowns, the least for a robust fit.
        if usable < 16 || mean <= 0.0 {
            return Ok(None);
        }
        // Relative residuals are taken against at least 2 % of the mean intensity, so black
        // texels (noise only) cannot dominate the fit.
        let floor = 0.02 * mean;
        let mut weights: Vec<f64> = cells.iter().map(|c| 1.0 / c.y_lin.max(floor)).collect();
        let half_h = h as f64 / w as f64; // plane half-height (the width spans [−1, 1])
        let mut fit = initial_fit(&cells, &weights);
        for round in 0..IRLS_ROUNDS {
            // The first rounds see the whole photo, so the fit cannot drift by shrinking its
            // domain; the last ones only the square symmetric about the estimate.
            let base: Vec<f64> = if round < IRLS_ROUNDS - SYMMETRIC_ROUNDS {
                weights.clone()
            } else {
                let domain = domain_weights(&cells, fit.p[0], fit.p[1], half_h);
                weights.iter().zip(&domain).map(|(w, d)| w * d).collect()
            };
            let next = nelder_mead(&cells, &base, fit);
            // A symmetric round only polishes: a big jump means it followed its own shrinking
            // domain rather than the photo, so the whole-photo estimate stands.
            if round >= IRLS_ROUNDS - SYMMETRIC_ROUNDS
                && (next.p[0] - fit.p[0]).hypot(next.p[1] - fit.p[1]) > MAX_POLISH
            {
                break;
            }
            fit = next;
            weights = reweight(&cells, &fit, floor);
        }
        let (lx, ly) = refine_peak(intensity, h, w, &fit, &cells).unwrap_or((fit.p[0], fit.p[1]));
        Ok(Some(FlashFit {
            lx,
            ly,
            alpha: fit.alpha(),
            vignetting: fit.p[3].clamp(0.0, 1.0),
            beam: fit.p[4].clamp(0.0, BEAM_MAX),
            coefficients: fit.coef,
            flash_share: flash_share(&cells, &fit, half_h),
            misfit: misfit(&cells, &fit, floor),
        }))
    }

    /// Block averages of the intensity on a grid of about `self.grid` cells across the width.
    fn cells(&self, intensity: &[f64], h: usize, w: usize) -> Vec<Cell> {
        let k = (w / self.grid.max(1)).max(1);
        let (rows, cols) = ((h / k).max(1), (w / k).max(1));
        let (kr, kc) = (k.min(h), k.min(w));
        let scale = PHOTO_SIDE / w as f64;
        let mut cells = Vec::with_capacity(rows * cols);
        for bi in 0..rows {
            for bj in 0..cols {
                let (mut sum, mut saturated) = (0.0, false);
                for i in bi * kr..(bi + 1) * kr {
                    for &v in &intensity[i * w + bj * kc..i * w + (bj + 1) * kc] {
                        sum += v;
                        saturated |= v >= SATURATED;
                    }
                }
                let row = (bi as f64 + 0.5) * kr as f64;
                let col = (bj as f64 + 0.5) * kc as f64;
                let (x, y) = (
                    (col - w as f64 / 2.0) * scale,
                    (h as f64 / 2.0 - row) * scale,
                );
                let cos2 = 1.0 / (1.0 + x * x + y * y);
                cells.push(Cell {
                    x,
                    y,
                    cos4: cos2 * cos2,
                    y_lin: sum / (kr * kc) as f64,
                    usable: !saturated,
                });
            }
        }
        cells
    }
}

/// Mean-shift refinement on the full-resolution specular residual when the fit found a
/// distinct, compact lobe: the residual above the fitted diffuse + ambient part, centroid over
/// a square window centred on the current estimate, repeated until the window stops moving.
/// At the fixed point the residual's centroid is the window's centre, so any lobe symmetric
/// about the flash point (round, a brushed streak, clipped) is found without the radial
/// model's shape; the camera factor barely tilts a lobe this narrow.
fn refine_peak(
    intensity: &[f64],
    h: usize,
    w: usize,
    fit: &Fit,
    cells: &[Cell],
) -> Option<(f64, f64)> {
    let alpha = fit.alpha();
    let [a, b, c] = fit.coef;
    let saturated = cells
        .iter()
        .filter(|c| !c.usable && (c.x - fit.p[0]).hypot(c.y - fit.p[1]) < 3.0 * alpha)
        .count();
    if saturated < 4 {
        return None;
    }
    // Distinct: the lobe's peak at least half the diffuse + ambient level under it; compact:
    // α ≤ 0.25, so a window of 3α stays inside a photo whose flash is off by 25 % at most.
    if b < 0.5 * (a + c) || alpha > 0.25 {
        return None;
    }
    let scale = PHOTO_SIDE / w as f64;
    let half_window = (3.0 * alpha).max(4.0 * scale);
    let background = |x: f64, y: f64| {
        let cell = Cell {
            x,
            y,
            cos4: (1.0 / (1.0 + x * x + y * y)).powi(2),
            y_lin: 0.0,
            usable: true,
        };
        let basis = basis(&cell, &fit.p);
        a * basis[0] + c
    };
    let (mut lx, mut ly) = (fit.p[0], fit.p[1]);
    // 50 shifts: each moves by the residual's offset inside the window, which shrinks
    // geometrically; stop below 0.01 pixel.
    for _ in 0..50 {
        let (x0, x1) = (lx - half_window, lx + half_window);
        let (y0, y1) = (ly - half_window, ly + half_window);
        let c0 = (((x0 + 1.0) / scale).floor().max(0.0) as usize).min(w);
        let c1 = (((x1 + 1.0) / scale).ceil().max(0.0) as usize).min(w);
        let half_h = h as f64 / w as f64;
        let r0 = (((half_h - y1) / scale).floor().max(0.0) as usize).min(h);
        let r1 = (((half_h - y0) / scale).ceil().max(0.0) as usize).min(h);
        // Residuals inside the window; only their top half (above half the largest) counts,
        // so dimmer texture (bright grout, wood grain) under a bright lobe does not pull.
        let mut window = Vec::new();
        for row in r0..r1 {
            let y = half_h - (row as f64 + 0.5) * scale;
            if y < y0 || y > y1 {
                continue;
            }
            for col in c0..c1 {
                let x = (col as f64 + 0.5) * scale - 1.0;
                if x < x0 || x > x1 {
                    continue;
                }
                window.push((x, y, intensity[row * w + col] - background(x, y)));
            }
        }
        let top = window.iter().map(|p| p.2).fold(0.0, f64::max);
        let (mut sum, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for &(x, y, r) in &window {
            let weight = r - 0.5 * top;
            if weight > 0.0 {
                sum += weight;
                sx += weight * x;
                sy += weight * y;
            }
        }
        if sum <= 0.0 {
            return None;
        }
        let (nx, ny) = (sx / sum, sy / sum);
        let moved = (nx - lx).hypot(ny - ly);
        (lx, ly) = (nx, ny);
        if moved < 0.01 * scale {
            break;
        }
    }
    // A window that wandered far from the fit followed something else than the lobe.
    ((lx - fit.p[0]).hypot(ly - fit.p[1]) <= 2.0 * alpha).then_some((lx, ly))
}

/// Best of a few starting positions (brightest blurred cell, above-mean centroid, image
/// centre) × [`ALPHA_STARTS`], with mid-range camera parameters, scored per unit of weight.
fn initial_fit(cells: &[Cell], weights: &[f64]) -> Fit {
    let mut starts = vec![(0.0, 0.0)];
    if let Some(c) = brightest(cells) {
        starts.push(c);
    }
    let centroid = |keep: &dyn Fn(&Cell) -> bool, weight: &dyn Fn(&Cell) -> f64| {
        let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for c in cells.iter().filter(|c| keep(c)) {
            s += weight(c);
            sx += weight(c) * c.x;
            sy += weight(c) * c.y;
        }
        (s > 0.0).then(|| (sx / s, sy / s))
    };
    let mean = cells.iter().map(|c| c.y_lin).sum::<f64>() / cells.len() as f64;
    // The paper's above-mean centroid, and the centroid of the saturated cells (a clipped
    // highlight hides its core from the fit).
    starts.extend(centroid(&|c| c.y_lin > mean, &|c| c.y_lin));
    starts.extend(centroid(&|c| !c.usable, &|_| 1.0));
    // A 9×9 grid over the central half of the photo (steps of 6 % of the width): the flash
    // is aimed at the centre, and one grid point lies within the basin of any lobe there.
    for i in 0..GRID_STARTS {
        for j in 0..GRID_STARTS {
            let t = |k: usize| (k as f64 / (GRID_STARTS - 1) as f64 - 0.5) * 1.0;
            starts.push((t(j), t(i)));
        }
    }
    let mut best: Option<Fit> = None;
    for &(lx, ly) in &starts {
        for &alpha in &ALPHA_STARTS {
            let fit = solve(cells, weights, [lx, ly, alpha.ln(), 0.25, 0.5]);
            if best.is_none_or(|b| fit.cost < b.cost) {
                best = Some(fit);
            }
        }
    }
    best.expect("at least one start")
}

/// Centre of the brightest cell after a 5×5 box blur (the blur keeps single hot texels
/// and sparkles from winning).
fn brightest(cells: &[Cell]) -> Option<(f64, f64)> {
    let n = (cells.len() as f64).sqrt() as usize;
    if n * n != cells.len() || n < 5 {
        return cells
            .iter()
            .max_by(|a, b| a.y_lin.total_cmp(&b.y_lin))
            .map(|c| (c.x, c.y));
    }
    let mut best = (f64::NEG_INFINITY, 0);
    for i in 2..n - 2 {
        for j in 2..n - 2 {
            let mut s = 0.0;
            for di in 0..5 {
                for dj in 0..5 {
                    s += cells[(i + di - 2) * n + j + dj - 2].y_lin;
                }
            }
            if s > best.0 {
                best = (s, i * n + j);
            }
        }
    }
    Some((cells[best.1].x, cells[best.1].y))
}

/// 1 inside the largest square centred on (lx, ly) within the photo (half-side at least
/// [`MIN_DOMAIN_HALF`]), 0 outside.
fn domain_weights(cells: &[Cell], lx: f64, ly: f64, half_h: f64) -> Vec<f64> {
    let half = (1.0 - lx.abs()).min(half_h - ly.abs()).max(MIN_DOMAIN_HALF);
    cells
        .iter()
        .map(|c| {
            if (c.x - lx).abs() <= half && (c.y - ly).abs() <= half {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// The basis functions at a cell: camera factor × diffuse profile, camera factor × specular
/// profile, and the ambient constant.
#[inline]
fn basis(c: &Cell, p: &Params) -> [f64; 3] {
    let (lx, ly) = (p[0], p[1]);
    let alpha = p[2].exp().clamp(ALPHA_MIN, ALPHA_MAX);
    let alpha2 = alpha * alpha;
    let v = p[3].clamp(0.0, 1.0);
    let k = p[4].clamp(0.0, BEAM_MAX);
    let s2 = (c.x - lx).powi(2) + (c.y - ly).powi(2);
    let q = 1.0 + s2;
    let root = q.sqrt();
    let g_d = 1.0 / (q * root);
    let lobe = alpha2 / (alpha2 + s2);
    let g_s = lobe * lobe * q * root;
    // cos β between the rays flash→cell and flash→image centre, flash at (lx, ly, 1).
    let l2 = lx * lx + ly * ly;
    let cos_beam = ((1.0 + l2 - c.x * lx - c.y * ly) / (root * (1.0 + l2).sqrt())).max(1e-6);
    let camera = (1.0 - v + v * c.cos4) * if k > 0.0 { cos_beam.powf(k) } else { 1.0 };
    [camera * g_d, camera * g_s, 1.0]
}

/// Weighted least-squares coefficients for fixed nonlinear parameters. All three must be
/// non-negative (a dip is not a flash, light does not subtract), so the best non-negative
/// solution among the subsets of basis functions is kept.
fn solve(cells: &[Cell], weights: &[f64], p: Params) -> Fit {
    // The flash point stays inside the photo: outside it, an empty symmetric domain would fit
    // perfectly.
    if p[0].abs() > 1.0 || p[1].abs() > 1.0 {
        return Fit {
            p,
            coef: [0.0; 3],
            cost: f64::INFINITY,
        };
    }
    let mut ata = [[0.0f64; 3]; 3];
    let mut atb = [0.0f64; 3];
    let mut btb = 0.0;
    for (c, &wt) in cells.iter().zip(weights) {
        if wt == 0.0 || !c.usable {
            continue;
        }
        let b = basis(c, &p);
        for i in 0..3 {
            let wb = wt * b[i];
            atb[i] += wb * c.y_lin;
            for j in i..3 {
                ata[i][j] += wb * b[j];
            }
        }
        btb += wt * c.y_lin * c.y_lin;
    }
    // Mirror the upper triangle.
    for (i, j) in [(1, 0), (2, 0), (2, 1)] {
        ata[i][j] = ata[j][i];
    }
    // Subsets: both profiles, diffuse only, specular only; with and without ambient light.
    const SUBSETS: [&[usize]; 6] = [&[0, 1, 2], &[0, 2], &[1, 2], &[0, 1], &[0], &[1]];
    let mut best = Fit {
        p,
        coef: [0.0; 3],
        cost: btb,
    };
    for subset in SUBSETS {
        let Some(x) = solve_subset(&ata, &atb, subset) else {
            continue;
        };
        let mut coef = [0.0; 3];
        for (k, &i) in subset.iter().enumerate() {
            coef[i] = x[k];
        }
        if coef.iter().any(|&c| c < 0.0) {
            continue;
        }
        // Weighted SSE = yᵀWy − xᵀAᵀWy at the least-squares solution.
        let cost = btb
            - subset
                .iter()
                .zip(&x)
                .map(|(&i, xi)| xi * atb[i])
                .sum::<f64>();
        if cost < best.cost {
            best.coef = coef;
            best.cost = cost.max(0.0);
        }
    }
    best.cost += censored_cost(cells, weights, &best);
    best
}

/// Cost of the saturated cells: clipping only lowers a pixel, so a saturated cell's mean is
/// a lower bound on the true one, and a model below it pays the squared shortfall at the
/// cell's photon weight (one-sided, as for censored data). This is what keeps a clipped
/// highlight's core, which carries no magnitude, from being left for a bright texture.
fn censored_cost(cells: &[Cell], weights: &[f64], fit: &Fit) -> f64 {
    cells
        .iter()
        .zip(weights)
        .filter(|(c, wt)| !c.usable && **wt > 0.0)
        .map(|(c, wt)| wt * (c.y_lin - model(c, fit)).max(0.0).powi(2))
        .sum()
}

/// Solve the normal equations restricted to `subset` by Cholesky; `None` if singular.
fn solve_subset(ata: &[[f64; 3]; 3], atb: &[f64; 3], subset: &[usize]) -> Option<Vec<f64>> {
    let n = subset.len();
    let mut l = vec![0.0f64; n * n];
    // A relative ridge of 1e-12 keeps nearly collinear profiles (α ≫ 1) solvable without
    // changing well-posed solutions beyond f64 rounding.
    let ridge = 1e-12 * subset.iter().map(|&i| ata[i][i]).sum::<f64>();
    for i in 0..n {
        for j in 0..=i {
            let mut s = ata[subset[i]][subset[j]] + if i == j { ridge } else { 0.0 };
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s <= 0.0 {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut z = vec![0.0; n];
    for i in 0..n {
        let mut s = atb[subset[i]];
        for k in 0..i {
            s -= l[i * n + k] * z[k];
        }
        z[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = z[i];
        for k in i + 1..n {
            s -= l[k * n + i] * z[k];
        }
        z[i] = s / l[i * n + i];
    }
    Some(z)
}

/// Model value at a cell.
fn model(c: &Cell, fit: &Fit) -> f64 {
    let b = basis(c, &fit.p);
    b.iter().zip(&fit.coef).map(|(b, k)| b * k).sum()
}

/// IRLS weights: relative residuals (against the model, floored) with Cauchy down-weighting
/// at a scale of 1.4826 × their median absolute value.
fn reweight(cells: &[Cell], fit: &Fit, floor: f64) -> Vec<f64> {
    // 1e-3 keeps noise-free synthetic images from getting an infinite weight scale.
    let sigma = misfit(cells, fit, floor).max(1e-3);
    cells
        .iter()
        .map(|c| {
            if c.usable {
                let m = model(c, fit).max(floor);
                let u = (c.y_lin - m) / m / (CAUCHY_C * sigma);
                1.0 / (m * (1.0 + u * u))
            } else {
                // Saturated: a bound, not a measurement ([`censored_cost`]), at photon weight.
                1.0 / c.y_lin.max(floor)
            }
        })
        .collect()
}

/// Robust scale of the usable cells' relative residuals `(Y − model) / model` (1.4826 × their
/// median absolute value, the standard deviation under Gaussian noise), the model floored at
/// `floor`: how far the photo departs from the flash model, texture included.
fn misfit(cells: &[Cell], fit: &Fit, floor: f64) -> f64 {
    let mut abs: Vec<f64> = cells
        .iter()
        .filter(|c| c.usable)
        .map(|c| {
            let m = model(c, fit).max(floor);
            ((c.y_lin - m) / m).abs()
        })
        .collect();
    abs.sort_unstable_by(f64::total_cmp);
    1.4826 * abs.get(abs.len() / 2).copied().unwrap_or(0.0)
}

/// Share of the fitted flash (everything but the ambient constant) in the fitted intensity,
/// averaged over the fitting domain.
fn flash_share(cells: &[Cell], fit: &Fit, half_h: f64) -> f64 {
    let domain = domain_weights(cells, fit.p[0], fit.p[1], half_h);
    let (mut flash, mut total) = (0.0, 0.0);
    for (c, d) in cells.iter().zip(domain) {
        if d > 0.0 {
            let m = model(c, fit);
            flash += m - fit.coef[2];
            total += m;
        }
    }
    if total > 0.0 { flash / total } else { 0.0 }
}

/// Nelder–Mead over the nonlinear parameters with the linear coefficients solved at every
/// vertex; standard coefficients (reflection 1, expansion 2, contraction ½, shrink ½).
fn nelder_mead(cells: &[Cell], weights: &[f64], start: Fit) -> Fit {
    const N: usize = 5;
    // Initial steps: 0.04 plane units (1 % of the side-2 width ≈ 5 px at 512²), a factor 1.5
    // in α, 0.15 in v and 0.5 in k; the search stops when the simplex's positions span less
    // than 1e-4 units (0.005 % of the width).
    const STEPS: Params = [0.04, 0.04, 0.4, 0.15, 0.5];
    const TOLERANCE: f64 = 1e-4;
    const MAX_EVALS: usize = 600;
    let eval = |p: Params| solve(cells, weights, p);
    let mut simplex: Vec<Fit> = vec![eval(start.p)];
    for (k, step) in STEPS.into_iter().enumerate() {
        let mut p = start.p;
        p[k] += step;
        simplex.push(eval(p));
    }
    let mut evals = N + 1;
    while evals < MAX_EVALS {
        simplex.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        let spread = simplex[1..]
            .iter()
            .map(|f| (f.p[0] - simplex[0].p[0]).hypot(f.p[1] - simplex[0].p[1]))
            .fold(0.0, f64::max);
        if spread < TOLERANCE {
            break;
        }
        let mut centroid = [0.0; N];
        for f in &simplex[..N] {
            for (c, p) in centroid.iter_mut().zip(&f.p) {
                *c += p / N as f64;
            }
        }
        let worst = simplex[N];
        let along = |t: f64| -> Params {
            let mut p = [0.0; N];
            for k in 0..N {
                p[k] = centroid[k] + t * (worst.p[k] - centroid[k]);
            }
            p
        };
        let fr = eval(along(-1.0));
        evals += 1;
        if fr.cost < simplex[0].cost {
            let fe = eval(along(-2.0));
            evals += 1;
            simplex[N] = if fe.cost < fr.cost { fe } else { fr };
        } else if fr.cost < simplex[N - 1].cost {
            simplex[N] = fr;
        } else {
            let fc = eval(if fr.cost < worst.cost {
                along(-0.5)
            } else {
                along(0.5)
            });
            evals += 1;
            if fc.cost < worst.cost.min(fr.cost) {
                simplex[N] = fc;
            } else {
                let best = simplex[0].p;
                for vertex in simplex.iter_mut().skip(1) {
                    let mut p = [0.0; N];
                    for k in 0..N {
                        p[k] = best[k] + 0.5 * (vertex.p[k] - best[k]);
                    }
                    *vertex = eval(p);
                    evals += 1;
                }
            }
        }
    }
    simplex
        .into_iter()
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .expect("vertices")
}

/// How much brighter the [`ARBITER_BOX`]-wide neighbourhood of (`row`, `col`) is than its
/// surroundings three times as wide, in `intensity` (row-major h×w): a lobe stands out, a
/// vignetted centre or a textured patch does not.
fn local_contrast(intensity: &[f64], h: usize, w: usize, row: f64, col: f64) -> f64 {
    let half = (ARBITER_BOX * w as f64 / 2.0).max(1.0);
    box_mean(intensity, h, w, row, col, half)
        / box_mean(intensity, h, w, row, col, 3.0 * half).max(f64::MIN_POSITIVE)
}

/// How far the second opinion moves from the fit towards the centroid (0: the fit, 1: the
/// centroid) given `ratio`, the centroid's [`local_contrast`] over the fit's: all the way
/// when the centroid stands out by [`ARBITER_TIE`] more, none when it stands out that much
/// less, and in between linearly, so that two positions the measure cannot tell apart meet
/// halfway rather than on the side of a coin flip.
fn centroid_share(ratio: f64) -> f64 {
    (0.5 + (ratio - 1.0) / (2.0 * ARBITER_TIE)).clamp(0.0, 1.0)
}

/// Mean of `values` (row-major h×w) over the pixels whose centres lie within `half` pixels
/// (Chebyshev distance) of continuous position (`row`, `col`), clipped to the image.
fn box_mean(values: &[f64], h: usize, w: usize, row: f64, col: f64, half: f64) -> f64 {
    let range = |centre: f64, n: usize| {
        let lo = (centre - half - 0.5).ceil().max(0.0) as usize;
        let hi = ((centre + half - 0.5).floor().max(-1.0) + 1.0).min(n as f64) as usize;
        lo..hi.max(lo)
    };
    let (rows, cols) = (range(row, h), range(col, w));
    let mut sum = 0.0;
    let mut count = 0usize;
    for r in rows {
        for c in cols.clone() {
            sum += values[r * w + c];
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::highlight::DetectionStatus;

    /// A noise-free grey photo rendered from the detector's own model (vignetting v, beam k).
    fn synthetic(size: usize, lx: f64, ly: f64, alpha: f64, v: f64, k: f64) -> PlanarImage {
        let mut data = Vec::with_capacity(size * size);
        for row in 0..size {
            for col in 0..size {
                let x = ((col as f64 + 0.5) / size as f64) * 2.0 - 1.0;
                let y = 1.0 - ((row as f64 + 0.5) / size as f64) * 2.0;
                let s2 = (x - lx).powi(2) + (y - ly).powi(2);
                let q = 1.0 + s2;
                let lobe = (alpha * alpha / (alpha * alpha + s2)).powi(2) * q.powf(1.5);
                let cos2 = 1.0 / (1.0 + x * x + y * y);
                let l2 = lx * lx + ly * ly;
                let cos_beam = (1.0 + l2 - x * lx - y * ly) / (q.sqrt() * (1.0 + l2).sqrt());
                let camera = (1.0 - v + v * cos2 * cos2) * cos_beam.powf(k);
                let lin = camera * (0.5 * q.powf(-1.5) + 0.4 * lobe) + 0.01;
                data.push(lin.powf(1.0 / 2.2) as f32);
            }
        }
        PlanarImage::new(1, size, size, data).unwrap()
    }

    #[test]
    fn robust_recovers_its_own_model_exactly() {
        // Noise-free, so the misfit is far below the second opinion's threshold.
        for (lx, ly, alpha, v, k) in [
            (0.1, -0.15, 0.1, 0.2, 0.5),
            (-0.3, 0.2, 0.4, 0.4, 1.0),
            (0.0, 0.0, 0.05, 0.0, 0.0),
        ] {
            let image = synthetic(128, lx, ly, alpha, v, k);
            let d = RobustDetector::default().detect(&image).unwrap();
            assert_eq!(d.status, DetectionStatus::Detected, "{d:?}");
            let h = d.highlight();
            // 0.002 plane units = 0.1 % of the width: the grid and f32 input limit the rest.
            assert!(
                (h.x - lx).abs() < 2e-3 && (h.y - ly).abs() < 2e-3,
                "{h:?} vs ({lx}, {ly})"
            );
        }
    }

    #[test]
    fn robust_falls_back_on_black_and_flat_images() {
        let detector = RobustDetector::default();
        let black = detector
            .detect(&PlanarImage::filled(3, 64, 64, 0.0))
            .unwrap();
        assert_eq!(black.status, DetectionStatus::FallbackCentre);
        let flat = detector
            .detect(&PlanarImage::filled(3, 64, 64, 0.5))
            .unwrap();
        assert_eq!(flat.status, DetectionStatus::FallbackCentre, "{flat:?}");
        assert!(flat.reason.unwrap().contains("does not dominate"));
    }

    #[test]
    fn second_opinion_moves_only_far_fits_by_how_much_less_they_stand_out() {
        // A lobe at (0.1, 0): the paper's centroid lands near it.
        let image = synthetic(128, 0.1, 0.0, 0.1, 0.0, 0.0);
        let detector = RobustDetector::default();
        let paper = super::super::PaperDetector::default()
            .detect(&image)
            .unwrap();
        let at = |row: f64, col: f64| Detection::detected(row, col, 128, 128);
        // A fit 30 % of the width away, in the dark: the centroid, with the reason.
        let far = detector
            .second_opinion(
                &image,
                &min_rgb_linear(&image).unwrap(),
                at(64.0, 20.0),
                false,
            )
            .unwrap();
        assert_eq!(far.pixel(), paper.pixel());
        assert!(
            far.reason.as_deref().unwrap().contains("stands out less"),
            "{far:?}"
        );
        // A fit 2 % of the width from the centroid: kept, even if collapsed.
        let (row, col) = (paper.row, paper.col + 2.56);
        let near = detector
            .second_opinion(&image, &min_rgb_linear(&image).unwrap(), at(row, col), true)
            .unwrap();
        assert_eq!((near.pixel(), near.reason), ((row, col), None));
        // Far but on the brighter side: kept, unless its lobe collapsed to a point. Strong
        // vignetting pulls the centroid of a sharp off-centre lobe towards the centre, while
        // the fit sits on the lobe (what the fit of these images gives, up to 0.1 %).
        let on_lobe = at(64.0, 96.0);
        let opinion = |image: &PlanarImage, implausible: bool| {
            let intensity = min_rgb_linear(image).unwrap();
            let centroid = super::super::PaperDetector::default()
                .detect(image)
                .unwrap();
            assert!(
                on_lobe.error_px(centroid.row, centroid.col) > 0.04 * 128.0,
                "{centroid:?}"
            );
            let contrast = |d: &Detection| local_contrast(&intensity, 128, 128, d.row, d.col);
            let share = centroid_share(contrast(&centroid) / contrast(&on_lobe));
            let answer = detector
                .second_opinion(image, &intensity, on_lobe.clone(), implausible)
                .unwrap();
            (answer, centroid, share)
        };
        // A lobe standing out by more than the tie margin: the fit, as it is.
        let sharp = synthetic(128, 0.5, 0.0, 0.08, 1.0, 0.0);
        let (kept, _, share) = opinion(&sharp, false);
        assert_eq!(share, 0.0);
        assert_eq!((kept.pixel(), kept.reason), (on_lobe.pixel(), None));
        // A narrower one, whose few pixels hardly lift the fit's box above the centroid's:
        // part of the way, less than half.
        let pulled = synthetic(128, 0.5, 0.0, 0.03, 1.0, 0.0);
        let (blended, centroid, share) = opinion(&pulled, false);
        assert!(share > 0.0 && share < 0.5, "{share}");
        let expected = (
            on_lobe.row + share * (centroid.row - on_lobe.row),
            on_lobe.col + share * (centroid.col - on_lobe.col),
        );
        assert_eq!(blended.pixel(), expected);
        assert!(
            blended.reason.as_deref().unwrap().contains("about as much"),
            "{blended:?}"
        );
        let (sparkle, centroid, _) = opinion(&pulled, true);
        assert_eq!(sparkle.pixel(), centroid.pixel());
        assert!(
            sparkle.reason.as_deref().unwrap().contains("sparkle"),
            "{sparkle:?}"
        );
        // Off: whatever the fit says.
        let off = RobustDetector {
            max_disagreement: 0.0,
            ..RobustDetector::default()
        };
        assert_eq!(
            off.second_opinion(
                &image,
                &min_rgb_linear(&image).unwrap(),
                at(64.0, 20.0),
                true
            )
            .unwrap()
            .pixel(),
            (64.0, 20.0)
        );
    }
}
