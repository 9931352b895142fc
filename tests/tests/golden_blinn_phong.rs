//! `blinn_phong` against a reference composed in Dr.Jit (Mitsuba 3 has no Blinn-Phong plugin):
//! `golden/blinn_phong.json`, Dr.Jit's own `power(cos θ_h, e)` against photomat's
//! `exp(−e/2 · ln(1 + tan²θ_h))` form; tolerances in `golden/README.md`.

use photomat_tests as _;

#[path = "golden_support/mod.rs"]
mod support;

use candle_core::{DType, Tensor};
use photomat_core::{Brdf, DifferentiableBrdf, MaterialMaps, ParamSpec, Result, lookup};
use support::{F32, F64, compare_brdf, evaluate, load_brdf};

#[test]
fn blinn_phong_matches_its_golden_f64() {
    let model = lookup("blinn_phong").unwrap();
    let golden = load_brdf("blinn_phong", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F64);
    compare_brdf(&golden, &ours, &F64).assert_clean("blinn_phong (f64) vs Dr.Jit");
}

#[test]
fn blinn_phong_matches_its_golden_f32() {
    let model = lookup("blinn_phong").unwrap();
    let golden = load_brdf("blinn_phong", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F32);
    compare_brdf(&golden, &ours, &F32).assert_clean("blinn_phong (f32) vs Dr.Jit");
}

/// GGX with the same masking and Fresnel terms, answering to the name `blinn_phong`.
struct Impostor(Brdf);

impl DifferentiableBrdf for Impostor {
    fn name(&self) -> String {
        "blinn_phong".into()
    }
    fn params(&self) -> &[ParamSpec] {
        self.0.params()
    }
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        self.0.eval(wi, wo, maps)
    }
}

#[test]
fn blinn_phong_golden_rejects_ggx_with_the_same_g_and_f() {
    // Same maps, same implicit G and constant F: only D differs (the peaks are equal by
    // construction, the tails are not), and the golden must see it on most cases.
    let impostor = Impostor(lookup("ggx(shadowing=implicit, fresnel=constant)").unwrap());
    let golden = load_brdf("blinn_phong", &impostor);
    let ours = evaluate(&impostor, &golden.cases, DType::F64);
    let value_failures = compare_brdf(&golden, &ours, &F64).value_failures();
    assert!(
        value_failures > 100,
        "GGX passes blinn_phong's golden too often: {value_failures} value failures"
    );
}
