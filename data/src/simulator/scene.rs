//! The photographed scene of the simulator: a material's shading maps over the whole photo,
//! the jittered flash position, and the light that reaches the camera.
//!
//! Geometry follows docs/datasets.md: an S×S photo spans a centred square of side
//! [`PHOTO_SIDE`] = 2 on the material plane, flash and camera collocated at height 1 above the
//! highlight. A procedural family's S×S maps are laid over that square (so one period of a
//! tileable family covers the whole photo and its 2H→H training crops see a quarter of it).
//!
//! Height-mapped families: the height adapter differentiates over texels assuming the unit
//! square (see [`photomat_core::render_radiance_with`]); over side 2 the same height map is
//! half as steep, so every `height` node of the family's model gets `scale / 2` before its
//! normal is derived. The scene then holds the *shading* model's maps
//! ([`photomat_core::DifferentiableBrdf::shading_maps`]: e.g. `ggx` with the implied normal);
//! they are both what is rendered and the ground truth written to `truth/`.

use candle_core::{DType, Device, Tensor};
use photomat_core::flash::FLASH_INTENSITY;
use photomat_core::image_io::PlanarImage;
use photomat_core::param::ColorSpace;
use photomat_core::plugin_spec::{ArgValue, PluginSpec};
use photomat_core::registry::registrations;
use photomat_core::vecops::normalize3;
use photomat_core::{
    Brdf, Error, FlashGeometry, Highlight, MaterialMaps, Result, lookup, render_radiance_with,
};
use rand::Rng;

use super::camera::{CameraModel, SceneRadiance};
use super::pose::PhonePose;
use super::random::standard_normal;
use crate::procedural::Family;

pub use crate::highlight::PHOTO_SIDE;

/// The adapter whose argument `scale` is a height in unit-square texel units.
const HEIGHT_ADAPTER: &str = "height";

/// A material laid over a whole photo, in its shading model.
#[derive(Clone)]
pub struct Scene {
    brdf: Brdf,
    maps: MaterialMaps,
    size: usize,
}

impl Scene {
    /// A scene from a shading model and its maps (1, C, S, S) over the square of side
    /// [`PHOTO_SIDE`]; the maps are validated (shapes, finiteness).
    pub fn new(brdf: Brdf, maps: MaterialMaps) -> Result<Self> {
        let model = brdf.name();
        maps.validate(&model, brdf.params())?;
        let (batch, height, width) = maps.batch_and_size()?;
        if batch != 1 || height != width {
            return Err(Error::InvalidMaps {
                model,
                reason: format!(
                    "a scene holds one square material, got a batch of {batch} of \
                     {height}×{width} maps"
                ),
            });
        }
        Ok(Self {
            brdf,
            maps,
            size: height,
        })
    }

    /// Material `seed` of `family` at S = `size` texels over the whole photo, converted to its
    /// shading model (module docs: height scale halved for side 2).
    pub fn from_family(
        family: &dyn Family,
        size: usize,
        seed: u64,
        device: &Device,
    ) -> Result<Self> {
        let spec_text = family.brdf();
        let spec = PluginSpec::parse(&spec_text)?;
        let family_model = lookup(&spec_text)?;
        let maps = family.generate(size, seed, device)?;
        maps.validate(&family_model.name(), family_model.params())?;
        let on_photo = lookup(&rescale_heights(&spec, PHOTO_SIDE)?.to_string())?;
        let shading_maps = on_photo.shading_maps(&maps)?;
        Self::new(on_photo.innermost(), shading_maps)
    }

    /// The shading model (`ggx`, `coated`, `lambert`, …).
    pub fn brdf(&self) -> &Brdf {
        &self.brdf
    }

    /// The shading model's maps, (1, C, S, S).
    pub fn maps(&self) -> &MaterialMaps {
        &self.maps
    }

    /// S, texels per side.
    pub fn size(&self) -> usize {
        self.size
    }

    /// The light reaching the camera with the flash at `highlight` (plane coordinates on the
    /// photo's square of side 2): the renderer's linear radiance over the photo, and the
    /// ambient reflectance.
    pub fn light(&self, highlight: Highlight) -> Result<SceneRadiance> {
        let first = self.maps.get(self.maps.names()[0])?;
        let geometry = FlashGeometry::with_side(
            &[highlight],
            self.size,
            PHOTO_SIDE,
            DType::F32,
            first.device(),
        )?;
        let radiance = render_radiance_with(self.brdf.as_ref(), &self.maps, &geometry)?;
        Ok(SceneRadiance {
            flash: PlanarImage::from_tensor(&radiance)?,
            ambient_reflectance: self.ambient_reflectance()?,
            highlight,
            side: PHOTO_SIDE,
        })
    }

