//! `ggx` against Mitsuba 3 (`diffuse` + `principled` metallic) and Dr.Jit gradients:
//! `golden/ggx.json`, tolerances in `golden/README.md`.

use photomat_tests as _;

#[path = "golden_support/mod.rs"]
mod support;

use std::sync::Arc;

use candle_core::{DType, Tensor};
use photomat_core::lobes::{ggx_lobe, lambert};
use photomat_core::microfacet::{ALPHA_MIN, schlick};
use photomat_core::{
    Brdf, DifferentiableBrdf, MaterialMaps, ParamSpec, Result, ShadingGeometry, lookup,
};
use support::{F32, F64, compare_brdf, evaluate, load_brdf};

#[test]
fn ggx_matches_mitsuba_golden_f64() {
    let model = lookup("ggx").unwrap();
    let golden = load_brdf("ggx", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F64);
    compare_brdf(&golden, &ours, &F64).assert_clean("ggx (f64) vs Mitsuba");
}

#[test]
fn ggx_matches_mitsuba_golden_f32() {
    let model = lookup("ggx").unwrap();
    let golden = load_brdf("ggx", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F32);
    compare_brdf(&golden, &ours, &F32).assert_clean("ggx (f32) vs Mitsuba");
}

/// Which formula of `ggx` a [`Perturbed`] model gets wrong.
#[derive(Clone, Copy, Debug)]
enum Perturbation {
    /// α = r instead of α = r².
    AlphaEqualsRoughness,
    /// The normal map used as given, without normalising it.
    UnnormalisedNormal,
    /// Same values, but no gradient reaches the roughness (a detached α).
    DetachedRoughness,
}

/// `ggx` rebuilt from core's public lobes with one formula changed.
struct Perturbed {
    base: Brdf,
    how: Perturbation,
}

impl DifferentiableBrdf for Perturbed {
    fn name(&self) -> String {
        "ggx".into()
    }

    fn params(&self) -> &[ParamSpec] {
        self.base.params()
    }

    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let normal = maps.get("normal")?;
        let geometry = match self.how {
            Perturbation::UnnormalisedNormal => {
                let mut g = ShadingGeometry::new(wi, wo, normal)?;
                // Cosines with the raw normal: wrong for every normal whose length is not 1.
                let dot =
                    |v: &Tensor| -> Result<Tensor> { Ok(normal.broadcast_mul(v)?.sum_keepdim(1)?) };
                g.cos_i = dot(wi)?.maximum(0.0)?;
                g.cos_o = dot(wo)?.maximum(0.0)?;
                g
            }
            _ => ShadingGeometry::new(wi, wo, normal)?,
        };
        let roughness = maps.get("roughness")?;
        let alpha = match self.how {
            Perturbation::AlphaEqualsRoughness => roughness.maximum(ALPHA_MIN)?,
            Perturbation::DetachedRoughness => roughness.detach().sqr()?.maximum(ALPHA_MIN)?,
            Perturbation::UnnormalisedNormal => roughness.sqr()?.maximum(ALPHA_MIN)?,
        };
        let f = schlick(&geometry.cos_d, maps.get("specular")?)?;
        let specular = ggx_lobe(&geometry, &f, &alpha)?;
        Ok((lambert(&geometry, maps.get("diffuse")?)? + specular)?)
    }
}

fn perturbed_failures(how: Perturbation) -> Vec<String> {
    let model = Perturbed {
        base: lookup("ggx").unwrap(),
        how,
    };
    let golden = load_brdf("ggx", &model);
    let ours = evaluate(&model, &golden.cases, DType::F64);
    let report = compare_brdf(&golden, &ours, &F64);
    eprintln!("{}", report.summary(&format!("perturbed ggx ({how:?})")));
    report.failures
}

#[test]
fn ggx_golden_rebuilt_from_core_lobes_passes() {
    // The perturbation harness itself is faithful: with the right formulas it passes.
    struct Rebuilt(Brdf);
    impl DifferentiableBrdf for Rebuilt {
        fn name(&self) -> String {
            "ggx".into()
        }
        fn params(&self) -> &[ParamSpec] {
            self.0.params()
        }
        fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
            let geometry = ShadingGeometry::new(wi, wo, maps.get("normal")?)?;
            let specular = photomat_core::lobes::ggx_specular(
                &geometry,
                maps.get("specular")?,
                maps.get("roughness")?,
            )?;
            Ok((lambert(&geometry, maps.get("diffuse")?)? + specular)?)
        }
    }
    let model = Rebuilt(lookup("ggx").unwrap());
    let golden = load_brdf("ggx", &model);
    let ours = evaluate(&model, &golden.cases, DType::F64);
    compare_brdf(&golden, &ours, &F64).assert_clean("ggx rebuilt from core lobes");
    let _: Arc<dyn DifferentiableBrdf> = Arc::new(model);
}

#[test]
fn ggx_golden_bites_alpha_equals_roughness() {
    let failures = perturbed_failures(Perturbation::AlphaEqualsRoughness);
    assert!(
        failures.iter().filter(|f| f.contains("f·cos θ_o")).count() > 100,
        "α = r instead of r² must fail the value comparison on most cases, got {} failures",
        failures.len()
    );
}

#[test]
fn ggx_golden_bites_unnormalised_normal() {
    let failures = perturbed_failures(Perturbation::UnnormalisedNormal);
    assert!(
        failures.iter().any(|f| f.contains("f·cos θ_o"))
            && failures.iter().any(|f| f.contains("/ d normal")),
        "skipping the normalisation must fail values and normal gradients, got {} failures",
        failures.len()
    );
}

#[test]
fn ggx_golden_bites_detached_roughness_gradient() {
    let failures = perturbed_failures(Perturbation::DetachedRoughness);
    assert!(
        !failures.is_empty() && failures.iter().all(|f| f.contains("/ d roughness")),
        "a roughness that receives no gradient must fail exactly the roughness-gradient checks: {:?}",
        failures.first()
    );
}
