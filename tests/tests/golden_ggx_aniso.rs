//! `ggx_aniso` against a model composed in Dr.Jit from Mitsuba 3's anisotropic GGX
//! `MicrofacetDistribution` (α_u, α_v) in the tangent frame, with Schlick's Fresnel:
//! `golden/ggx_aniso.json`, tolerances in `golden/README.md`.

use photomat_tests as _;

#[path = "golden_support/mod.rs"]
mod support;

use candle_core::{DType, Tensor};
use photomat_core::{Brdf, DifferentiableBrdf, MaterialMaps, ParamSpec, Result, lookup};
use support::{F32, F64, compare_brdf, evaluate, load_brdf};

#[test]
fn ggx_aniso_matches_mitsuba_golden_f64() {
    let model = lookup("ggx_aniso").unwrap();
    let golden = load_brdf("ggx_aniso", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F64);
    compare_brdf(&golden, &ours, &F64).assert_clean("ggx_aniso (f64) vs Dr.Jit");
}

#[test]
fn ggx_aniso_matches_mitsuba_golden_f32() {
    let model = lookup("ggx_aniso").unwrap();
    let golden = load_brdf("ggx_aniso", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F32);
    compare_brdf(&golden, &ours, &F32).assert_clean("ggx_aniso (f32) vs Dr.Jit");
}

/// `ggx_aniso` with the tangent turned a quarter turn (α_t and α_b swap roles): the golden
/// must tell the tangent from the bitangent.
struct QuarterTurn(Brdf);

impl DifferentiableBrdf for QuarterTurn {
    fn name(&self) -> String {
        "ggx_aniso".into()
    }
    fn params(&self) -> &[ParamSpec] {
        self.0.params()
    }
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let mut turned = maps.clone();
        turned.insert("angle", (maps.get("angle")? + 0.5)?);
        self.0.eval(wi, wo, &turned)
    }
}

#[test]
fn ggx_aniso_golden_bites_a_quarter_turn_of_the_tangent() {
    let model = QuarterTurn(lookup("ggx_aniso").unwrap());
    let golden = load_brdf("ggx_aniso", &model);
    let ours = evaluate(&model, &golden.cases, DType::F64);
    let value_failures = compare_brdf(&golden, &ours, &F64).value_failures();
    assert!(
        value_failures > 100,
        "a quarter turn of the tangent must fail most cases, got {value_failures}"
    );
}

#[test]
fn ggx_aniso_with_equal_roughnesses_is_ggx() {
    // With α_t = α_b the lobe is isotropic: ggx_aniso equals ggx at every angle. The golden's
    // directions are unit only to float32 precision, and the two models' G1 forms read
    // |v|² = 1 differently (c² + α²(1 − c²) against c² + α²(v_t² + v_b²)): relative 1e-6.
    let aniso = lookup("ggx_aniso").unwrap();
    let iso = lookup("ggx").unwrap();
    let golden = load_brdf("ggx_aniso", &*aniso);
    let mut cases = golden.cases;
    for case in &mut cases {
        let r = case.params["roughness_t"].clone();
        case.params.insert("roughness_b".into(), r);
    }
    let ours = evaluate(&*aniso, &cases, DType::F64);
    for case in &mut cases {
        let r = case.params.remove("roughness_t").unwrap();
        case.params.remove("roughness_b");
        case.params.remove("angle");
        case.params.insert("roughness".into(), r);
    }
    let reference = evaluate(&*iso, &cases, DType::F64);
    for (i, (a, b)) in ours.f_cos.iter().zip(&reference.f_cos).enumerate() {
        for k in 0..3 {
            let (x, y) = (a[k], b[k]);
            assert!(
                (x - y).abs() <= 1e-6 * y.abs().max(1e-12),
                "case {i} ({}): ggx_aniso {x} vs ggx {y}",
                cases[i].tag
            );
        }
    }
}