    /// What a phone in `pose` sees (module docs of [`super::pose`]): the maps resampled at
    /// the plane points of its S×S pixels (bilinear, the material repeated periodically, unit
    /// vectors renormalised), and the light reaching each pixel from the flash beside the lens
    /// (the BRDF evaluated with separate light and view directions, falloff 1/d² from the
    /// flash). The overhead pose returns this scene and [`Self::light`] unchanged.
    pub fn seen_from(
        &self,
        highlight: Highlight,
        pose: &PhonePose,
    ) -> Result<(Scene, SceneRadiance)> {
        if pose.is_overhead() {
            return Ok((self.clone(), self.light(highlight)?));
        }
        pose.validate()?;
        let size = self.size;
        let points = pose.plane_points(highlight, size, PHOTO_SIDE)?;
        let seen = self.resampled_at(&points)?;
        let (camera, flash) = (pose.camera(highlight), pose.flash(highlight));
        let plane = size * size;
        let mut wi = vec![0f32; 3 * plane];
        let mut wo = vec![0f32; 3 * plane];
        let mut inv_dist2 = vec![0f32; plane];
        for (t, &p) in points.iter().enumerate() {
            let to_flash = flash - p;
            let (light, view) = (to_flash.normalize(), (camera - p).normalize());
            for c in 0..3 {
                wi[c * plane + t] = light[c] as f32;
                wo[c * plane + t] = view[c] as f32;
            }
            inv_dist2[t] = (1.0 / to_flash.length_squared()) as f32;
        }
        let device = self.maps.get(self.maps.names()[0])?.device().clone();
        let directions = |data: Vec<f32>| Tensor::from_vec(data, (1, 3, size, size), &device);
        let (wi, wo) = (directions(wi)?, directions(wo)?);
        let inv_dist2 = Tensor::from_vec(inv_dist2, (1, 1, size, size), &device)?;
        let f_cos = seen.brdf.eval(&wi, &wo, &seen.maps)?;
        let radiance = (f_cos.broadcast_mul(&inv_dist2)? * FLASH_INTENSITY)?;
        let light = SceneRadiance {
            flash: PlanarImage::from_tensor(&radiance)?,
            ambient_reflectance: seen.ambient_reflectance()?,
            highlight,
            side: PHOTO_SIDE,
        };
        Ok((seen, light))
    }

    /// The scene's maps read at `points` (one per output texel, row-major, S² of them) of the
    /// plane: bilinear and periodic, unit-vector maps renormalised.
    fn resampled_at(&self, points: &[glam::DVec3]) -> Result<Scene> {
        let size = self.size;
        // Continuous pixel coordinates of each point on the S×S grid over the centred square.
        let pixels: Vec<(f64, f64)> = points
            .iter()
            .map(|p| Highlight::new(p.x, p.y).to_pixel_on(size, PHOTO_SIDE))
            .collect();
        let mut maps = MaterialMaps::new();
        for (name, map) in self.maps.iter() {
            let image = PlanarImage::from_tensor(map)?;
            let mut out = PlanarImage::filled(image.channels, size, size, 0.0);
            for (t, &(row, col)) in pixels.iter().enumerate() {
                for c in 0..image.channels {
                    out.data[c * size * size + t] = image.sample_periodic(c, row, col);
                }
            }
            let unit_vector = self
                .brdf
                .params()
                .iter()
                .any(|spec| spec.name == name && spec.color_space == ColorSpace::UnitVector);
            let mut seen = out.to_tensor(map.device())?.to_dtype(map.dtype())?;
            if unit_vector {
                // Bilinear blends of unit normals are shorter than 1 (never zero: neighbouring
                // normals of a height map lie within 90° of each other).
                seen = normalize3(&seen)?;
            }
            maps.insert(name, seen);
        }
        Scene::new(self.brdf.clone(), maps)
    }

    /// The photo (3, S, S display values in [0, 1]) that `camera` takes with the flash at
    /// `highlight`: [`CameraModel::develop`] of [`Self::light`].
    pub fn photograph(
        &self,
        highlight: Highlight,
        camera: &CameraModel,
        rng: &mut impl Rng,
    ) -> Result<PlanarImage> {
        camera.develop(&self.light(highlight)?, rng)
    }

    /// Reflectance under a uniform white sky, (3, S, S): the maps' own
    /// ([`MaterialMaps::ambient_reflectance`]), zero for a model with no diffuse or specular
    /// map.
    pub fn ambient_reflectance(&self) -> Result<PlanarImage> {
        match self.maps.ambient_reflectance()? {
            Some(total) => PlanarImage::from_tensor(&total),
            None => Ok(PlanarImage::filled(3, self.size, self.size, 0.0)),
        }
    }
}

