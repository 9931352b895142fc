//! What every family shares: per-texel values of the models the families target, the
//! point-sampled [`Pattern`] a family member is, the loop that turns a pattern into
//! [`MaterialMaps`], and small shaping and colour helpers.
//!
//! A family draws a *member* from a seed (colours, scales, orientation); the member is a pure
//! function of the texture coordinates (u, v) ∈ [0, 1)², u right and v down, periodic with
//! period 1 in both, evaluated at texel centres. Because members are point functions of
//! continuous coordinates, one seed gives the same material at every resolution.

use candle_core::{Device, Tensor};
use photomat_core::{MaterialMaps, Result};
use rand::Rng;

/// Values of one texel, in the order of the maps named by [`TexelValues::MAPS`].
pub(crate) trait TexelValues {
    /// (map name, channels) in the order [`TexelValues::write`] fills.
    const MAPS: &'static [(&'static str, usize)];

    /// Writes the texel's values, map after map, into `out` (length = total channels).
    fn write(&self, out: &mut [f64]);
}

/// One texel of a `height(ggx, …)` material: Lambert + GGX maps plus a height in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GgxTexel {
    /// Diffuse albedo ρ_d, linear rgb.
    pub diffuse: [f64; 3],
    /// Schlick F0, linear rgb.
    pub specular: [f64; 3],
    /// Perceptual roughness (GGX α = r²).
    pub roughness: f64,
    /// Height as a fraction of the adapter's `scale`.
    pub height: f64,
}

impl TexelValues for GgxTexel {
    const MAPS: &'static [(&'static str, usize)] = &[
        ("diffuse", 3),
        ("specular", 3),
        ("roughness", 1),
        ("height", 1),
    ];

    fn write(&self, out: &mut [f64]) {
        out[..3].copy_from_slice(&self.diffuse);
        out[3..6].copy_from_slice(&self.specular);
        out[6] = self.roughness;
        out[7] = self.height;
    }
}

/// One texel of a `coated` material: Lambert + two GGX lobes, flat normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CoatedTexel {
    /// Diffuse albedo ρ_d, linear rgb.
    pub diffuse: [f64; 3],
    /// Lobe 1 (broad, metallic flakes) Schlick F0, linear rgb.
    pub specular: [f64; 3],
    /// Lobe 1 perceptual roughness.
    pub roughness: f64,
    /// Lobe 2 (sharp clear coat) Schlick F0, linear rgb.
    pub specular2: [f64; 3],
    /// Lobe 2 perceptual roughness.
    pub roughness2: f64,
}

impl TexelValues for CoatedTexel {
    const MAPS: &'static [(&'static str, usize)] = &[
        ("diffuse", 3),
        ("specular", 3),
        ("roughness", 1),
        ("specular2", 3),
        ("roughness2", 1),
    ];

    fn write(&self, out: &mut [f64]) {
        out[..3].copy_from_slice(&self.diffuse);
        out[3..6].copy_from_slice(&self.specular);
        out[6] = self.roughness;
        out[7..10].copy_from_slice(&self.specular2);
        out[10] = self.roughness2;
    }
}

/// One member of a family: texel values as a function of texture coordinates, periodic with
/// period 1 in u and v.
pub(crate) trait Pattern {
    /// What one texel holds.
    type Texel: TexelValues;

    /// The texel at texture coordinates (u right, v down); any real u, v (periodic).
    fn sample(&self, u: f64, v: f64) -> Self::Texel;
}

/// Most channels any [`TexelValues`] writes (coated: 11).
const MAX_CHANNELS: usize = 16;

/// Samples `pattern` at the centres of a size × size grid: maps (1, C, size, size), f32.
///
/// Every map of the models the families target (`ggx`, `coated`, `height`) has the physical
/// range [0, 1]; values are clamped into it here, once, so that a rare noise extreme can never
/// leave the model's range (the families keep their values inside it by construction).
pub(crate) fn sample_maps<P: Pattern>(
    pattern: &P,
    size: usize,
    device: &Device,
) -> Result<MaterialMaps> {
    let layout = P::Texel::MAPS;
    let channels: usize = layout.iter().map(|(_, c)| c).sum();
    assert!(
        channels <= MAX_CHANNELS,
        "texel layout wider than MAX_CHANNELS"
    );
    let plane = size * size;
    let mut data = vec![0f32; channels * plane];
    let mut texel = [0f64; MAX_CHANNELS];
    for row in 0..size {
        let v = (row as f64 + 0.5) / size as f64;
        for col in 0..size {
            let u = (col as f64 + 0.5) / size as f64;
            pattern.sample(u, v).write(&mut texel[..channels]);
            for (c, value) in texel[..channels].iter().enumerate() {
                data[c * plane + row * size + col] = value.clamp(0.0, 1.0) as f32;
            }
        }
    }
    let mut maps = MaterialMaps::new();
    let mut first = 0;
    for &(name, c) in layout {
        let values = data[first * plane..(first + c) * plane].to_vec();
        maps.insert(name, Tensor::from_vec(values, (1, c, size, size), device)?);
        first += c;
    }
    Ok(maps)
}

