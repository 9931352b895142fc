//! `MaterialMaps`: the named parameter maps of one batch of materials.
//!
//! Shapes: every map is NCHW, (B, channels, H, W), all maps of a set sharing B, H and W.
//!
//! A set may carry its texel size in world units (`docs/conventions.md`, "Spatial
//! generator"): a spatial model's materials keep one texel size whatever their side N, so
//! that what is derived across texels (the `height` adapter's normals) means the same at every
//! N. Without one, the maps cover the unit square and a texel is 1/R wide.
//! Maps of shape (B, C, 1, 1) are allowed where a model is evaluated on independent samples
//! (brdf-eval, furnace tests): plugins broadcast maps against the direction tensors.

use std::collections::BTreeMap;

use candle_core::{DType, Device, Tensor};

use crate::param::ParamSpec;
use crate::{Error, Result};

/// Named NCHW tensors, one per parameter of a BRDF model.
#[derive(Debug, Clone, Default)]
pub struct MaterialMaps {
    maps: BTreeMap<String, Tensor>,
    texel_size: Option<f64>,
}

impl MaterialMaps {
    /// An empty set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Builder-style insertion.
    pub fn with(mut self, name: impl Into<String>, map: Tensor) -> Self {
        self.insert(name, map);
        self
    }

    /// The same maps with texels of `size` world units (`None`: the unit square's 1/R).
    pub fn with_texel_size(mut self, size: Option<f64>) -> Self {
        self.texel_size = size;
        self
    }

    /// World units per texel, when the set records it (module docs).
    pub fn texel_size(&self) -> Option<f64> {
        self.texel_size
    }

    /// World units per texel of maps R texels wide: the recorded size, else 1/R (the unit
    /// square).
    pub fn texel_size_or_unit(&self, size: usize) -> f64 {
        self.texel_size.unwrap_or(1.0 / size as f64)
    }

    /// Insert or replace one map.
    pub fn insert(&mut self, name: impl Into<String>, map: Tensor) {
        self.maps.insert(name.into(), map);
    }

    /// Remove one map, returning it.
    pub fn remove(&mut self, name: &str) -> Option<Tensor> {
        self.maps.remove(name)
    }

    /// The map called `name`, or an error naming the maps that exist.
    pub fn get(&self, name: &str) -> Result<&Tensor> {
        self.maps.get(name).ok_or_else(|| {
            Error::Invalid(format!(
                "material has no '{name}' map (it has: {})",
                self.names().join(", ")
            ))
        })
    }

    /// Whether a map called `name` exists.
    pub fn contains(&self, name: &str) -> bool {
        self.maps.contains_key(name)
    }

    /// Map names, sorted.
    pub fn names(&self) -> Vec<&str> {
        self.maps.keys().map(String::as_str).collect()
    }

