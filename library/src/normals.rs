//! Tangent-space normal maps read into photomat's convention (docs/conventions.md, "Normal
//! maps of imported materials"): `n = 2·rgb − 1` with x along the image's columns (right), y
//! up the image (towards row 0) and z out of the surface, the "OpenGL" or Y+ convention.
//!
//! Game data stores either that or the DirectX (Y−) convention, whose green channel holds −y,
//! and no package this importer reads keeps to one (docs/data.md): the convention is decided
//! per map. A normal map is the gradient field of a height, `n ∝ (−∂h/∂x, −∂h/∂y, 1)`, so its
//! slopes `p = −n_x/n_z`, `q = −n_y/n_z` satisfy `∂p/∂y = ∂q/∂x` (the field is curl-free). Read
//! with the wrong sign of y, the two sides are opposite: [`green_test`] correlates them over the
//! map (after a 3×3 box blur, which keeps the texture's slopes and removes the 8-bit
//! quantisation that dominates single-texel differences). A correlation above
//! [`DECISIVE_CORRELATION`] keeps green, one below its negative flips it; in between a height
//! map, when the package has one, decides by the sign of `corr(n_y, −∂h/∂y)·corr(n_x, −∂h/∂x)`
//! (the second factor allows for depth maps, white = low, where the x slopes show it);
//! otherwise the package's majority,
//! Y− ([`GreenConvention::PACKAGE_DEFAULT_FLIPS`]).

use photomat_core::image_io::PlanarImage;
use serde::{Deserialize, Serialize};

/// Smallest `n_z` of a decoded normal: 8-bit normal maps hold a few texels pointing along the
/// surface (n_z ≈ 0) whose slope would be unbounded; 0.1 (84° from the surface normal) keeps
/// every slope below 10 and changes no texel a renderer would shade differently.
pub const MIN_NZ: f32 = 0.1;

/// How strongly the curl test must decide (|correlation|) to be trusted: on the surveyed
/// packages 95 % of maps are beyond 0.3 with the sign of the map set they belong to, and the
/// rest are near-flat or noisy maps (docs/data.md, "Normal maps").
pub const DECISIVE_CORRELATION: f64 = 0.3;

/// What decided a normal map's green channel.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GreenEvidence {
    /// The slopes' curl correlation ([`green_test`]).
    Curl,
    /// The height map's correlation with the slopes.
    Height,
    /// Neither decided: the package's majority.
    PackageDefault,
}

/// The green channel's convention of one normal map, and the evidence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GreenConvention {
    /// The map stores −y (DirectX, Y−): green is flipped on reading.
    pub flipped: bool,
    /// The correlation that decided (curl or height), 0 for the package default.
    pub correlation: f64,
    pub evidence: GreenEvidence,
}

impl GreenConvention {
    /// What every surveyed package stores in most of its maps: Y− (docs/data.md).
    pub const PACKAGE_DEFAULT_FLIPS: bool = true;
}

/// Decodes a normal map's stored RGB (channels 0–2 of `rgb`, values in [0, 1]) as read,
/// green as stored: planes x, y, z of unit normals with `n_z ≥` [`MIN_NZ`].
pub fn decode(rgb: &PlanarImage, flip_green: bool) -> PlanarImage {
    let plane = rgb.width * rgb.height;
    let mut out = vec![0.0f32; 3 * plane];
    for i in 0..plane {
        let x = 2.0 * rgb.data[i] - 1.0;
        let mut y = 2.0 * rgb.data[plane + i] - 1.0;
        if flip_green {
            y = -y;
        }
        let z = (2.0 * rgb.data[2 * plane + i] - 1.0).max(MIN_NZ);
        let length = (x * x + y * y + z * z).sqrt();
        out[i] = x / length;
        out[plane + i] = y / length;
        out[2 * plane + i] = z / length;
    }
    PlanarImage {
        channels: 3,
        height: rgb.height,
        width: rgb.width,
        data: out,
    }
}