/// A configured (least, most) count range made safe to draw from: least at least `floor`
/// (a count below it would leave nothing to draw or a zero period), most at least least (a
/// reversed range draws the least).
pub(crate) fn counts((least, most): (u32, u32), floor: u32) -> std::ops::RangeInclusive<u32> {
    let least = least.max(floor);
    least..=most.max(least)
}

/// Hermite smoothstep on [e0, e1] (e0 < e1): 0 below, 1 above, C¹ in between.
pub(crate) fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Linear interpolation a + (b − a)·t.
pub(crate) fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// Component-wise [`lerp`] of two colours.
pub(crate) fn mix(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    [
        lerp(a[0], b[0], t),
        lerp(a[1], b[1], t),
        lerp(a[2], b[2], t),
    ]
}

/// Colour times a scalar.
pub(crate) fn scale(c: [f64; 3], k: f64) -> [f64; 3] {
    c.map(|x| x * k)
}

/// The fractional part in [0, 1), also for negative x (`f64::fract` keeps the sign).
pub(crate) fn wrap01(x: f64) -> f64 {
    x - x.floor()
}

/// sRGB-encoded colour (what a colour picker shows) → linear reflectance (IEC 61966-2-1).
pub(crate) fn srgb(c: [f64; 3]) -> [f64; 3] {
    c.map(|x| {
        if x <= 0.04045 {
            x / 12.92
        } else {
            ((x + 0.055) / 1.055).powf(2.4)
        }
    })
}

/// Hue (turns, any real), saturation and value in [0, 1] → sRGB-encoded colour.
pub(crate) fn hsv(h: f64, s: f64, v: f64) -> [f64; 3] {
    let k = |n: f64| {
        let k = (n + 6.0 * wrap01(h)) % 6.0;
        v - v * s * k.min(4.0 - k).clamp(0.0, 1.0) // the trapezoid ramp of each channel
    };
    [k(5.0), k(3.0), k(1.0)]
}

/// Multiplies each channel of a colour by an independent factor from `1 ± amount`, drawn
/// from `rng` (colour variation between members of a family).
pub(crate) fn jitter<R: Rng>(rng: &mut R, c: [f64; 3], amount: f64) -> [f64; 3] {
    c.map(|x| x * rng.random_range(1.0 - amount..=1.0 + amount))
}

/// One of the 8 symmetries of the square (quarter turns and mirror images) applied to texture
/// coordinates: the symmetries that keep a unit-periodic pattern unit-periodic, used to
/// orient a member (grain along x or y, mirrored or not).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Symmetry(u8);

impl Symmetry {
    /// A uniformly random symmetry.
    pub fn random<R: Rng>(rng: &mut R) -> Self {
        Self(rng.random_range(0..8))
    }

    /// Pattern coordinates of texture coordinates (u, v).
    pub fn apply(self, u: f64, v: f64) -> (f64, f64) {
        let (x, y) = if self.0 & 1 == 0 { (u, v) } else { (v, u) };
        let x = if self.0 & 2 == 0 { x } else { -x };
        let y = if self.0 & 4 == 0 { y } else { -y };
        (x, y)
    }
}

/// A direction on the unit torus with integer components, for streaks at 0°, 45°, 90° or
/// 135°: the coordinates `along = a·u + b·v` and `across = −b·u + a·v` are integer
/// combinations of (u, v), so any unit-periodic function of them is unit-periodic in (u, v).
/// (Along a diagonal the pattern repeats twice per square, invisible for fine streaks.)
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Streaks {
    pub a: i8,
    pub b: i8,
}

impl Streaks {
    /// One of the four directions, uniformly.
    pub fn random<R: Rng>(rng: &mut R) -> Self {
        let (a, b) = [(1, 0), (0, 1), (1, 1), (1, -1)][rng.random_range(0..4)];
        Self { a, b }
    }

    /// (along, across) coordinates of texture coordinates (u, v).
    pub fn apply(self, u: f64, v: f64) -> (f64, f64) {
        let (a, b) = (self.a as f64, self.b as f64);
        (a * u + b * v, -b * u + a * v)
    }
}

/// Test helpers shared by the families' unit tests.
#[cfg(test)]
pub(crate) mod testing {
    use super::*;

    /// All channels of one texel as a vector.
    pub fn texel<P: Pattern>(pattern: &P, u: f64, v: f64) -> Vec<f64> {
        let mut out = vec![0.0; P::Texel::MAPS.iter().map(|(_, c)| c).sum()];
        pattern.sample(u, v).write(&mut out);
        out
    }

