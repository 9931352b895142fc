//! The prior's outputs as a model's maps (docs/neural-models.md, "Relief prior"): the colour
//! head's raw channels decoded by the model's own parameter specs, the relief head's height
//! (world units) as the model's relief: a `height` map of `height(·, scale=S)` whose scale is
//! the height's range, so that nothing clips ([`height_model`]), or the normals a height
//! adapter would derive from it for a model with a `normal` map.
//!
//! A model the prior serves has maps for its colour and one relief map: `height` (the height
//! adapter's) or `normal`; [`ReliefMap`] says which, [`colour_specs`] lists the others.

use anyhow::{Context, bail};
use candle_core::Tensor;
use photomat_core::{Brdf, MaterialMaps, ParamSpec, lookup};

/// How a model holds its relief.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReliefMap {
    /// A height map of the height adapter (`height(ggx)`).
    Height,
    /// A unit normal map (`ggx`).
    Normal,
    /// No relief map: flat normals (`coated`).
    None,
}

impl ReliefMap {
    /// The relief map of `brdf`.
    pub fn of(brdf: &Brdf) -> Self {
        let has = |name: &str| brdf.params().iter().any(|p| p.name == name);
        if has("height") {
            ReliefMap::Height
        } else if has("normal") {
            ReliefMap::Normal
        } else {
            ReliefMap::None
        }
    }

    /// The map's name, if there is one.
    pub fn name(self) -> Option<&'static str> {
        match self {
            ReliefMap::Height => Some("height"),
            ReliefMap::Normal => Some("normal"),
            ReliefMap::None => None,
        }
    }
}

/// The parameter specs of `brdf` that the colour head predicts: every map but the relief.
pub fn colour_specs(brdf: &Brdf) -> Vec<ParamSpec> {
    let relief = ReliefMap::of(brdf).name();
    brdf.params()
        .iter()
        .filter(|p| Some(p.name) != relief)
        .cloned()
        .collect()
}

/// The colour maps decoded from raw channels `raw` (B, n_c, H, W), in the specs' order.
pub fn decode_colour(specs: &[ParamSpec], raw: &Tensor) -> anyhow::Result<MaterialMaps> {
    let mut maps = MaterialMaps::new();
    let mut offset = 0;
    for spec in specs {
        maps.insert(
            spec.name,
            spec.decode(&raw.narrow(1, offset, spec.channels)?)?,
        );
        offset += spec.channels;
    }
    let (_, c, _, _) = raw.dims4()?;
    if offset != c {
        bail!("the colour head gives {c} channels, the model's colour maps take {offset}");
    }
    Ok(maps)
}

/// Unit normals (B, 3, H, W) of heights `height` (B, 1, H, W, world units) on texels of
/// `texel` world units, by the height adapter's wrap-around central differences over one
/// texel on each side (`brdf-plugins/src/height.rs`), y up the image.
pub fn normals_of_height(height: &Tensor, texel: f64) -> photomat_core::Result<Tensor> {
    let inv = 0.5 / texel;
    let gx = ((height.roll(-1, 3)? - height.roll(1, 3)?)? * inv)?;
    let gy = ((height.roll(1, 2)? - height.roll(-1, 2)?)? * inv)?;
    let nz = gx.ones_like()?;
    photomat_core::vecops::normalize3(&Tensor::cat(&[gx.neg()?, gy.neg()?, nz], 1)?)
}

/// The `height(<inner>, scale=S)` specification and map for heights `height` (1, 1, N, N,
/// world units): `S` the range (at least [`MIN_SCALE`]), the map `(H − H_min)/S` in [0, 1].
pub fn height_model(inner: &str, height: &Tensor) -> anyhow::Result<(Brdf, Tensor)> {
    let lo = height.min_all()?.to_scalar::<f32>()? as f64;
    let hi = height.max_all()?.to_scalar::<f32>()? as f64;
    let scale = (hi - lo).clamp(MIN_SCALE, MAX_SCALE);
    let map = ((height - lo)? / scale)?.clamp(0.0, 1.0)?;
    let brdf =
        lookup(&format!("height({inner}, scale={scale})")).context("the prior's height model")?;
    Ok((brdf, map))
}

