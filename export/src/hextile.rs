//! HexTiling: Mikkelsen, "Practical Real-Time Hex-Tiling", JCGT 11(2), 2022.
//!
//! A periodic texture repeated over a large area shows its period. Hex-tiling hides it: the
//! output plane is covered by a triangular lattice whose vertices are the centres of hexagonal
//! tiles; every output texel lies in one lattice triangle and blends three copies of the input,
//! one per triangle vertex, each shifted by a random offset (and optionally rotated about the
//! vertex) drawn for that vertex. The paper's barycentric weights `w_i` vanish on the far edges
//! of each hexagon, so the blend is continuous everywhere.
//!
//! Weights, as in the paper's reference code (`hex2colTex`):
//! `W_i ∝ D_i · w_i^γ` with γ = [`HexTiling::exponent`] (paper: 7) and the luminance-based
//! contrast-preserving factor `D_i = lerp(1, L(c_i), k)` (k = [`HexTiling::contrast`], paper
//! 0.6; L = 0.299 R + 0.587 G + 0.114 B of the guide's sample), which lets bright features win
//! over dark ones instead of being averaged away; optionally sharpened by the paper's `Gain3`
//! with r = [`HexTiling::gain`] (0.5 = off). Implemented: all of it.
//!
//! Deviations, for a material rather than one texture:
//! - **one lattice for every map**: [`hextile`] computes the weights once per output texel
//!   (from an optional `guide`, e.g. the diffuse albedo) and applies them, with the same
//!   offsets and rotations, to every map, so diffuse, roughness and normals stay aligned;
//! - tangent-space normal maps ([`Content::TangentNormal`]) have their xy rotated with the
//!   copy they come from and are renormalised after blending;
//! - the per-vertex offsets and angles come from a seeded SplitMix64 hash of the vertex
//!   (the paper's `sin`-based hash depends on the GPU's `sin` precision): deterministic per
//!   [`HexTiling::seed`] on every machine.
//!
//! Sampling is bilinear with wrap-around; the input must be periodic (tileable), otherwise its
//! own seam reappears inside the hexagons.
//!
//! # Shapes
//! Inputs (C, h, w) planar images, all of one size; outputs (C, out_h, out_w), the same texel
//! density (an output of 2h × 2w covers 2 × 2 input periods).

use photomat_core::image_io::PlanarImage;
use photomat_core::rng::SplitMix64;
use photomat_core::{Error, Result};
use rayon::prelude::*;

/// √3.
const SQRT3: f64 = 1.732_050_807_568_877_2;

/// HexTiling parameters. `Default` is the paper's defaults without rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HexTiling {
    /// Seed of the per-vertex offsets and rotations.
    pub seed: u64,
    /// Lattice density: hexagon centres are `1/(2√3·rate)` input periods apart
    /// (≈ 0.29 periods at rate 1). Default 1.
    pub rate: f64,
    /// Rotation of the copies, 0 (none, default: keeps directional structure such as wood
    /// grain and brushed metal) to 1 (uniform in [−π, π)).
    pub rotation: f64,
    /// Exponent γ of the barycentric weights (paper: 7); larger → narrower transitions.
    pub exponent: f64,
    /// Contrast-preservation strength k in [0, 1] (paper: 0.6); 0 = plain barycentric blend.
    pub contrast: f64,
    /// The paper's `Gain3` r in (0, 1): > 0.5 sharpens the transitions; 0.5 = off (default).
    pub gain: f64,
}

impl Default for HexTiling {
    fn default() -> Self {
        Self {
            seed: 0,
            rate: 1.0,
            rotation: 0.0,
            exponent: 7.0,
            contrast: 0.6,
            gain: 0.5,
        }
    }
}

/// How a map's channels behave under rotation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Content {
    /// Values blended as they are (colours, roughness, height).
    Scalar,
    /// Unit vectors (x right, y up, z out): xy rotated with the copy, renormalised after blending.
    TangentNormal,
}

/// One lattice vertex's copy of the input: its centre, offset and rotation.
#[derive(Debug, Clone, Copy)]
struct Copy {
    center: [f64; 2],
    offset: [f64; 2],
    cos: f64,
    sin: f64,
}

