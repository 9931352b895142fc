//! `lambert`: an ideal diffuse reflector, `f = ρ/π`.
//!
//! The cheapest model: what "model only what the scene requires" picks for matte materials
//! (paper, fabrics, plaster). Reference: Mitsuba 3 `diffuse` (Lambert 1760).
//!
//! | map      | ch | range  | encoding | file        | at 0                 | at the top          |
//! |----------|----|--------|----------|-------------|----------------------|---------------------|
//! | `diffuse`| 3  | [0, 1] | gamma2.2 | gamma PNG   | black: no reflection | white: reflects all |
//! | `normal` | 3  | unit   | normal   | 0.5·n + 0.5 | +z: flat             | grazing tilt        |
//!
//! n = 6. Usage: `photomat render --maps DIR --brdf lambert --light 0,0 --out img.png`.

use std::sync::Arc;

use candle_core::Tensor;
use photomat_core::lobes::lambert;
use photomat_core::{
    Brdf, BrdfArgs, BrdfRegistration, DifferentiableBrdf, MaterialMaps, ParamSpec, Result,
    ShadingGeometry, register_brdf,
};

use crate::common::{DIFFUSE, NORMAL};

const PARAMS: &[ParamSpec] = &[DIFFUSE, NORMAL];

/// The Lambert model.
pub struct Lambert;

impl DifferentiableBrdf for Lambert {
    fn name(&self) -> String {
        "lambert".into()
    }

    fn params(&self) -> &[ParamSpec] {
        PARAMS
    }

    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
        lambert(&geometry, maps.get("diffuse")?)
    }
}

fn construct(_: &BrdfArgs) -> Result<Brdf> {
    Ok(Arc::new(Lambert))
}

register_brdf!(BrdfRegistration {
    name: "lambert",
    summary: "ideal diffuse reflector ρ/π (Mitsuba 'diffuse')",
    params: PARAMS,
    replaces: &[],
    takes_nested: false,
    args: &[],
    construct,
});