/// The slopes `(∂h/∂x, ∂h/∂y)` of unit normals `n` (3 planes), y up, per texel, in units of
/// height per unit length: `(−n_x/n_z, −n_y/n_z)`.
pub fn slopes(n: &PlanarImage) -> (Vec<f64>, Vec<f64>) {
    let plane = n.width * n.height;
    let mut p = vec![0.0; plane];
    let mut q = vec![0.0; plane];
    for i in 0..plane {
        let z = n.data[2 * plane + i].max(MIN_NZ) as f64;
        p[i] = -(n.data[i] as f64) / z;
        q[i] = -(n.data[plane + i] as f64) / z;
    }
    (p, q)
}

/// Decides the green convention of the stored normal map `rgb` (module docs); `height`, when
/// the package has one, is a height or depth map of the same size (stored values, channel 0).
pub fn green_test(rgb: &PlanarImage, height: Option<&PlanarImage>) -> GreenConvention {
    let n = decode(rgb, false);
    let (w, h) = (n.width, n.height);
    let (p, q) = slopes(&n);
    let (p, q) = (box_blur(&p, w, h), box_blur(&q, w, h));
    // ∂p/∂y (y up: towards row 0) and ∂q/∂x, central differences with wrap-around.
    let dp_dy = derivative(&p, w, h, Axis::Up);
    let dq_dx = derivative(&q, w, h, Axis::Right);
    let curl = correlation(&dp_dy, &dq_dx);
    if curl.abs() > DECISIVE_CORRELATION {
        return GreenConvention {
            flipped: curl < 0.0,
            correlation: curl,
            evidence: GreenEvidence::Curl,
        };
    }
    if let Some(height) = height.filter(|m| m.width == w && m.height == h) {
        let z = box_blur(
            &height.data[..w * h]
                .iter()
                .map(|&v| v as f64)
                .collect::<Vec<_>>(),
            w,
            h,
        );
        let minus = |v: Vec<f64>| v.into_iter().map(|x| -x).collect::<Vec<f64>>();
        let nx: Vec<f64> = n.data[..w * h].iter().map(|&v| v as f64).collect();
        let ny: Vec<f64> = n.data[w * h..2 * w * h].iter().map(|&v| v as f64).collect();
        let along_x = correlation(&nx, &minus(derivative(&z, w, h, Axis::Right)));
        let along_y = correlation(&ny, &minus(derivative(&z, w, h, Axis::Up)));
        // White is high unless the x slopes say the map is a depth (a relief along y alone
        // leaves them constant, and its height is then taken as a height).
        let polarity = if along_x.abs() > DECISIVE_CORRELATION {
            along_x.signum()
        } else {
            1.0
        };
        let signed = polarity * along_y;
        if signed.abs() > DECISIVE_CORRELATION {
            return GreenConvention {
                flipped: signed < 0.0,
                correlation: signed,
                evidence: GreenEvidence::Height,
            };
        }
    }
    GreenConvention {
        flipped: GreenConvention::PACKAGE_DEFAULT_FLIPS,
        correlation: 0.0,
        evidence: GreenEvidence::PackageDefault,
    }
}

/// A derivative's direction on the image.
#[derive(Clone, Copy)]
enum Axis {
    /// Along the columns, towards larger column index.
    Right,
    /// Towards row 0.
    Up,
}

/// The central difference of the `w`×`h` plane `v` along `axis`, wrapping around, per texel
/// (unit texel spacing).
fn derivative(v: &[f64], w: usize, h: usize, axis: Axis) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for r in 0..h {
        for c in 0..w {
            let (a, b) = match axis {
                Axis::Right => (r * w + (c + 1) % w, r * w + (c + w - 1) % w),
                Axis::Up => (((r + h - 1) % h) * w + c, ((r + 1) % h) * w + c),
            };
            out[r * w + c] = 0.5 * (v[a] - v[b]);
        }
    }
    out
}

/// The 3×3 box mean of the `w`×`h` plane `v`, wrapping around.
fn box_blur(v: &[f64], w: usize, h: usize) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut sum = 0.0;
            for dr in [h - 1, 0, 1] {
                for dc in [w - 1, 0, 1] {
                    sum += v[((r + dr) % h) * w + (c + dc) % w];
                }
            }
            out[r * w + c] = sum / 9.0;
        }
    }
    out
}

