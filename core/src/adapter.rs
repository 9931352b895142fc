//! Composable adapters: a model that rewrites its maps and hands them to a nested model.
//!
//! Mitsuba 3's `bumpmap`/`normalmap` are the model: an adapter is a plugin too, registered
//! with [`register_brdf!`](crate::register_brdf)'s `adapter:` form, built around the nested
//! model named in the specification (`height(ggx)`), and adapters nest (`a(b(ggx))`). The
//! registration declares which of the nested model's maps the adapter replaces and which it
//! adds; [`AdaptedBrdf`] does the bookkeeping and implements [`DifferentiableBrdf`] by evaluating the nested model on the
//! adapted maps, so gradients flow through the adaptation by candle autodiff.

use candle_core::Tensor;

use crate::brdf::{Brdf, DifferentiableBrdf};
use crate::maps::MaterialMaps;
use crate::param::ParamSpec;
use crate::registry::BrdfArgs;
use crate::{Error, Result};

/// The map rewrite at the heart of an adapter.
pub trait MapAdapter: Send + Sync {
    /// The nested model's maps from this adapter's maps: read the added maps, produce the
    /// replaced ones, pass every other map through unchanged.
    fn adapt(&self, maps: &MaterialMaps) -> Result<MaterialMaps>;
}

/// A nested model seen through a [`MapAdapter`].
pub struct AdaptedBrdf<A: MapAdapter> {
    name: String,
    params: Vec<ParamSpec>,
    nested: Brdf,
    adapter: A,
}

impl<A: MapAdapter> AdaptedBrdf<A> {
    /// Wrap `args.nested()`: its maps named in the registration's `replaces` give way to the
    /// registration's `params` (the maps the adapter adds), inserted where the first replaced
    /// map stood (so the channel order stays natural: diffuse, specular, roughness, height).
    pub fn new(args: &BrdfArgs, adapter: A) -> Result<Self> {
        let (adds, replaces) = (args.registration().params, args.registration().replaces);
        let nested = args.nested()?;
        let inner = nested.params();
        for name in replaces {
            if !inner.iter().any(|s| s.name == *name) {
                return Err(Error::BadSpec {
                    spec: args.canonical_name().to_string(),
                    reason: format!(
                        "the nested model '{}' has no '{name}' map to replace (its maps: {})",
                        nested.name(),
                        inner.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
                    ),
                });
            }
        }
        let mut params = Vec::with_capacity(inner.len() + adds.len());
        let mut inserted = false;
        for spec in inner {
            if replaces.contains(&spec.name) {
                if !inserted {
                    params.extend_from_slice(adds);
                    inserted = true;
                }
            } else {
                params.push(spec.clone());
            }
        }
        if !inserted {
            params.extend_from_slice(adds);
        }
        Ok(Self {
            name: args.canonical_name().to_string(),
            params,
            nested,
            adapter,
        })
    }

    /// The map rewrite.
    pub fn adapter(&self) -> &A {
        &self.adapter
    }
}

impl<A: MapAdapter> DifferentiableBrdf for AdaptedBrdf<A> {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn params(&self) -> &[ParamSpec] {
        &self.params
    }

    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        self.nested.eval(wi, wo, &self.adapter.adapt(maps)?)
    }

    fn shading_maps(&self, maps: &MaterialMaps) -> Result<MaterialMaps> {
        self.nested.shading_maps(&self.adapter.adapt(maps)?)
    }

    fn nested(&self) -> Option<&Brdf> {
        Some(&self.nested)
    }
}