/// Smallest relief range recorded (a flat prediction still needs a positive scale): a micron
/// on the photo's 10 cm square.
pub const MIN_SCALE: f64 = 1e-6;
/// Largest relief range the height adapter takes (1 world unit, the flash's height).
pub const MAX_SCALE: f64 = 1.0;

/// The maps of `brdf` from decoded colour maps and heights (B, 1, H, W) on texels of `texel`
/// world units: the relief as the model holds it ([`ReliefMap`]); for a height model the
/// height map of [`height_model`] with the model's own scale replaced (the returned model).
pub fn model_maps(
    brdf: &Brdf,
    colour: &MaterialMaps,
    height: &Tensor,
    texel: f64,
) -> anyhow::Result<(Brdf, MaterialMaps)> {
    let mut maps = colour.clone().with_texel_size(Some(texel));
    match ReliefMap::of(brdf) {
        ReliefMap::Height => {
            let inner = inner_spec(brdf)?;
            let (model, map) = height_model(&inner, height)?;
            maps.insert("height", map);
            Ok((model, maps))
        }
        ReliefMap::Normal => {
            maps.insert("normal", normals_of_height(height, texel)?);
            Ok((brdf.clone(), maps))
        }
        ReliefMap::None => Ok((brdf.clone(), maps)),
    }
}

/// The nested model of a `height(…)` specification (`height(ggx, scale=0.02)` → `ggx`).
pub fn inner_spec(brdf: &Brdf) -> anyhow::Result<String> {
    let spec = photomat_core::PluginSpec::parse(&brdf.name())?;
    let inner = spec
        .nested
        .first()
        .with_context(|| format!("{} has no nested model", brdf.name()))?;
    Ok(inner.to_string())
}

#[cfg(test)]
mod tests {
    use candle_core::Device;
    use photomat_brdfs as _;

    use super::*;

    #[test]
    fn a_height_model_holds_the_range_as_its_scale_and_its_normals_are_the_heights() {
        let device = Device::Cpu;
        let n = 16;
        let texel = 2.0 / n as f64;
        let values: Vec<f32> = (0..n * n)
            .map(|i| 0.01 * ((i % n) as f32 * std::f32::consts::TAU / n as f32).sin())
            .collect();
        let height = Tensor::from_vec(values, (1, 1, n, n), &device).unwrap();
        let brdf = lookup("height(ggx)").unwrap();
        let (model, map) = height_model("ggx", &height).unwrap();
        assert!(
            model.name().starts_with("height(ggx, scale=0.0199"),
            "{}",
            model.name()
        );
        let max = map.max_all().unwrap().to_scalar::<f32>().unwrap();
        assert!((max - 1.0).abs() < 1e-6);
        // The model's own normals of the map are those of the heights.
        let colour = MaterialMaps::new();
        let (model, maps) = model_maps(&brdf, &colour, &height, texel).unwrap();
        let derived = model.shading_maps(
            &maps
                .with(
                    "diffuse",
                    Tensor::zeros((1, 3, n, n), candle_core::DType::F32, &device).unwrap(),
                )
                .with(
                    "specular",
                    Tensor::zeros((1, 3, n, n), candle_core::DType::F32, &device).unwrap(),
                )
                .with(
                    "roughness",
                    Tensor::ones((1, 1, n, n), candle_core::DType::F32, &device).unwrap(),
                ),
        );
        let derived = derived.unwrap();
        let expected = normals_of_height(&height, texel).unwrap();
        let diff = (derived.get("normal").unwrap() - expected)
            .unwrap()
            .abs()
            .unwrap();
        assert!(diff.max_all().unwrap().to_scalar::<f32>().unwrap() < 1e-5);
        assert_eq!(colour_specs(&brdf).len(), 3);
        assert_eq!(ReliefMap::of(&lookup("coated").unwrap()), ReliefMap::None);
    }
}
