//! Extreme inputs in f32, the production dtype: roughness at its floor and at 1, grazing
//! directions (cos θ = 1e-6, 0, just below 0), zero and unit albedos, near-tangent and zero
//! normals, steep height reliefs. Values and gradients must be finite (never NaN) and values
//! non-negative.
//!
//! The model-generic cases are the conformance kit's
//! ([`photomat_core::testing::check_finite_at_extremes`]: 10 000 seeded cases of 16 texels per
//! model, through `eval` and the renderer); the height adapter's steep reliefs are checked
//! here with proptest (10 000 cases), and the α floor's derivative is the chosen subgradient
//! in f32 (0 at a tie, never half the unclamped one).

use candle_core::{DType, Device, Tensor};
use photomat_core::microfacet::{ALPHA_MIN, alpha_from_roughness};
use photomat_core::testing::{check_finite_at_extremes, check_finite_with_gradients};
use photomat_core::{Highlight, MaterialMaps, render_radiance};
use photomat_tests::{model, models_under_test};
use proptest::prelude::*;

const SIZE: usize = 4;
const TEXELS: usize = SIZE * SIZE;

/// Proptest cases per property (each covering 16 texels).
const CASES: u32 = 10_000;

fn tensor(data: Vec<f64>, channels: usize) -> Tensor {
    Tensor::from_vec(data, (1, channels, SIZE, SIZE), &Device::Cpu)
        .unwrap()
        .to_dtype(DType::F32)
        .unwrap()
}

#[test]
fn every_model_eval_and_render_are_finite_at_extremes() {
    for spec in models_under_test() {
        check_finite_at_extremes(&spec).unwrap();
    }
}

/// dα/dr of [`alpha_from_roughness`] at each f32 roughness, by autodiff.
fn alpha_gradient(roughness: &[f32]) -> Vec<f32> {
    let r = candle_core::Var::from_tensor(
        &Tensor::from_vec(roughness.to_vec(), (1, 1, 1, roughness.len()), &Device::Cpu).unwrap(),
    )
    .unwrap();
    let grads = alpha_from_roughness(r.as_tensor())
        .unwrap()
        .sum_all()
        .unwrap()
        .backward()
        .unwrap();
    grads
        .get(r.as_tensor())
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap()
}

#[test]
fn alpha_floor_tie_has_zero_gradient_in_f32() {
    // 0.01 squares to exactly the f32 value of the floor 1e-4: the floor holds, dα/dr = 0.
    let tie = 0.01f32;
    assert_eq!(tie * tie, ALPHA_MIN as f32);
    let above = f32::from_bits(tie.to_bits() + 1);
    let below = f32::from_bits(tie.to_bits() - 1);
    assert_eq!(
        alpha_gradient(&[below, tie, above]),
        [0.0, 0.0, 2.0 * above]
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn alpha_gradient_is_the_chosen_subgradient(
        r in prop_oneof![Just(0.0f32), Just(0.01f32), 0.0f32..=1.0, 0.009f32..0.011],
    ) {
        let g = alpha_gradient(&[r])[0];
        let expected = if r * r > ALPHA_MIN as f32 { 2.0 * r } else { 0.0 };
        prop_assert_eq!(g, expected);
    }

    #[test]
    fn height_adapter_is_finite_for_steep_reliefs(
        heights in prop::collection::vec(prop_oneof![Just(0.0), Just(1.0), 0.0..=1.0f64], TEXELS),
        scale in prop_oneof![Just(0.0), Just(1e-3), Just(1.0), 0.0..=1.0f64],
        lx in -1.0..1.0f64,
    ) {
        let brdf = model(&format!("height(ggx, scale={scale})"));
        let mut maps = MaterialMaps::defaults(brdf.params(), 1, SIZE, DType::F32, &Device::Cpu).unwrap();
        maps.insert("height", tensor(heights, 1));
        maps.insert("roughness", Tensor::full(1e-4f32, (1, 1, SIZE, SIZE), &Device::Cpu).unwrap());
        let light = [Highlight::new(lx, 0.0)];
        check_finite_with_gradients("height(ggx)", &maps, |m| render_radiance(brdf.as_ref(), m, &light)).unwrap();
    }
}

#[test]
fn height_adapter_is_finite_for_a_256_checkerboard_at_full_scale() {
    // The steepest relief the format allows: h alternating 0/1 per texel at 256², scale 1,
    // i.e. slopes of 128 (normals ≈ 89.6° from +z), mirror-like roughness.
    const R: usize = 256;
    let brdf = model("height(ggx, scale=1)");
    let heights: Vec<f32> = (0..R * R).map(|i| ((i / R + i % R) % 2) as f32).collect();
    let mut maps = MaterialMaps::defaults(brdf.params(), 1, R, DType::F32, &Device::Cpu).unwrap();
    maps.insert(
        "height",
        Tensor::from_vec(heights, (1, 1, R, R), &Device::Cpu).unwrap(),
    );
    maps.insert(
        "roughness",
        Tensor::zeros((1, 1, R, R), DType::F32, &Device::Cpu).unwrap(),
    );
    let light = [Highlight::new(0.3, -0.2)];
    check_finite_with_gradients("height(ggx, scale=1)", &maps, |m| {
        render_radiance(brdf.as_ref(), m, &light)
    })
    .unwrap();
}
