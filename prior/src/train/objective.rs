//! The relief prior's loss on a batch (docs/neural-models.md, "Relief prior"): per-map L1 on
//! the colour maps (albedos in their display encoding, roughness as it is), L1 of the unit
//! normals that the predicted and the true heights give (the relief's shape, whatever its
//! mean level), and a rendering loss, L1 of `ln(radiance + 0.01)` of the predicted and the
//! true maps under random flash positions (Deschaintre et al. 2018, §4.2: the log compresses
//! the highlight so that it does not drown the rest).

use candle_core::{DType, Device, Tensor};
use photomat_core::render::render_radiance_with;
use photomat_core::{Brdf, FlashGeometry, Highlight, MaterialMaps, ParamSpec};
use serde::{Deserialize, Serialize};

use crate::maps::{decode_colour, normals_of_height};
use crate::network::PriorOutput;

/// Offset of the rendering loss's log: radiance 0.01 (a dark texel far from the flash) is
/// where the log starts compressing; below it differences count nearly linearly.
const LOG_OFFSET: f64 = 0.01;

/// Weights of the loss's terms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// Colour maps' L1. Default 1.
    pub maps: f64,
    /// Normals' L1. Default 2: the relief is what the prior is for.
    pub normal: f64,
    /// Rendering L1. Default 1.
    pub render: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            maps: 1.0,
            normal: 2.0,
            render: 1.0,
        }
    }
}

/// The loss's terms on one batch.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LossTerms {
    pub maps: f64,
    pub normal: f64,
    pub render: f64,
    pub total: f64,
}

/// A batch: photos and what is true of them.
pub struct Batch {
    /// (B, 5, N, N) network input.
    pub input: Tensor,
    /// The true `ggx` maps (B, ·, N, N).
    pub truth: MaterialMaps,
    /// True heights (B, 1, N, N) in world units.
    pub height: Tensor,
    /// World units per texel.
    pub texel: f64,
    /// Side of the photographed square.
    pub side: f64,
    /// Per example, the flash positions of the rendering loss.
    pub render_lights: Vec<Vec<Highlight>>,
}

/// The loss of `out` (the network's output on `batch.input`) for a prior whose colour maps are
/// `specs`, rendered with the shading model `shading` (the model's own, normals from the
/// heights); the truth renders with `ggx`, the model the photos were made with.
pub fn loss(
    out: &PriorOutput,
    batch: &Batch,
    specs: &[ParamSpec],
    shading: &Brdf,
    ggx: &Brdf,
    weights: &LossWeights,
) -> anyhow::Result<(Tensor, LossTerms)> {
    let colour = decode_colour(specs, &out.colour)?;
    let mut maps_loss = Tensor::zeros((), DType::F32, &Device::Cpu)?;
    for spec in specs {
        let (p, t) = (colour.get(spec.name)?, batch.truth.get(spec.name)?);
        // Albedos compare as people see them (the display encoding); others as they are.
        let encode = |x: &Tensor| -> candle_core::Result<Tensor> {
            match spec.color_space {
                photomat_core::ColorSpace::Gamma22 => x.clamp(1e-6, 1.0)?.powf(1.0 / 2.2),
                _ => Ok(x.clone()),
            }
        };
        let l1 = (encode(p)? - encode(t)?)?.abs()?.mean_all()?;
        maps_loss = (maps_loss + l1)?;
    }
    let normal_p = normals_of_height(&out.height, batch.texel)?;
    let normal_t = normals_of_height(&batch.height, batch.texel)?;
    let normal_loss = (&normal_p - &normal_t)?.abs()?.mean_all()?;
    let predicted = colour
        .with("normal", normal_p)
        .with_texel_size(Some(batch.texel));
    let render_loss = render_l1(&predicted, &batch.truth, shading, ggx, batch)?;
    let total = ((maps_loss.clone() * weights.maps)?
        + (normal_loss.clone() * weights.normal)?
        + (render_loss.clone() * weights.render)?)?;
    let scalar = |t: &Tensor| -> candle_core::Result<f64> { Ok(t.to_scalar::<f32>()? as f64) };
    let terms = LossTerms {
        maps: scalar(&maps_loss)?,
        normal: scalar(&normal_loss)?,
        render: scalar(&render_loss)?,
        total: scalar(&total)?,
    };
    Ok((total, terms))
}

/// L1 of `ln(radiance + 0.01)` between `predicted` (the shading model) and `truth` (`ggx`)
/// under each example's rendering lights.
fn render_l1(
    predicted: &MaterialMaps,
    truth: &MaterialMaps,
    shading: &Brdf,
    ggx: &Brdf,
    batch: &Batch,
) -> anyhow::Result<Tensor> {
    let (_, _, n, _) = batch.height.dims4()?;
    let per = batch.render_lights.first().map_or(0, Vec::len);
    let lights: Vec<Highlight> = batch.render_lights.iter().flatten().copied().collect();
    let geometry = FlashGeometry::with_side(&lights, n, batch.side, DType::F32, &Device::Cpu)?;
    // Every example once per light: (B·K, C, N, N), example-major like `lights`.
    let repeat = |maps: &MaterialMaps| -> anyhow::Result<MaterialMaps> {
        Ok(maps.map_tensors(|t| {
            let (b, c, h, w) = t.dims4()?;
            Ok(t.unsqueeze(1)?
                .broadcast_as((b, per, c, h, w))?
                .reshape((b * per, c, h, w))?)
        })?)
    };
    let radiance_p = render_radiance_with(shading.as_ref(), &repeat(predicted)?, &geometry)?;
    let radiance_t = render_radiance_with(ggx.as_ref(), &repeat(truth)?, &geometry)?;
    let log = |x: Tensor| -> candle_core::Result<Tensor> {
        (x.clamp(0.0, f64::INFINITY)? + LOG_OFFSET)?.log()
    };
    Ok((log(radiance_p)? - log(radiance_t.detach())?)?
        .abs()?
        .mean_all()?)
}
