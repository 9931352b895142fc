//! Gradients of every model w.r.t. every parameter map against central finite differences
//! in f64, through `eval` alone and through the whole flash renderer (so the height
//! adapter's wrap-around differences and the 1/d² falloff are covered too).

use candle_core::{DType, Tensor};
use photomat_core::{Brdf, Highlight, MaterialMaps, render_radiance};
use photomat_tests::{
    MODELS_UNDER_TEST, as_vars, gradients, model, perturbed, random_directions, random_maps, rng,
    values,
};
use rand::Rng;

const SIZE: usize = 4;
/// Central-difference step: truncation error ~h² ≈ 1e-12, rounding ~ε/h ≈ 1e-10 in f64.
const STEP: f64 = 1e-6;
/// Agreement required between analytic and numerical gradients (relative to max(1, |g|)).
const TOL: f64 = 1e-6;

fn check_against_finite_differences(
    spec: &str,
    maps: &MaterialMaps,
    loss: impl Fn(&MaterialMaps) -> Tensor,
) {
    let (var_maps, vars) = as_vars(maps);
    let analytic = gradients(&loss(&var_maps), &vars);
    for (name, grad) in analytic {
        let mut nonzero = 0;
        for (i, g) in grad.iter().enumerate() {
            let up = values(&loss(&perturbed(maps, &name, i, STEP)))[0];
            let down = values(&loss(&perturbed(maps, &name, i, -STEP)))[0];
            let numeric = (up - down) / (2.0 * STEP);
            assert!(
                (g - numeric).abs() <= TOL * g.abs().max(1.0),
                "{spec}: d/d{name}[{i}] analytic {g} vs finite difference {numeric}"
            );
            nonzero += usize::from(g.abs() > 1e-9);
        }
        assert!(
            nonzero > 0,
            "{spec}: gradient w.r.t. {name} is identically zero"
        );
    }
}

fn weights(seed: u64) -> Tensor {
    let mut r = rng(seed);
    let w: Vec<f64> = (0..3 * SIZE * SIZE)
        .map(|_| r.random_range(0.5..1.5))
        .collect();
    Tensor::from_vec(w, (1, 3, SIZE, SIZE), &candle_core::Device::Cpu).unwrap()
}

fn model_for_gradients(spec: &str) -> Brdf {
    // A visible relief so that the height adapter's normals depend strongly on the heights.
    model(if spec == "height(ggx)" {
        "height(ggx, scale=0.2)"
    } else {
        spec
    })
}

#[test]
fn every_model_eval_gradient_matches_finite_differences() {
    for spec in MODELS_UNDER_TEST {
        let brdf = model_for_gradients(spec);
        let mut r = rng(10);
        let maps = random_maps(&brdf, &mut r, SIZE, 0.1, DType::F64);
        let wi = random_directions(&mut r, SIZE, 0.5, DType::F64);
        let wo = random_directions(&mut r, SIZE, 0.5, DType::F64);
        let w = weights(11);
        check_against_finite_differences(spec, &maps, |m| {
            brdf.eval(&wi, &wo, m)
                .unwrap()
                .mul(&w)
                .unwrap()
                .sum_all()
                .unwrap()
        });
    }
}

#[test]
fn every_model_render_gradient_matches_finite_differences() {
    for spec in MODELS_UNDER_TEST {
        let brdf = model_for_gradients(spec);
        let mut r = rng(12);
        let maps = random_maps(&brdf, &mut r, SIZE, 0.1, DType::F64);
        let w = weights(13);
        let light = [Highlight::new(0.15, -0.1)];
        check_against_finite_differences(spec, &maps, |m| {
            render_radiance(brdf.as_ref(), m, &light)
                .unwrap()
                .mul(&w)
                .unwrap()
                .sum_all()
                .unwrap()
        });
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
    let w = weights(15);
    check_against_finite_differences("ggx (low roughness)", &maps, |m| {
        brdf.eval(&wi, &wo, m)
            .unwrap()
            .mul(&w)
            .unwrap()
            .sum_all()
            .unwrap()
    });
}
