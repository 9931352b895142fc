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

use candle_core::Tensor;
use photomat_core::lobes::lambert;
use photomat_core::param::common::{DIFFUSE, NORMAL};
use photomat_core::{MaterialMaps, Reflectance, Result, ShadingGeometry, register_brdf};

/// The Lambert model.
pub struct Lambert;

impl Reflectance for Lambert {
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
        lambert(&geometry, maps.get("diffuse")?)
    }
}

register_brdf! {
    name: "lambert",
    summary: "ideal diffuse reflector ρ/π (Mitsuba 'diffuse')",
    params: &[DIFFUSE, NORMAL],
    model: |_| Ok(Lambert),
}
