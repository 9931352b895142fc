//! Painted surface: a coat of brushed paint over a slightly uneven substrate, with visible
//! brush strokes, bristle striations and a finish from matte to gloss.
//!
//! Imitates a painted wall, door or board photographed close up. The paint is laid in
//! parallel lanes of strokes (lanes wobble, so they are never ruled lines); each stroke
//! starts with a load of paint that thins towards its end, leaves fine striations from the
//! bristles along its length and ridges where paint was pushed to its edges and its start.
//! Neighbouring strokes overlap softly (their paint is blended over a narrow band) and end
//! raggedly, since every bristle lifts off at its own place. Thicker paint levels out
//! smoother, so the gloss varies slightly with the paint thickness; on some members the
//! brush ran dry and the primer shows where the film is thinnest. Under it all,
//! low-frequency fBm bumps stand for the substrate. Paint is a dielectric (binder
//! n ≈ 1.5: grey F0 0.04-0.05); roughness by finish: matte 0.55-0.75, eggshell 0.38-0.5,
//! satin 0.25-0.38, gloss 0.1-0.22.
//!
//! Maps for `height(ggx, scale=relief)`: diffuse, specular, roughness, height.
//! Per seed: paint colour (any hue, from greys to saturated), finish, stroke direction
//! (0°, 45°, 90°, 135°), lane width and wobble, stroke length, bristle density, ridge
//! strength, dry brushing, primer grey, substrate unevenness.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::PatternFamily;
use super::common::{GgxTexel, Pattern, Streaks, counts, hsv, mix, scale, smoothstep, srgb};
use super::noise::{PeriodicNoise, mix64, unit_f64};

/// Configuration of the paint family; every field has a documented default.
#[derive(Debug, Clone)]
pub struct Paint {
    /// World-space height of the height map's full range (default 0.006: brush marks a
    /// fraction of a millimetre deep on a 10 cm swatch).
    pub relief: f64,
    /// Stroke lanes per unit across the stroke direction, least and most (default 4, 10).
    pub lanes: (u32, u32),
}

impl Default for Paint {
    fn default() -> Self {
        Self {
            relief: 0.006,
            lanes: (4, 10),
        }
    }
}

/// Finishes: (least, most) base roughness of matte, eggshell, satin and gloss paint.
const FINISHES: [(f64, f64); 4] = [(0.55, 0.75), (0.38, 0.5), (0.25, 0.38), (0.1, 0.22)];

/// One member of the family.
pub(crate) struct Coat {
    colour: [f64; 3],
    streaks: Streaks,
    lanes: u32,
    /// How far lanes wobble sideways, in lane widths.
    wobble: f64,
    /// Strokes along one lane per unit of the along coordinate.
    strokes: u32,
    /// Bristle striations per unit across the strokes.
    bristles: u32,
    ridges: f64,
    substrate: f64,
    /// Primer colour and how much of it dry brushing lets through (0: full cover).
    primer: [f64; 3],
    dry: f64,
    roughness: f64,
    f0: f64,
    seed: u64,
    noise: [PeriodicNoise; 3],
}

impl PatternFamily for Paint {
    const NAME: &'static str = "paint";
    type Member = Coat;

    fn brdf(&self) -> String {
        format!("height(ggx, scale={})", self.relief)
    }

    fn member(&self, seed: u64) -> Coat {
        let mut rng = StdRng::seed_from_u64(seed);
        // Greys half as often as colours; values kept off pure black and white.
        let saturation = if rng.random_bool(0.3) {
            rng.random_range(0.0..0.08)
        } else {
            rng.random_range(0.2..0.85)
        };
        let colour = srgb(hsv(
            rng.random_range(0.0..1.0),
            saturation,
            rng.random_range(0.25..0.92),
        ));
        let (r0, r1) = FINISHES[rng.random_range(0..FINISHES.len())];
        Coat {
            colour,
            streaks: Streaks::random(&mut rng),
            lanes: rng.random_range(counts(self.lanes, 1)),
            wobble: rng.random_range(0.15..0.35),
            strokes: rng.random_range(1..=3),
            bristles: rng.random_range(50..120),
            ridges: rng.random_range(0.15..0.4),
            substrate: rng.random_range(0.05..0.25),
            primer: srgb([rng.random_range(0.6..0.9); 3]),
            dry: if rng.random_bool(0.4) {
                rng.random_range(0.2..0.45)
            } else {
                0.0
            },
            roughness: rng.random_range(r0..r1),
            f0: rng.random_range(0.04..0.05),
            seed: rng.random(),
            noise: [(); 3].map(|_| PeriodicNoise::new(rng.random())),
        }
    }
}

/// Width of the blend between neighbouring lanes, in lane widths, and between consecutive
/// strokes, in stroke lengths: strokes overlap softly instead of meeting at a cut.
const LANE_FEATHER: f64 = 0.1;
const STROKE_FEATHER: f64 = 0.06;

/// Weight of the nearer neighbour at fraction `t` ∈ [0, 1) of a cell: ½ on the border,
/// 0 beyond `feather`; returns the neighbour's offset (−1 or +1), its weight and the
/// distance to the border.
fn neighbour(t: f64, feather: f64) -> (i64, f64, f64) {
    let (side, d) = if t < 0.5 { (-1, t) } else { (1, 1.0 - t) };
    (side, 0.5 * (1.0 - smoothstep(0.0, feather, d)), d)
}