    /// Iterate over (name, map), sorted by name.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &Tensor)> {
        self.maps.iter().map(|(k, v)| (k.as_str(), v))
    }

    /// Reflectance under a dim, uniform white sky: (B, 3, H, W), the sum of the `diffuse` map
    /// and of every 3-channel map whose name starts with `specular`, or `None` when the set
    /// has neither. A Lambert lobe reflects exactly its albedo `ρ_d` of a uniform sky; a GGX
    /// lobe reflects about its F0 (the Fresnel rise at grazing angles and the
    /// multiple-scattering loss neglected), which is what the names mean in the built-in
    /// models (`docs/conventions.md`, "Parameter maps"). The flash-photo simulator lights its
    /// photos' ambient term with it and `photomat capture` fits that term.
    pub fn ambient_reflectance(&self) -> Result<Option<Tensor>> {
        let mut total: Option<Tensor> = None;
        for (name, map) in self.iter() {
            let reflects = name == "diffuse" || name.starts_with("specular");
            if reflects && map.dim(1)? == 3 {
                total = Some(match total {
                    None => map.clone(),
                    Some(t) => (t + map)?,
                });
            }
        }
        Ok(total)
    }

    /// Apply `f` to every map (dtype or device conversion, detaching, narrowing a batch).
    pub fn map_tensors(&self, mut f: impl FnMut(&Tensor) -> Result<Tensor>) -> Result<Self> {
        let mut out = Self::new().with_texel_size(self.texel_size);
        for (name, map) in &self.maps {
            out.insert(name.clone(), f(map)?);
        }
        Ok(out)
    }

    /// Maps filled with each spec's default value: (batch, channels, size, size) per spec.
    pub fn defaults(
        specs: &[ParamSpec],
        batch: usize,
        size: usize,
        dtype: DType,
        device: &Device,
    ) -> Result<Self> {
        let mut out = Self::new();
        for spec in specs {
            let v = Tensor::new(spec.default, device)?
                .to_dtype(dtype)?
                .reshape((1, spec.channels, 1, 1))?
                .broadcast_as((batch, spec.channels, size, size))?
                .contiguous()?;
            out.insert(spec.name, v);
        }
        Ok(out)
    }

    /// (B, H, W) shared by all maps; error if the set is empty or the maps disagree.
    pub fn batch_and_size(&self) -> Result<(usize, usize, usize)> {
        let mut shape: Option<(usize, usize, usize, &str)> = None;
        for (name, map) in self.iter() {
            let (b, _, h, w) = map.dims4().map_err(|_| {
                Error::Invalid(format!(
                    "map '{name}' must be NCHW (4 dims), got shape {:?}",
                    map.dims()
                ))
            })?;
            match shape {
                None => shape = Some((b, h, w, name)),
                Some((b0, h0, w0, first)) if (b0, h0, w0) != (b, h, w) => {
                    return Err(Error::Invalid(format!(
                        "map sizes differ: '{first}' is {b0}×{h0}×{w0} (batch×height×width), \
                         '{name}' is {b}×{h}×{w}"
                    )));
                }
                Some(_) => {}
            }
        }
        shape
            .map(|(b, h, w, _)| (b, h, w))
            .ok_or_else(|| Error::Invalid("material has no maps".into()))
    }

    /// Full check at a trust boundary (files, command line): [`Self::validate_shapes`] plus
    /// no NaN or infinity anywhere. Copies the maps to host memory.
    pub fn validate(&self, model: &str, specs: &[ParamSpec]) -> Result<()> {
        self.validate_shapes(model, specs)?;
        for (name, map) in self.iter() {
            let finite = map
                .to_dtype(DType::F32)?
                .flatten_all()?
                .to_vec1::<f32>()?
                .iter()
                .all(|v| v.is_finite());
            if !finite {
                return Err(Error::InvalidMaps {
                    model: model.to_string(),
                    reason: format!("map '{name}' contains NaN or infinite values"),
                });
            }
        }
        Ok(())
    }

    /// Cheap structural check (used on every render): every spec present with the right
    /// channel count, no unknown maps, equal B/H/W.
    pub fn validate_shapes(&self, model: &str, specs: &[ParamSpec]) -> Result<()> {
        let bad = |reason: String| Error::InvalidMaps {
            model: model.to_string(),
            reason,
        };
        for spec in specs {
            let map = self.maps.get(spec.name).ok_or_else(|| {
                bad(format!(
                    "missing map '{}' (expected: {}; given: {})",
                    spec.name,
                    specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", "),
                    self.names().join(", ")
                ))
            })?;
            let c = map.dims().get(1).copied().unwrap_or(0);
            if map.rank() != 4 || c != spec.channels {
                return Err(bad(format!(
                    "map '{}' must have shape (B, {}, H, W), got {:?}",
                    spec.name,
                    spec.channels,
                    map.dims()
                )));
            }
        }
        if let Some(extra) = self
            .names()
            .into_iter()
            .find(|n| !specs.iter().any(|s| s.name == *n))
        {
            return Err(bad(format!(
                "unexpected map '{extra}' (the model takes: {})",
                specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
            )));
        }
        self.batch_and_size().map_err(|e| bad(e.to_string()))?;
        Ok(())
    }
}