/// Pearson correlation of two equally long series; 0 when either is constant.
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        ab += dx * dy;
        aa += dx * dx;
        bb += dy * dy;
    }
    // Constant series (a flat normal map) carry no evidence either way.
    if aa <= f64::EPSILON || bb <= f64::EPSILON {
        return 0.0;
    }
    ab / (aa * bb).sqrt()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A periodic test height on a `side`² grid: two plane waves and a bump, in texel units.
    pub fn test_height(side: usize) -> Vec<f64> {
        let s = side as f64;
        let mut h = vec![0.0; side * side];
        for r in 0..side {
            for c in 0..side {
                let (x, y) = (c as f64 / s, -(r as f64) / s);
                let tau = std::f64::consts::TAU;
                h[r * side + c] = 3.0 * (tau * 2.0 * x).sin() * (tau * y).cos()
                    + 1.5 * (tau * (x + 3.0 * y)).cos();
            }
        }
        h
    }

    /// The stored RGB of the normals of height `h` (texel units, `side`²), y up (Y+), or with
    /// green holding −y when `directx`.
    pub fn stored_normals(h: &[f64], side: usize, directx: bool) -> PlanarImage {
        let gx = derivative(h, side, side, Axis::Right);
        let gy = derivative(h, side, side, Axis::Up);
        let plane = side * side;
        let mut data = vec![0.0f32; 3 * plane];
        for i in 0..plane {
            let (x, y, z) = (-gx[i], -gy[i], 1.0);
            let l = (x * x + y * y + z * z).sqrt();
            let y = if directx { -y } else { y };
            data[i] = (0.5 * x / l + 0.5) as f32;
            data[plane + i] = (0.5 * y / l + 0.5) as f32;
            data[2 * plane + i] = (0.5 * z / l + 0.5) as f32;
        }
        PlanarImage {
            channels: 3,
            height: side,
            width: side,
            data,
        }
    }

    #[test]
    fn the_curl_test_tells_opengl_from_directx_maps() {
        let side = 64;
        let h = test_height(side);
        let opengl = green_test(&stored_normals(&h, side, false), None);
        assert!(!opengl.flipped && opengl.evidence == GreenEvidence::Curl);
        assert!(opengl.correlation > 0.9, "{opengl:?}");
        let directx = green_test(&stored_normals(&h, side, true), None);
        assert!(directx.flipped && directx.correlation < -0.9, "{directx:?}");
        // Read with the flip, a DirectX map gives the OpenGL map's normals.
        let a = decode(&stored_normals(&h, side, false), false);
        let b = decode(&stored_normals(&h, side, true), true);
        for (x, y) in a.data.iter().zip(&b.data) {
            assert!((x - y).abs() < 1e-6);
        }
    }

    #[test]
    fn a_relief_along_one_axis_is_decided_by_its_height_map() {
        // Ridges along x: h depends on the row only, so both sides of the curl test are 0.
        let side = 32;
        let h: Vec<f64> = (0..side * side)
            .map(|i| 2.0 * (std::f64::consts::TAU * (i / side) as f64 / side as f64).sin())
            .collect();
        let stored = PlanarImage::new(
            1,
            side,
            side,
            h.iter().map(|&v| (0.5 + v / 8.0) as f32).collect(),
        )
        .unwrap();
        for directx in [false, true] {
            let convention = green_test(&stored_normals(&h, side, directx), Some(&stored));
            assert_eq!(convention.evidence, GreenEvidence::Height, "{convention:?}");
            assert_eq!(convention.flipped, directx, "{convention:?}");
        }
    }

    #[test]
    fn a_flat_map_falls_back_to_the_package_default() {
        let flat = PlanarImage::new(
            3,
            8,
            8,
            [vec![0.5; 64], vec![0.5; 64], vec![1.0; 64]].concat(),
        )
        .unwrap();
        let convention = green_test(&flat, None);
        assert_eq!(convention.evidence, GreenEvidence::PackageDefault);
        assert_eq!(convention.flipped, GreenConvention::PACKAGE_DEFAULT_FLIPS);
    }
}