impl Coat {
    /// Paint of stroke `stroke` in lane `lane` (both wrapped) at (along, across): bristle
    /// striation in [−1, 1] and paint load (thins from 1 at the start to 0.6 at the end).
    fn stroke(&self, lane: i64, stroke: i64, ts: f64, along: f64, across: f64) -> (f64, f64) {
        let lane = lane.rem_euclid(self.lanes as i64) as u64;
        let stroke = stroke.rem_euclid(self.strokes as i64) as u64;
        let id = mix64(self.seed ^ (lane << 8 | stroke).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        // Bristle marks: dense across the stroke, long along it, different in every stroke.
        let shift = unit_f64(id);
        let bristle = self.noise[1].fbm_xy(across, along + shift, (self.bristles, 2), 2);
        let load = (0.6 + 0.4 * unit_f64(mix64(id))) * (1.0 - 0.5 * ts);
        (bristle, load)
    }
}

impl Pattern for Coat {
    type Texel = GgxTexel;

    fn sample(&self, u: f64, v: f64) -> GgxTexel {
        let (along, across) = self.streaks.apply(u, v);
        let [n0, n1, n2] = &self.noise;
        let lanes = self.lanes as f64;
        let a = (across + self.wobble / lanes * n0.fbm(u, v, 2, 3)) * lanes;
        let lane = a.floor() as i64;
        let (side, lane_blend, lane_edge) = neighbour(a - a.floor(), LANE_FEATHER);
        // Blend this lane's stroke with the nearer neighbour lane's, and in each lane the
        // stroke with the nearer consecutive one: the paint field is continuous.
        let (mut bristle, mut load, mut stroke_edge) = (0.0, 0.0, 0.0);
        for (l, wl) in [(lane, 1.0 - lane_blend), (lane + side, lane_blend)] {
            let offset = unit_f64(mix64(self.seed ^ l.rem_euclid(self.lanes as i64) as u64));
            // Ragged ends: every bristle lifts off at a slightly different place.
            let ragged = 0.08 * n1.value_xy(across, along, (self.bristles / 3, 2), 7);
            let s = (along + offset) * self.strokes as f64 + ragged;
            let (k, ts) = (s.floor() as i64, s - s.floor());
            let (step, stroke_blend, edge) = neighbour(ts, STROKE_FEATHER);
            // Position in the neighbour stroke: just past its end (ts + 1 > 1) for the previous
            // one, just before its start (ts − 1 < 0) for the next; its taper extends linearly.
            let next_ts = if step > 0 { ts - 1.0 } else { ts + 1.0 };
            for (kk, t, ws) in [
                (k, ts, 1.0 - stroke_blend),
                (k + step, next_ts, stroke_blend),
            ] {
                let (b, p) = self.stroke(l, kk, t, along, across);
                bristle += wl * ws * b;
                load += wl * ws * p;
            }
            stroke_edge += wl * (1.0 - smoothstep(0.0, 0.03, edge));
        }
        // Ridges where paint was pushed to a stroke's sides and piled at its start.
        let ridge = self.ridges * ((1.0 - smoothstep(0.0, 0.08, lane_edge)) + 0.6 * stroke_edge);
        let film = load * (0.6 + 0.4 * bristle); // paint film between the bristle marks
        let thickness = film + ridge;
        let substrate = n2.fbm(u, v, 5, 4);
        // Dry brushing: where the film is thinnest the primer shows through.
        let cover = 1.0 - self.dry * (1.0 - smoothstep(0.1, 0.35, film));
        let paint = scale(self.colour, (1.0 + 0.04 * bristle) * (0.85 + 0.15 * load));
        GgxTexel {
            diffuse: mix(self.primer, paint, cover),
            specular: [self.f0; 3],
            // Thicker paint levels out smoother.
            roughness: self.roughness + 0.12 * (1.0 - load) + 0.04 * bristle,
            height: 0.35 + 0.4 * thickness + self.substrate * substrate,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural::common::testing::channel_stats;

    #[test]
    fn paint_is_a_dielectric_with_slight_gloss_variation() {
        for seed in 0..12 {
            let s = channel_stats(&Paint::default().member(seed));
            assert!(
                (0.04..=0.05).contains(&s[3].1),
                "seed {seed}: F0 {:?}",
                s[3]
            );
            let r = s[6];
            assert!((0.1..0.85).contains(&r.1), "seed {seed}: roughness {r:?}");
            // Slight: visible but within ±0.15 of the mean.
            assert!(
                r.2 - r.0 > 0.03 && r.2 - r.0 < 0.3,
                "seed {seed}: roughness {r:?}"
            );
        }
    }

    #[test]
    fn paint_strokes_are_thick_at_the_start_and_thin_at_the_end() {
        for seed in 0..6 {
            // Straight lanes along u, so that (u, v) = (along, across) is known exactly.
            let mut coat = Paint::default().member(seed);
            coat.wobble = 0.0;
            coat.streaks = Streaks { a: 1, b: 0 };
            let lanes = coat.lanes as f64;
            let (mut start, mut end) = (0.0, 0.0);
            for lane in 0..coat.lanes as u64 {
                // Strokes start where (along + offset)·strokes is whole.
                let offset = unit_f64(mix64(coat.seed ^ lane));
                let at = |ts: f64, ta: f64| {
                    let u = (1.0 + ts) / coat.strokes as f64 - offset;
                    coat.sample(u, (lane as f64 + ta) / lanes).height
                };
                for k in 0..20 {
                    let ta = 0.2 + 0.6 * k as f64 / 20.0; // clear of the edge ridges
                    start += at(0.1, ta);
                    end += at(0.9, ta);
                }
            }
            assert!(start > end, "seed {seed}: {start} vs {end}");
        }
    }
}
