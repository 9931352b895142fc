//! Parameter specifications: what maps a BRDF model takes and how they are stored.
//!
//! A plugin declares its maps as a list of [`ParamSpec`]s (Mitsuba's parameter table, made
//! machine readable). The estimator's output channel count is the sum of their channels; the
//! [`Encoding`] turns that unconstrained network output into physical values; the
//! [`ColorSpace`] says how the map is written to 8/16-bit files. The maps several models share
//! (`diffuse`, `specular`, `roughness`, `normal`) have one definition, in [`common`].

pub mod common;

use candle_core::Tensor;

use crate::vecops::normalize3;
use crate::{Error, Result};

/// How a map is stored in integer image files (EXR files always hold the physical values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ColorSpace {
    /// Albedo-like values in [0, 1], written as `x^(1/2.2)` (the display encoding of `docs/conventions.md`).
    Gamma22,
    /// Scalar values in [0, 1] written as they are (roughness, height).
    Linear,
    /// Unit vectors written as `0.5·n + 0.5`.
    UnitVector,
}

impl ColorSpace {
    /// Physical value → value in [0, 1] stored in a PNG.
    pub fn to_stored(self, v: f32) -> f32 {
        match self {
            ColorSpace::Gamma22 => v.clamp(0.0, 1.0).powf(1.0 / 2.2),
            ColorSpace::Linear => v.clamp(0.0, 1.0),
            ColorSpace::UnitVector => (0.5 * v + 0.5).clamp(0.0, 1.0),
        }
    }

    /// Value in [0, 1] read from a PNG → physical value.
    pub fn from_stored(self, s: f32) -> f32 {
        match self {
            ColorSpace::Gamma22 => s.powf(2.2),
            ColorSpace::Linear => s,
            ColorSpace::UnitVector => 2.0 * s - 1.0,
        }
    }
}

/// Map from an unconstrained network output `x` (any real) to the physical parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Encoding {
    /// `lo + (hi − lo)·(tanh x + 1)/2`: values spread linearly over the range.
    Linear,
    /// `lo + (hi − lo)·((tanh x + 1)/2)^2.2`: uniform steps in gamma space, as the reference
    /// decodes albedos (dark values get more of the output range).
    Gamma22,
    /// Unit normal in the upper hemisphere: `normalize(tanh x₀, tanh x₁, max((tanh x₂+1)/2, ε))`.
    UnitNormal,
}

/// Floor of the decoded normal's z component: keeps the normal in the upper hemisphere and
/// the vector non-zero (normalize never divides by 0); 1e-3 allows tilts up to ≈ 89.9°.
const NORMAL_Z_FLOOR: f64 = 1e-3;

/// One parameter map of a BRDF model.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    /// Map name, unique within the model (`diffuse`, `roughness`, `normal`, …).
    pub name: &'static str,
    /// Number of channels (1 for scalars, 3 for colours and vectors).
    pub channels: usize,
    /// Physical range `(lo, hi)` of every channel.
    pub range: (f32, f32),
    /// Decoding from unconstrained network output.
    pub encoding: Encoding,
    /// How integer image files store it.
    pub color_space: ColorSpace,
    /// Default physical value per channel (`channels` entries).
    pub default: &'static [f32],
    /// Whether gradients w.r.t. this map are meaningful (false for e.g. tabulated inputs).
    pub differentiable: bool,
    /// One line for `photomat brdfs`.
    pub doc: &'static str,
}

impl ParamSpec {
    /// Decode raw network output (B, channels, H, W) into the physical map (B, channels, H, W).
    pub fn decode(&self, raw: &Tensor) -> Result<Tensor> {
        let (_, c, _, _) = raw.dims4()?;
        if c != self.channels {
            return Err(Error::Invalid(format!(
                "map '{}' expects {} channels, the raw tensor has {c}",
                self.name, self.channels
            )));
        }
        let (lo, hi) = (self.range.0 as f64, self.range.1 as f64);
        let unit = ((raw.tanh()? + 1.0)? * 0.5)?; // (tanh x + 1)/2 in [0, 1]
        Ok(match self.encoding {
            Encoding::Linear => unit.affine(hi - lo, lo)?,
            Encoding::Gamma22 => unit.powf(2.2)?.affine(hi - lo, lo)?,
            Encoding::UnitNormal => {
                if c != 3 {
                    return Err(Error::Invalid(format!(
                        "map '{}' uses the unit-normal encoding but has {c} channels",
                        self.name
                    )));
                }
                let xy = raw.narrow(1, 0, 2)?.tanh()?;
                let z = unit.narrow(1, 2, 1)?.maximum(NORMAL_Z_FLOOR)?;
                normalize3(&Tensor::cat(&[xy, z], 1)?)?
            }
        })
    }

    /// The raw output that [`ParamSpec::decode`] maps to the physical `value` (one entry
    /// per channel), e.g. to start an optimisation at the model's [`ParamSpec::default`]s.
    /// Values are clamped just inside the range first, since tanh reaches neither end;
    /// a unit normal `n` (n_z > 0) is written as `(atanh(n_x/2), atanh(n_y/2),
    /// atanh(n_z − 1))`, which decodes to `normalize(n/2) = n`.
    pub fn raw_for(&self, value: &[f32]) -> Vec<f32> {
        // 1e-4 of the range from either end: atanh stays below 5 and its decoded value
        // within 1e-4 of the asked one.
        const INSIDE: f32 = 1e-4;
        let atanh = |y: f32| 0.5 * ((1.0 + y) / (1.0 - y)).ln();
        let (lo, hi) = self.range;
        let unit = |v: f32| ((v - lo) / (hi - lo)).clamp(INSIDE, 1.0 - INSIDE);
        match self.encoding {
            Encoding::Linear => value.iter().map(|&v| atanh(2.0 * unit(v) - 1.0)).collect(),
            Encoding::Gamma22 => value
                .iter()
                .map(|&v| atanh(2.0 * unit(v).powf(1.0 / 2.2) - 1.0))
                .collect(),
            Encoding::UnitNormal => {
                let half = |v: f32| (0.5 * v).clamp(INSIDE - 1.0, 1.0 - INSIDE);
                let z = (value[2] as f64).max(NORMAL_Z_FLOOR) as f32;
                vec![
                    atanh(half(value[0])),
                    atanh(half(value[1])),
                    atanh((z - 1.0).clamp(INSIDE - 1.0, 0.0)),
                ]
            }
        }
    }
}

impl ParamSpec {
    /// The raw map that [`ParamSpec::decode`] maps to the physical `map` (B, channels, H, W),
    /// texel by texel as [`ParamSpec::raw_for`] (so with its clamping just inside the range):
    /// (B, channels, H, W). E.g. to hold a capture's map at values known from elsewhere.
    pub fn raw_for_map(&self, map: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = map.dims4()?;
        if c != self.channels {
            return Err(Error::Invalid(format!(
                "map '{}' has {} channels, the values given have {c}",
                self.name, self.channels
            )));
        }
        let texels: Vec<f32> = map.permute((0, 2, 3, 1))?.flatten_all()?.to_vec1()?;
        let raw: Vec<f32> = texels.chunks(c).flat_map(|v| self.raw_for(v)).collect();
        Ok(Tensor::from_vec(raw, (b, h, w, c), map.device())?
            .permute((0, 3, 1, 2))?
            .contiguous()?)
    }
}

/// Total channel count `n` of a list of specs: the estimator's output width.
pub fn total_channels(specs: &[ParamSpec]) -> usize {
    specs.iter().map(|s| s.channels).sum()
}
