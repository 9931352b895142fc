//! The variants of `ggx` (its `shadowing` and `fresnel` choices) against references composed in
//! Dr.Jit from Mitsuba 3's `MicrofacetDistribution` (Mitsuba has no plugin for them):
//! `golden/ggx_*.json`, tolerances in `golden/README.md`.

use photomat_tests as _;

#[path = "golden_support/mod.rs"]
mod support;

use candle_core::{DType, Tensor};
use photomat_core::{Brdf, DifferentiableBrdf, MaterialMaps, ParamSpec, Result, lookup};
use support::{F32, F64, compare_brdf, evaluate, load_brdf};

/// (golden stem, specification) of every variant with a golden file.
const VARIANTS: [(&str, &str); 3] = [
    ("ggx_shadowing_correlated", "ggx(shadowing=correlated)"),
    ("ggx_shadowing_implicit", "ggx(shadowing=implicit)"),
    ("ggx_fresnel_constant", "ggx(fresnel=constant)"),
];

#[test]
fn ggx_variants_match_their_goldens_f64() {
    for (stem, spec) in VARIANTS {
        let model = lookup(spec).unwrap();
        let golden = load_brdf(stem, &*model);
        let ours = evaluate(&*model, &golden.cases, DType::F64);
        compare_brdf(&golden, &ours, &F64).assert_clean(&format!("{spec} (f64) vs Dr.Jit"));
    }
}

#[test]
fn ggx_variants_match_their_goldens_f32() {
    for (stem, spec) in VARIANTS {
        let model = lookup(spec).unwrap();
        let golden = load_brdf(stem, &*model);
        let ours = evaluate(&*model, &golden.cases, DType::F32);
        compare_brdf(&golden, &ours, &F32).assert_clean(&format!("{spec} (f32) vs Dr.Jit"));
    }
}

/// Another model answering to a variant's name, to show that the goldens tell variants apart.
struct Impostor {
    model: Brdf,
    name: &'static str,
}

impl DifferentiableBrdf for Impostor {
    fn name(&self) -> String {
        self.name.into()
    }
    fn params(&self) -> &[ParamSpec] {
        self.model.params()
    }
    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        self.model.eval(wi, wo, maps)
    }
}

#[test]
fn ggx_variant_goldens_reject_the_default_model() {
    // The default `ggx` (separable Smith, Schlick) differs from each variant on most random
    // cases: the variant goldens would catch an argument that is parsed but ignored.
    for (stem, spec) in VARIANTS {
        let impostor = Impostor {
            model: lookup("ggx").unwrap(),
            name: spec,
        };
        let golden = load_brdf(stem, &impostor);
        let ours = evaluate(&impostor, &golden.cases, DType::F64);
        let value_failures = compare_brdf(&golden, &ours, &F64).value_failures();
        assert!(
            value_failures > 100,
            "plain ggx passes {spec}'s golden too often: {value_failures} value failures"
        );
    }
}