    /// Asserts that `pattern` is periodic with period 1 in u and v at 500 scattered points.
    /// Shifts by whole periods change the last bits of the coordinates only, so values agree
    /// to 1e-6 except within ~1e-15 of a discontinuity (none of the points is that close).
    pub fn assert_periodic<P: Pattern>(pattern: &P) {
        for k in 0..500 {
            let (u, v) = (
                wrap01(k as f64 * 0.618_034),
                wrap01(k as f64 * 0.414_214 + 0.1),
            );
            let here = texel(pattern, u, v);
            for (du, dv) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 2.0)] {
                let there = texel(pattern, u + du, v + dv);
                let worst = here
                    .iter()
                    .zip(&there)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(
                    worst < 1e-6,
                    "not periodic at ({u}, {v}) + ({du}, {dv}): {worst}"
                );
            }
        }
    }

    /// Per-channel (min, mean, max) of `pattern` over 4096 points of the R2 low-discrepancy
    /// sequence (Roberts 2018): unlike a regular grid, it cannot alias with a periodic
    /// pattern whose period divides the grid's.
    pub fn channel_stats<P: Pattern>(pattern: &P) -> Vec<(f64, f64, f64)> {
        let n = 4096;
        let mut stats: Vec<(f64, f64, f64)> = Vec::new();
        for k in 0..n {
            let (u, v) = (
                wrap01(k as f64 * 0.754_877_666),
                wrap01(k as f64 * 0.569_840_291),
            );
            let t = texel(pattern, u, v);
            if stats.is_empty() {
                stats = vec![(f64::INFINITY, 0.0, f64::NEG_INFINITY); t.len()];
            }
            for (s, x) in stats.iter_mut().zip(t) {
                *s = (s.0.min(x), s.1 + x / n as f64, s.2.max(x));
            }
        }
        stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::StdRng;

    #[test]
    fn srgb_and_hsv_match_known_values() {
        assert!((srgb([0.5; 3])[0] - 0.214_041).abs() < 1e-6);
        assert_eq!(srgb([0.0, 1.0, 0.02]), [0.0, 1.0, 0.02 / 12.92]);
        assert_eq!(hsv(0.0, 1.0, 1.0), [1.0, 0.0, 0.0]);
        assert_eq!(hsv(1.0 / 3.0, 1.0, 0.5), [0.0, 0.5, 0.0]);
        assert_eq!(hsv(2.0 / 3.0, 0.0, 0.7), [0.7; 3]);
    }

    #[test]
    fn counts_are_never_empty_nor_below_the_floor() {
        assert_eq!(counts((4, 10), 1), 4..=10);
        assert_eq!(counts((0, 0), 1), 1..=1);
        assert_eq!(counts((12, 3), 2), 12..=12);
        assert_eq!(counts((3, 40), 8), 8..=40);
    }

    #[test]
    fn symmetries_and_streaks_keep_unit_periods() {
        // Every symmetry and direction maps a whole-period shift of (u, v) to a whole-period
        // shift of the pattern coordinates.
        let mut rng = StdRng::seed_from_u64(0);
        for _ in 0..64 {
            let (s, d) = (Symmetry::random(&mut rng), Streaks::random(&mut rng));
            let whole = |x: f64| (x.round() - x).abs() < 1e-12;
            for (a, b) in [
                (s.apply(0.3, 0.7), s.apply(1.3, -1.3)),
                (d.apply(0.3, 0.7), d.apply(2.3, -0.3)),
            ] {
                assert!(whole(a.0 - b.0) && whole(a.1 - b.1), "{s:?} {d:?}");
            }
        }
    }

    struct Ramp;

    impl Pattern for Ramp {
        type Texel = CoatedTexel;
        fn sample(&self, u: f64, v: f64) -> CoatedTexel {
            CoatedTexel {
                diffuse: [u, v, 2.0],
                specular: [0.1, 0.2, 0.3],
                roughness: -1.0,
                specular2: [0.4; 3],
                roughness2: u * v,
            }
        }
    }

    #[test]
    fn sample_maps_lays_out_channels_at_texel_centres_and_clamps_to_the_range() {
        let maps = sample_maps(&Ramp, 4, &Device::Cpu).unwrap();
        assert_eq!(
            maps.names(),
            [
                "diffuse",
                "roughness",
                "roughness2",
                "specular",
                "specular2"
            ]
        );
        let diffuse: Vec<f32> = maps
            .get("diffuse")
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert_eq!(diffuse.len(), 48);
        assert_eq!(&diffuse[..4], &[0.125, 0.375, 0.625, 0.875]); // u of row 0
        assert_eq!(diffuse[16 + 4], 0.375); // v of row 1
        assert!(diffuse[32..].iter().all(|&x| x == 1.0)); // 2 clamped to 1
        let r: Vec<f32> = maps
            .get("roughness")
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        assert!(r.iter().all(|&x| x == 0.0)); // −1 clamped to 0
    }
}