/// `spec` with every height adapter's `scale` divided by `side` (the registry's default scale
/// when the specification gives none).
fn rescale_heights(spec: &PluginSpec, side: f64) -> Result<PluginSpec> {
    let mut out = spec.clone();
    out.nested = spec
        .nested
        .iter()
        .map(|n| rescale_heights(n, side))
        .collect::<Result<_>>()?;
    if spec.name == HEIGHT_ADAPTER {
        let scale = match spec.values.iter().find(|(k, _)| k == "scale") {
            Some((_, ArgValue::Number(v))) => *v,
            Some((_, word)) => {
                return Err(Error::Invalid(format!(
                    "'{spec}': the height adapter's scale={word} must be a number"
                )));
            }
            None => registrations()?
                .iter()
                .find(|r| r.name == HEIGHT_ADAPTER)
                .and_then(|r| r.args.iter().find(|a| a.name == "scale"))
                .and_then(|a| match a.default_value() {
                    ArgValue::Number(v) => Some(v),
                    ArgValue::Word(_) => None,
                })
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "'{spec}' uses the height adapter, but no linked plugin registers \
                         '{HEIGHT_ADAPTER}' with a 'scale' argument"
                    ))
                })?,
        };
        out.values.retain(|(k, _)| k != "scale");
        out.values
            .push(("scale".into(), ArgValue::Number(scale / side)));
    }
    Ok(out)
}

/// Where the flash lands: the photo centre plus Gaussian jitter, like a hand-held phone aimed
/// at the middle of the material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HighlightJitter {
    /// Standard deviation per axis as a fraction of the photo width (default 0.04: the
    /// highlight lies within ±4 % of the width of the centre two times in three).
    pub sigma: f64,
    /// Truncation in standard deviations, by redrawing (default 3: the highlight never leaves
    /// the central 24 % of the photo, so every photo shows its highlight and falloff).
    pub truncate: f64,
}

impl Default for HighlightJitter {
    fn default() -> Self {
        Self {
            sigma: 0.04,
            truncate: 3.0,
        }
    }
}

impl HighlightJitter {
    /// Continuous pixel coordinates (row, col) of the highlight in an S×S photo (docs: the
    /// centre of a 512² photo is (256, 256)). Draws row first, then column.
    pub fn sample(&self, size: usize, rng: &mut impl Rng) -> (f64, f64) {
        let s = size as f64;
        let mut axis = || {
            if self.sigma == 0.0 {
                return s / 2.0;
            }
            loop {
                let z = standard_normal(rng);
                if z.abs() <= self.truncate {
                    return s / 2.0 + self.sigma * s * z;
                }
            }
        };
        let row = axis();
        let col = axis();
        (row, col)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulator::random::photo_rng;
    use photomat_brdfs as _;

    #[test]
    fn height_scale_is_divided_by_the_side() {
        let spec = PluginSpec::parse("height(ggx, scale=0.02)").unwrap();
        assert_eq!(
            rescale_heights(&spec, 2.0).unwrap().to_string(),
            "height(ggx, scale=0.01)"
        );
        let default = PluginSpec::parse("height(ggx)").unwrap();
        assert_eq!(
            rescale_heights(&default, 2.0).unwrap().to_string(),
            "height(ggx, scale=0.01)"
        );
        let plain = PluginSpec::parse("coated").unwrap();
        assert_eq!(rescale_heights(&plain, 2.0).unwrap(), plain);
    }

    #[test]
    fn scene_normals_match_the_height_adapter_at_half_scale() {
        let family = crate::procedural::GlazedTiles::default();
        let scene = Scene::from_family(&family, 32, 5, &Device::Cpu).unwrap();
        assert_eq!(scene.brdf().name(), "ggx");
        let maps = family.generate(32, 5, &Device::Cpu).unwrap();
        let expected = photomat_brdfs::height::HeightToNormal {
            scale: family.relief / 2.0,
        }
        .normals(maps.get("height").unwrap())
        .unwrap();
        let diff = (scene.maps().get("normal").unwrap() - expected)
            .unwrap()
            .abs()
            .unwrap()
            .flatten_all()
            .unwrap()
            .max(0)
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert!(diff < 1e-6, "normals differ by {diff}");
    }

    #[test]
    fn highlight_jitter_is_centred_and_truncated() {
        let jitter = HighlightJitter::default();
        let mut rng = photo_rng(3, 0);
        let n = 4000;
        let samples: Vec<(f64, f64)> = (0..n).map(|_| jitter.sample(100, &mut rng)).collect();
        let mean_row = samples.iter().map(|s| s.0).sum::<f64>() / n as f64;
        let var_col = samples.iter().map(|s| (s.1 - 50.0).powi(2)).sum::<f64>() / n as f64;
        // σ = 4 px; standard error of the mean 4/√4000 ≈ 0.06 px. Truncation at 3σ lowers the
        // variance by 2.7 %.
        assert!((mean_row - 50.0).abs() < 0.3, "mean row {mean_row}");
        assert!((var_col.sqrt() - 4.0).abs() < 0.2, "std {}", var_col.sqrt());
        assert!(
            samples
                .iter()
                .all(|s| (s.0 - 50.0).abs() <= 12.0 && (s.1 - 50.0).abs() <= 12.0)
        );
        let fixed = HighlightJitter {
            sigma: 0.0,
            ..jitter
        };
        assert_eq!(fixed.sample(64, &mut rng), (32.0, 32.0));
    }
}
