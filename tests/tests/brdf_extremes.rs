//! Extreme inputs in f32, the production dtype: roughness at its floor and at 1, grazing
//! directions (cos θ = 1e-6, 0, just below 0), zero and unit albedos, near-tangent and zero
//! normals, steep height reliefs. Values and gradients must be finite (never NaN) and values
//! non-negative.
//!
//! Each proptest case evaluates 16 texels at once; every run (default profile included) runs
//! 10 000 cases per property, ≈ 25 s in all on the 2-core build machine.

use candle_core::{DType, Device, Tensor};
use photomat_core::{Brdf, Highlight, MaterialMaps, render_radiance};
use photomat_tests::{MODELS_UNDER_TEST, as_vars, gradients, model, values};
use proptest::prelude::*;

const SIZE: usize = 4;
const TEXELS: usize = SIZE * SIZE;

/// Proptest cases per property (each covering 16 texels).
const CASES: u32 = 10_000;

/// A value in [0, 1] biased towards the ends and the α-floor region of roughness.
fn unit() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(1.0),
        Just(1e-4),
        Just(1e-2),
        Just(1.0 - 1e-7),
        0.0..=1.0f64
    ]
}

/// A cosine biased towards grazing: exactly tangent, 1e-6, 1e-7, just below the horizon.
fn cosine() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(1e-6),
        Just(1e-7),
        Just(-1e-6),
        Just(1.0),
        -1.0..=1.0f64,
        1e-6..1e-3f64
    ]
}

fn direction() -> impl Strategy<Value = [f64; 3]> {
    (cosine(), 0.0..std::f64::consts::TAU).prop_map(|(z, phi)| {
        let s = (1.0 - z * z).max(0.0).sqrt();
        [s * phi.cos(), s * phi.sin(), z]
    })
}

/// Normals including near-tangent ones and the zero vector (degenerate input).
fn normal() -> impl Strategy<Value = [f64; 3]> {
    prop_oneof![
        Just([0.0, 0.0, 0.0]),
        Just([0.0, 0.0, 1.0]),
        direction(),
        (
            0.0..std::f64::consts::TAU,
            prop_oneof![Just(1e-6), Just(1e-3)]
        )
            .prop_map(|(phi, z): (f64, f64)| [phi.cos(), phi.sin(), z]),
    ]
}

#[derive(Debug, Clone)]
struct Texel {
    wi: [f64; 3],
    wo: [f64; 3],
    normal: [f64; 3],
    params: Vec<f64>, // enough unit values for the widest model
}

fn texels() -> impl Strategy<Value = Vec<Texel>> {
    prop::collection::vec(
        (
            direction(),
            direction(),
            normal(),
            prop::collection::vec(unit(), 11),
        )
            .prop_map(|(wi, wo, normal, params)| Texel {
                wi,
                wo,
                normal,
                params,
            }),
        TEXELS,
    )
}

fn tensor(data: Vec<f64>, channels: usize) -> Tensor {
    Tensor::from_vec(data, (1, channels, SIZE, SIZE), &Device::Cpu)
        .unwrap()
        .to_dtype(DType::F32)
        .unwrap()
}

fn vectors(texels: &[Texel], pick: impl Fn(&Texel) -> [f64; 3]) -> Tensor {
    let mut data = vec![0.0; 3 * TEXELS];
    for (t, texel) in texels.iter().enumerate() {
        for (c, v) in pick(texel).iter().enumerate() {
            data[c * TEXELS + t] = *v;
        }
    }
    tensor(data, 3)
}

/// Maps for `brdf`: normals from the texels, every other channel from the unit values
/// scaled to the spec's range.
fn maps_for(brdf: &Brdf, texels: &[Texel]) -> MaterialMaps {
    let mut maps = MaterialMaps::new();
    let mut next = 0;
    for spec in brdf.params() {
        let t = if spec.name == "normal" {
            vectors(texels, |t| t.normal)
        } else {
            let (lo, hi) = (spec.range.0 as f64, spec.range.1 as f64);
            let mut data = vec![0.0; spec.channels * TEXELS];
            for c in 0..spec.channels {
                for (i, texel) in texels.iter().enumerate() {
                    data[c * TEXELS + i] = lo + (hi - lo) * texel.params[next + c];
                }
            }
            tensor(data, spec.channels)
        };
        next += spec.channels;
        maps.insert(spec.name, t);
    }
    maps
}

fn assert_finite_with_gradients(
    spec: &str,
    maps: &MaterialMaps,
    eval: impl Fn(&MaterialMaps) -> Tensor,
) {
    let (var_maps, vars) = as_vars(maps);
    let out = eval(&var_maps);
    let v = values(&out);
    assert!(
        v.iter().all(|x| x.is_finite() && *x >= 0.0),
        "{spec}: value not finite or negative: {v:?}"
    );
    for (name, g) in gradients(&out.sum_all().unwrap(), &vars) {
        assert!(
            g.iter().all(|x| x.is_finite()),
            "{spec}: gradient w.r.t. {name} not finite: {g:?}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn every_model_eval_is_finite_at_extremes(texels in texels()) {
        for spec in MODELS_UNDER_TEST {
            let brdf = model(spec);
            let maps = maps_for(&brdf, &texels);
            let wi = vectors(&texels, |t| t.wi);
            let wo = vectors(&texels, |t| t.wo);
            assert_finite_with_gradients(spec, &maps, |m| brdf.eval(&wi, &wo, m).unwrap());
        }
    }

    #[test]
    fn every_model_render_is_finite_at_extremes(texels in texels(), lx in -2.0..2.0f64, ly in -2.0..2.0f64) {
        for spec in MODELS_UNDER_TEST {
            let brdf = model(spec);
            let maps = maps_for(&brdf, &texels);
            let light = [Highlight::new(lx, ly)];
            assert_finite_with_gradients(spec, &maps, |m| {
                photomat_core::encode_display(&render_radiance(brdf.as_ref(), m, &light).unwrap()).unwrap()
            });
        }
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
        assert_finite_with_gradients("height(ggx)", &maps, |m| render_radiance(brdf.as_ref(), m, &light).unwrap());
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
    assert_finite_with_gradients("height(ggx, scale=1)", &maps, |m| {
        render_radiance(brdf.as_ref(), m, &light).unwrap()
    });
}
