//! The raw channels of a capture's maps that the fit does not move texel by texel
//! (docs/capture.md, "Fit"): maps held at one value over the square
//! ([`crate::CaptureOptions::uniform_maps`], and the relief of a fit from constant maps),
//! and maps held at values known from elsewhere ([`crate::CaptureOptions::known_maps`]).

use anyhow::bail;
use candle_core::{DType, Device, Tensor};
use photomat_core::param::Encoding;
use photomat_core::vecops::normalize3;
use photomat_core::{Brdf, MaterialMaps};

/// What one size of a fit holds: (1, C, 1, 1) masks over the raw channels of the model.
pub(crate) struct HeldChannels {
    /// 1 on the channels held at their mean over the square.
    uniform: Option<Tensor>,
    /// The known maps' raw values (1, C, n, n) (0 on the other channels) and the mask of the
    /// channels they fill.
    known: Option<(Tensor, Tensor)>,
}

impl HeldChannels {
    /// The channels of `brdf`'s maps named in `uniform`, and those of `known` (maps of the
    /// capture's full side N) box-filtered by `factor` for a stage of side N / `factor`.
    /// Names the model lacks, a map both uniform and known, and known maps of another shape
    /// than (1, channels, N, N) are errors that say so.
    pub(crate) fn new(
        brdf: &Brdf,
        uniform: &[String],
        known: Option<&MaterialMaps>,
        full_size: usize,
        factor: usize,
    ) -> anyhow::Result<Self> {
        let params = brdf.params();
        let known_names: Vec<&str> = known.map_or_else(Vec::new, |k| k.names());
        let ensure_taken = |name: &str, purpose: &str| -> anyhow::Result<()> {
            if !params.iter().any(|p| p.name == name) {
                let theirs: Vec<&str> = params.iter().map(|p| p.name).collect();
                bail!(
                    "{}: no map named '{name}' to hold {purpose} (its maps: {})",
                    brdf.name(),
                    theirs.join(", ")
                );
            }
            Ok(())
        };
        for name in uniform.iter().map(String::as_str) {
            ensure_taken(name, "uniform")?;
            if known_names.contains(&name) {
                bail!("map '{name}' is held both uniform and at known values: choose one");
            }
        }
        for name in &known_names {
            ensure_taken(name, "at known values")?;
        }
        let mask = |held: &dyn Fn(&str) -> bool| -> candle_core::Result<Tensor> {
            let m: Vec<f32> = params
                .iter()
                .flat_map(|p| vec![if held(p.name) { 1.0 } else { 0.0 }; p.channels])
                .collect();
            let c = m.len();
            Tensor::from_vec(m, (1, c, 1, 1), &Device::Cpu)
        };
        let uniform_mask = if uniform.is_empty() {
            None
        } else {
            Some(mask(&|n| uniform.iter().any(|u| u == n))?)
        };
        let known = match known {
            Some(maps) if !known_names.is_empty() => Some((
                known_raw(brdf, maps, full_size, factor)?,
                mask(&|n| known_names.contains(&n))?,
            )),
            _ => None,
        };
        Ok(Self {
            uniform: uniform_mask,
            known,
        })
    }

    /// `raw` (B, C, n, n) with the uniform channels replaced by their mean over the square
    /// (the gradient reaching a held texel is then the same for all of them) and the known
    /// channels by the known values (no gradient reaches them).
    pub(crate) fn apply(&self, raw: &Tensor) -> candle_core::Result<Tensor> {
        let mut raw = raw.clone();
        if let Some(mask) = &self.uniform {
            let mean = raw.mean_keepdim(3)?.mean_keepdim(2)?;
            let free = raw.broadcast_mul(&mask.affine(-1.0, 1.0)?)?;
            raw = (free + mean.broadcast_mul(mask)?.broadcast_as(raw.shape())?)?;
        }
        if let Some((values, mask)) = &self.known {
            let free = raw.broadcast_mul(&mask.affine(-1.0, 1.0)?)?;
            raw = (free + values.broadcast_mul(mask)?)?;
        }
        Ok(raw)
    }
}

/// The raw values (1, C, N / `factor`, N / `factor`) of the maps of `known` (each
/// (1, channels, N, N), N = `full_size`) box-filtered by `factor`, in the channel order of
/// `brdf`'s maps; 0 on the channels of maps `known` lacks.
fn known_raw(
    brdf: &Brdf,
    known: &MaterialMaps,
    full_size: usize,
    factor: usize,
) -> anyhow::Result<Tensor> {
    let size = full_size / factor;
    let mut raws = Vec::new();
    for p in brdf.params() {
        let Ok(map) = known.get(p.name) else {
            raws.push(Tensor::zeros(
                (1, p.channels, size, size),
                DType::F32,
                &Device::Cpu,
            )?);
            continue;
        };
        let dims = map.dims();
        if dims != [1, p.channels, full_size, full_size] {
            bail!(
                "known map '{}' has shape {dims:?}, the capture takes [1, {}, {full_size}, {full_size}]",
                p.name,
                p.channels
            );
        }
        let mut map = map.to_dtype(DType::F32)?;
        if factor > 1 {
            // What the coarse stage's box-filtered photo saw; a unit normal's average is
            // renormalised.
            map = map.avg_pool2d(factor)?;
            if p.encoding == Encoding::UnitNormal {
                map = normalize3(&map)?;
            }
        }
        raws.push(p.raw_for_map(&map)?);
    }
    Ok(Tensor::cat(&raws, 1)?)
}
