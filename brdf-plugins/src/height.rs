//! `height`: adapter that derives a nested model's `normal` map from a 1-channel height map.
//!
//! Model: Mitsuba 3's `bumpmap`. On the unit material square (`docs/conventions.md`: side 1,
//! +y up) a map
//! value h ∈ [0, 1] stands for the surface height `scale·h` in world units, and
//! `normal = normalize(−scale·∂h/∂x, −scale·∂h/∂y, 1)` with central differences over one texel
//! on each side, wrapping around the edges (so a tileable height map gives a tileable normal
//! map). Row index grows towards −y, so `∂h/∂y = (h[i−1] − h[i+1]) / (2Δ)` with Δ the texel
//! size: 1/R on the unit square, or the size the maps record (a spatial model's materials,
//! whose texel is the same world size at every sample side; `MaterialMaps::texel_size`).
//!
//! Specification: `height(MODEL)` or `height(MODEL, scale=S)`; MODEL must take a `normal` map
//! (`ggx`, `lambert`, another adapter producing one, or a user plugin).
//!
//! | map / argument | ch | range     | encoding | file       | at 0              | at the top        |
//! |----------------|----|-----------|----------|------------|-------------------|-------------------|
//! | `height`       | 1  | [0, 1]    | linear   | linear PNG | lowest point      | highest point     |
//! | `scale` (arg)  | –  | [0, 1]    | –        | manifest   | flat normals      | 1 world unit tall |
//!
//! `scale` defaults to 0.02 (2 % of the sample width: a 2 mm relief on a 10 cm swatch); it is a
//! construction argument, not a map, and is never differentiated. With the nested `ggx`:
//! n = 8 (diffuse 3, specular 3, roughness 1, height 1), the paper's configuration.

use candle_core::Tensor;
use photomat_core::vecops::normalize3;
use photomat_core::{
    ArgSpec, ColorSpace, Encoding, MapAdapter, MaterialMaps, ParamSpec, Result, register_brdf,
};

const HEIGHT: ParamSpec = ParamSpec {
    name: "height",
    channels: 1,
    range: (0.0, 1.0),
    encoding: Encoding::Linear,
    color_space: ColorSpace::Linear,
    default: &[0.5],
    differentiable: true,
    doc: "surface height as a fraction of `scale` (world units = scale·h)",
};

/// Height → normal conversion with a fixed relief scale.
pub struct HeightToNormal {
    /// World-space height of h = 1.
    pub scale: f64,
}

impl HeightToNormal {
    /// Unit normals (B, 3, R, R) from heights (B, 1, R, R) on the unit square (texel 1/R),
    /// wrap-around central differences.
    pub fn normals(&self, height: &Tensor) -> Result<Tensor> {
        let (_, _, rows, cols) = height.dims4()?;
        // Texel spacing 1/R: the central difference spans 2/R.
        self.normals_scaled(height, cols as f64 / 2.0, rows as f64 / 2.0)
    }

    /// Unit normals (B, 3, R, C) from heights (B, 1, R, C) with square texels of `texel`
    /// world units; the central difference spans 2·texel.
    pub fn normals_with_texel(&self, height: &Tensor, texel: f64) -> Result<Tensor> {
        self.normals_scaled(height, 0.5 / texel, 0.5 / texel)
    }

    /// Normals from the central differences multiplied by `1/(2Δx)`, `1/(2Δy)`.
    fn normals_scaled(&self, height: &Tensor, inv_2dx: f64, inv_2dy: f64) -> Result<Tensor> {
        let gx = ((height.roll(-1, 3)? - height.roll(1, 3)?)? * inv_2dx)?;
        let gy = ((height.roll(1, 2)? - height.roll(-1, 2)?)? * inv_2dy)?;
        let nx = (gx * -self.scale)?;
        let ny = (gy * -self.scale)?;
        let nz = nx.ones_like()?;
        normalize3(&Tensor::cat(&[nx, ny, nz], 1)?)
    }
}

impl MapAdapter for HeightToNormal {
    fn adapt(&self, maps: &MaterialMaps) -> Result<MaterialMaps> {
        let mut nested = maps.clone();
        let height = nested.remove("height").ok_or_else(|| {
            photomat_core::Error::Invalid(format!(
                "height adapter: material has no 'height' map (it has: {})",
                maps.names().join(", ")
            ))
        })?;
        let normals = match maps.texel_size() {
            Some(t) => self.normals_with_texel(&height, t)?,
            None => self.normals(&height)?,
        };
        nested.insert("normal", normals);
        Ok(nested)
    }
}

register_brdf! {
    name: "height",
    summary: "adapter: nested model's normal map from a height map (Mitsuba 'bumpmap')",
    adds: &[HEIGHT],
    replaces: &["normal"],
    args: &[ArgSpec::number(
        "scale",
        0.02,
        (0.0, 1.0),
        "world-space height of h = 1 (the plane side is 1)",
    )],
    adapter: |args| {
        Ok(HeightToNormal {
            scale: args.value("scale")?,
        })
    },
}
