//! Gradients of every model w.r.t. every parameter map against central finite differences
//! in f64, through `eval` alone and through the whole flash renderer (so the height
//! adapter's wrap-around differences and the 1/d² falloff are covered too). The checks are
//! the conformance kit's ([`photomat_core::testing`]); the sharp-lobe case is ggx's own.

use candle_core::{DType, Tensor};
use photomat_core::plugin_spec::PluginSpec;
use photomat_core::testing::{
    GRADIENT_SIZE as SIZE, check_against_finite_differences, check_eval_gradients,
    check_render_gradients, weights,
};
use photomat_tests::{model, models_under_test, random_directions, random_maps, rng};
use rand::Rng;

/// `spec` with a visible relief (every height adapter at scale 0.2), so that the height
/// adapter's normals depend strongly on the heights.
fn with_visible_relief(spec: &str) -> String {
    fn relief(spec: &mut PluginSpec) {
        spec.nested.iter_mut().for_each(relief);
        if spec.name == "height" {
            spec.values.retain(|(k, _)| k != "scale");
            spec.values
                .push(("scale".into(), photomat_core::ArgValue::Number(0.2)));
        }
    }
    let mut parsed = PluginSpec::parse(spec).unwrap();
    relief(&mut parsed);
    parsed.to_string()
}

#[test]
fn every_model_eval_gradient_matches_finite_differences() {
    for spec in models_under_test() {
        check_eval_gradients(&with_visible_relief(&spec)).unwrap();
    }
}

#[test]
fn every_model_render_gradient_matches_finite_differences() {
    for spec in models_under_test() {
        check_render_gradients(&with_visible_relief(&spec)).unwrap();
    }
}

#[test]
fn ggx_low_roughness_gradient_matches_finite_differences() {
    // Sharp lobes (r ∈ [0.05, 0.2]) with wo near the mirror direction of wi stress D's slope.
    let brdf = model("ggx");
    let mut r = rng(14);
    let mut maps = random_maps(&brdf, &mut r, SIZE, 0.05, DType::F64);
    let rough: Vec<f64> = (0..SIZE * SIZE)
        .map(|_| r.random_range(0.05..0.2))
        .collect();
    maps.insert(
        "roughness",
        Tensor::from_vec(rough, (1, 1, SIZE, SIZE), &candle_core::Device::Cpu).unwrap(),
    );
    let wi = random_directions(&mut r, SIZE, 0.9, DType::F64);
    let wo = wi.clone();
    let w = weights(15).unwrap();
    check_against_finite_differences("ggx (low roughness)", &maps, |m| {
        Ok(brdf.eval(&wi, &wo, m)?.mul(&w)?.sum_all()?)
    })
    .unwrap();
}
