//! Models: the reflectance maths of a plugin under the name and maps of its registration.
//!
//! pbrt-v4 keeps the BxDF maths apart from the material's bookkeeping; here the plugin writes
//! only the maths ([`Reflectance::eval`]) and declares everything else once, in
//! [`register_brdf!`](crate::register_brdf): the registry builds a [`ModelBrdf`] that carries
//! the canonical name and the parameter maps of the registration and implements
//! [`DifferentiableBrdf`] by delegating `eval`. Adapters are the other kind of plugin
//! ([`crate::adapter`]).

use candle_core::Tensor;

use crate::Result;
use crate::brdf::DifferentiableBrdf;
use crate::maps::MaterialMaps;
use crate::param::ParamSpec;
use crate::registry::BrdfArgs;

/// The maths of a model plugin: `f(wi, wo)·cos θ_o` from per-texel directions and maps.
pub trait Reflectance: Send + Sync {
    /// `f(wi, wo)·cos θ_o`, exactly 0 when either direction is below the shading horizon
    /// (the contract of [`DifferentiableBrdf::eval`]).
    ///
    /// # Shapes
    /// `wi`, `wo`: (B, 3, H, W) unit vectors; maps: (B or 1, C, H or 1, W or 1), one per
    /// declared parameter; result (B, 3, H, W).
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor>;
}

/// A registered model: its [`Reflectance`] plus the identity its registration gave it.
pub struct ModelBrdf<R: Reflectance> {
    name: String,
    params: &'static [ParamSpec],
    reflectance: R,
}

impl<R: Reflectance> ModelBrdf<R> {
    /// The instance the registry is building (`args`), evaluated by `reflectance`: its name
    /// is the canonical specification, its maps the registration's `params`.
    pub fn new(args: &BrdfArgs, reflectance: R) -> Self {
        Self {
            name: args.canonical_name().to_string(),
            params: args.registration().params,
            reflectance,
        }
    }

    /// The model's maths.
    pub fn reflectance(&self) -> &R {
        &self.reflectance
    }
}

impl<R: Reflectance> DifferentiableBrdf for ModelBrdf<R> {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn params(&self) -> &[ParamSpec] {
        self.params
    }

    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        self.reflectance.eval(wi, wo, maps)
    }
}