impl HexTiling {
    fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::Invalid(format!("hex-tiling: {what}")));
        if !(self.rate.is_finite() && self.rate > 0.0) {
            return bad(format!("rate must be positive, got {}", self.rate));
        }
        if !(0.0..=1.0).contains(&self.rotation) {
            return bad(format!("rotation must be in [0, 1], got {}", self.rotation));
        }
        if !(self.exponent.is_finite() && self.exponent >= 1.0) {
            return bad(format!("exponent must be ≥ 1, got {}", self.exponent));
        }
        if !(0.0..=1.0).contains(&self.contrast) {
            return bad(format!("contrast must be in [0, 1], got {}", self.contrast));
        }
        if !(self.gain > 0.0 && self.gain < 1.0) {
            return bad(format!("gain must be in (0, 1), got {}", self.gain));
        }
        Ok(())
    }

    /// The copy of lattice vertex `v` (skewed integer coordinates).
    fn copy(&self, v: [i64; 2]) -> Copy {
        let key = (v[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (v[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        let mut rng = SplitMix64(self.seed ^ key);
        let offset = [rng.next_unit(), rng.next_unit()];
        let angle = self.rotation * std::f64::consts::TAU * (rng.next_unit() - 0.5);
        // Paper's MakeCenST: the vertex back in unskewed coordinates, in input periods.
        let (x, y) = (v[0] as f64, v[1] as f64);
        let center = [
            (x + 0.5 * y) / (2.0 * SQRT3 * self.rate),
            (y * SQRT3 / 2.0) / (2.0 * SQRT3 * self.rate),
        ];
        Copy {
            center,
            offset,
            cos: angle.cos(),
            sin: angle.sin(),
        }
    }
}

/// The paper's `TriangleGrid`: barycentric weights and the three vertices (skewed lattice
/// coordinates) of the lattice triangle holding `st` (input periods).
fn triangle_grid(st: [f64; 2], rate: f64) -> ([f64; 3], [[i64; 2]; 3]) {
    let scale = 2.0 * SQRT3 * rate;
    let (x, y) = (st[0] * scale, st[1] * scale);
    // gridToSkewedGrid = [[1, −1/√3], [0, 2/√3]].
    let skewed = [x - y / SQRT3, 2.0 * y / SQRT3];
    let base = [skewed[0].floor(), skewed[1].floor()];
    let (fx, fy) = (skewed[0] - base[0], skewed[1] - base[1]);
    let z = 1.0 - fx - fy;
    let s = if z < 0.0 { 1.0 } else { 0.0 };
    let s2 = 2.0 * s - 1.0;
    let w = [-z * s2, s - fy * s2, s - fx * s2];
    let (bx, by, si) = (base[0] as i64, base[1] as i64, s as i64);
    (
        w,
        [
            [bx + si, by + si],
            [bx + si, by + 1 - si],
            [bx + 1 - si, by + si],
        ],
    )
}

/// Bilinear sample with wrap-around of channel plane `plane` at texel coordinates (x, y)
/// (texel centres at integers + ½).
fn sample(image: &PlanarImage, c: usize, x: f64, y: f64) -> f64 {
    let (w, h) = (image.width as i64, image.height as i64);
    let (x, y) = (x - 0.5, y - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |col: i64, row: i64| {
        image.get(c, row.rem_euclid(h) as usize, col.rem_euclid(w) as usize) as f64
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
    let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
    top * (1.0 - fy) + bottom * fy
}

/// The paper's `Gain3`: sharpen (r > ½) or soften (r < ½) normalised weights, renormalised.
fn gain3(w: [f64; 3], r: f64) -> [f64; 3] {
    let k = (1.0 - r).ln() / 0.5f64.ln();
    let g = w.map(|x| {
        let s = if x >= 0.5 { 2.0 } else { 0.0 };
        let m = 2.0 * (1.0 - s);
        0.5 * s + 0.25 * m * (s + x * m).max(0.0).powf(k)
    });
    let sum: f64 = g.iter().sum();
    g.map(|x| x / sum)
}

/// Luminance of a guide sample (1 channel: the value; 3: the paper's weights), clamped to
/// [0, 1] as the paper's LDR textures are.
fn luminance(guide: &PlanarImage, x: f64, y: f64) -> f64 {
    let l = match guide.channels {
        3 => [0.299, 0.587, 0.114]
            .iter()
            .enumerate()
            .map(|(c, k)| k * sample(guide, c, x, y))
            .sum(),
        _ => sample(guide, 0, x, y),
    };
    l.clamp(0.0, 1.0)
}

/// Hex-tile `inputs` (all of one size) to `out_height × out_width` texels with one lattice;
/// `guide` (same size as the inputs, 1 or 3 channels, display-encoded values in [0, 1]) drives
/// the contrast-preserving weights — without one the plain barycentric weights are used.
pub fn hextile(
    tiling: &HexTiling,
    inputs: &[(&PlanarImage, Content)],
    guide: Option<&PlanarImage>,
    out_height: usize,
    out_width: usize,
) -> Result<Vec<PlanarImage>> {
    tiling.validate()?;
    let Some((first, _)) = inputs.first() else {
        return Err(Error::Invalid("hex-tiling needs at least one image".into()));
    };
    let (h, w) = (first.height, first.width);
    let same = |i: &PlanarImage| i.height == h && i.width == w && i.texels() > 0;
    if let Some((bad, _)) = inputs.iter().find(|(i, _)| !same(i)) {
        return Err(Error::Invalid(format!(
            "hex-tiling inputs differ in size: {h}×{w} and {}×{}",
            bad.height, bad.width
        )));
    }
    if let Some((bad, _)) = inputs
        .iter()
        .find(|(i, c)| *c == Content::TangentNormal && i.channels != 3)
    {
        return Err(Error::Invalid(format!(
            "a tangent-space normal map has 3 channels, got {}",
            bad.channels
        )));
    }
    if let Some(g) = guide
        && (!same(g) || !matches!(g.channels, 1 | 3))
    {
        return Err(Error::Invalid(format!(
            "the hex-tiling guide must be {h}×{w} with 1 or 3 channels, got {}×{}×{}",
            g.channels, g.height, g.width
        )));
    }
    if out_height == 0 || out_width == 0 {
        return Err(Error::Invalid("hex-tiling output must not be empty".into()));
    }
    // Rows are independent: one task per row, each returning its row of every output.
    let rows: Vec<Vec<Vec<f32>>> = (0..out_height)
        .into_par_iter()
        .map(|row| hextile_row(tiling, inputs, guide, row, out_width))
        .collect();
    let mut outputs: Vec<PlanarImage> = inputs
        .iter()
        .map(|(i, _)| PlanarImage::filled(i.channels, out_height, out_width, 0.0))
        .collect();
    for (row, values) in rows.iter().enumerate() {
        for (output, values) in outputs.iter_mut().zip(values) {
            for c in 0..output.channels {
                let dst = (c * out_height + row) * out_width;
                output.data[dst..dst + out_width]
                    .copy_from_slice(&values[c * out_width..(c + 1) * out_width]);
            }
        }
    }
    Ok(outputs)
}

/// Row `row` of every output of [`hextile`]: per input, its channels one after the other
/// (`channels × out_width` values).
fn hextile_row(
    tiling: &HexTiling,
    inputs: &[(&PlanarImage, Content)],
    guide: Option<&PlanarImage>,
    row: usize,
    out_width: usize,
) -> Vec<Vec<f32>> {
    let (h, w) = (inputs[0].0.height, inputs[0].0.width);
    let mut rows: Vec<Vec<f32>> = inputs
        .iter()
        .map(|(i, _)| vec![0.0; i.channels * out_width])
        .collect();
    for col in 0..out_width {
        let st = [(col as f64 + 0.5) / w as f64, (row as f64 + 0.5) / h as f64];
        let (bary, vertices) = triangle_grid(st, tiling.rate);
        let copies = vertices.map(|v| tiling.copy(v));
        // Where copy i samples, in input texel coordinates.
        let at = copies.map(|k| {
            let d = [st[0] - k.center[0], st[1] - k.center[1]];
            let s = k.cos * d[0] + k.sin * d[1] + k.center[0] + k.offset[0];
            let t = -k.sin * d[0] + k.cos * d[1] + k.center[1] + k.offset[1];
            (s * w as f64, t * h as f64)
        });
        let mut weights = [0.0; 3];
        for i in 0..3 {
            let d = match guide {
                Some(g) => {
                    let l = luminance(g, at[i].0, at[i].1);
                    1.0 + tiling.contrast * (l - 1.0)
                }
                None => 1.0,
            };
            weights[i] = d * bary[i].max(0.0).powf(tiling.exponent);
        }
        let sum: f64 = weights.iter().sum();
        // Exactly one barycentric weight can be 1 and the others 0, never all 0; D ≥ 1 − k
        // > 0 unless k = 1 with a black guide, where the plain weights take over.
        let weights = if sum > 1e-300 {
            weights.map(|x| x / sum)
        } else {
            let plain = bary.map(|b| b.max(0.0).powf(tiling.exponent));
            let s: f64 = plain.iter().sum();
            plain.map(|x| x / s)
        };
        let weights = if tiling.gain == 0.5 {
            weights
        } else {
            gain3(weights, tiling.gain)
        };
        for ((input, content), output) in inputs.iter().zip(rows.iter_mut()) {
            match content {
                Content::Scalar => {
                    for c in 0..input.channels {
                        let v: f64 = (0..3)
                            .map(|i| weights[i] * sample(input, c, at[i].0, at[i].1))
                            .sum();
                        output[c * out_width + col] = v as f32;
                    }
                }
                Content::TangentNormal => {
                    let mut n = [0.0f64; 3];
                    for i in 0..3 {
                        let v = [0, 1, 2].map(|c| sample(input, c, at[i].0, at[i].1));
                        // The copy's content turns by −θ in the y-up frame (θ acts on
                        // (s, t) with t pointing down the rows).
                        let (cs, sn) = (copies[i].cos, copies[i].sin);
                        n[0] += weights[i] * (cs * v[0] + sn * v[1]);
                        n[1] += weights[i] * (-sn * v[0] + cs * v[1]);
                        n[2] += weights[i] * v[2];
                    }
                    let len = n.iter().map(|x| x * x).sum::<f64>().sqrt();
                    // Blends of upper-hemisphere unit vectors have z > 0: len > 0.
                    let n = if len > 1e-12 {
                        n.map(|x| x / len)
                    } else {
                        [0.0, 0.0, 1.0]
                    };
                    for (c, x) in n.iter().enumerate() {
                        output[c * out_width + col] = *x as f32;
                    }
                }
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_grid_weights_are_barycentric() {
        for k in 0..200 {
            let st = [0.013 * k as f64, 0.0071 * (k * k % 97) as f64];
            let (w, v) = triangle_grid(st, 1.0);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{w:?}");
            assert!(
                w.iter().all(|&x| (-1e-12..=1.0 + 1e-12).contains(&x)),
                "{w:?}"
            );
            // The weighted vertex positions reproduce the point (barycentric interpolation).
            let t = HexTiling::default();
            let p = v.map(|v| t.copy(v).center);
            let x: f64 = (0..3).map(|i| w[i] * p[i][0]).sum();
            let y: f64 = (0..3).map(|i| w[i] * p[i][1]).sum();
            assert!(
                (x - st[0]).abs() < 1e-9 && (y - st[1]).abs() < 1e-9,
                "{st:?}"
            );
        }
    }

    #[test]
    fn gain3_at_half_is_identity_and_sharpens_above() {
        let w = [0.6, 0.3, 0.1];
        let same = gain3(w, 0.5);
        assert!((0..3).all(|i| (same[i] - w[i]).abs() < 1e-12), "{same:?}");
        let sharp = gain3(w, 0.8);
        assert!(sharp[0] > w[0] && sharp[2] < w[2], "{sharp:?}");
    }
}
