//! The `DifferentiableBrdf` trait every model and adapter implements.
//!
//! Plugins do not implement it by hand: [`register_brdf!`](crate::register_brdf) wraps a
//! model's [`Reflectance`](crate::model::Reflectance) in a [`ModelBrdf`](crate::model::ModelBrdf)
//! and an adapter's [`MapAdapter`](crate::adapter::MapAdapter) in an
//! [`AdaptedBrdf`](crate::adapter::AdaptedBrdf), which carry the name and parameter maps of
//! the registration. Implementing it directly stays possible for models that are not
//! registered (test doubles, wrappers).
//!
//! Conventions (`docs/conventions.md`, Mitsuba 3's `BSDF::eval`): directions are per-texel world-space
//! unit vectors pointing away from the surface; `eval` returns `f(wi, wo)·cos θ_o` where θ_o
//! is measured from the model's shading normal; a pair with either direction below the
//! shading horizon gives exactly 0 (never NaN, with finite gradients).

use std::sync::Arc;

use candle_core::Tensor;

use crate::maps::MaterialMaps;
use crate::param::{ParamSpec, total_channels};
use crate::{Error, Result};

/// A reflectance model whose evaluation is differentiable w.r.t. every map (candle autodiff).
pub trait DifferentiableBrdf: Send + Sync {
    /// Canonical specification: [`crate::registry::lookup`] of this string rebuilds an equal
    /// model (`ggx`, `height(ggx, scale=0.02)`). Stored in map manifests.
    fn name(&self) -> String;

    /// The parameter maps the model takes, in the order of the estimator's output channels.
    fn params(&self) -> &[ParamSpec];

    /// `f(wi, wo)·cos θ_o`.
    ///
    /// # Shapes
    /// `wi`, `wo`: (B, 3, H, W) unit vectors; maps: (B or 1, C, H or 1, W or 1) as in
    /// [`MaterialMaps`]; result (B, 3, H, W).
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor>;

    /// The maps of the innermost analytic model, as a renderer outside photomat needs them
    /// (an adapter returns e.g. the normal derived from its height map). Identity for models.
    fn shading_maps(&self, maps: &MaterialMaps) -> Result<MaterialMaps> {
        Ok(maps.clone())
    }

    /// The model an adapter wraps (`ggx` in `height(ggx)`); `None` for models.
    /// [`innermost`](Self::innermost) follows this chain to the shading model.
    fn nested(&self) -> Option<&Brdf> {
        None
    }

    /// Total channel count `n` of the parameter maps (the estimator's output width).
    fn channels(&self) -> usize {
        total_channels(self.params())
    }

    /// Split raw network output (B, n, H, W) by parameter and decode each slice.
    fn decode(&self, raw: &Tensor) -> Result<MaterialMaps> {
        let (_, c, _, _) = raw.dims4()?;
        if c != self.channels() {
            return Err(Error::Invalid(format!(
                "model '{}' decodes {} channels, the raw tensor has {c}",
                self.name(),
                self.channels()
            )));
        }
        let mut maps = MaterialMaps::new();
        let mut offset = 0;
        for spec in self.params() {
            maps.insert(
                spec.name,
                spec.decode(&raw.narrow(1, offset, spec.channels)?)?,
            );
            offset += spec.channels;
        }
        Ok(maps)
    }
}

/// Shared handle to a model, as returned by the registry.
pub type Brdf = Arc<dyn DifferentiableBrdf>;

impl dyn DifferentiableBrdf {
    /// The innermost model of an adapter chain, the one that shades what
    /// [`DifferentiableBrdf::shading_maps`] returns: `ggx` for `height(ggx, scale=0.02)`,
    /// the model itself for a model.
    pub fn innermost(self: &Arc<Self>) -> Brdf {
        match self.nested() {
            Some(inner) => inner.innermost(),
            None => Arc::clone(self),
        }
    }
}
