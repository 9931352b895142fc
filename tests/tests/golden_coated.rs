//! `coated` against Mitsuba 3 (`diffuse` + two `principled` metallic lobes) and Dr.Jit
//! gradients: `golden/coated.json`, tolerances in `golden/README.md`.

use photomat_tests as _;

#[path = "golden_support/mod.rs"]
mod support;

use candle_core::{DType, Tensor};
use photomat_core::lobes::{ggx_lobe, ggx_specular, lambert};
use photomat_core::microfacet::alpha_from_roughness;
use photomat_core::vecops::constant3;
use photomat_core::{
    Brdf, DifferentiableBrdf, MaterialMaps, ParamSpec, Result, ShadingGeometry, lookup,
};
use support::{F32, F64, compare_brdf, evaluate, load_brdf};

#[test]
fn coated_matches_mitsuba_golden_f64() {
    let model = lookup("coated").unwrap();
    let golden = load_brdf("coated", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F64);
    compare_brdf(&golden, &ours, &F64).assert_clean("coated (f64) vs Mitsuba");
}

#[test]
fn coated_matches_mitsuba_golden_f32() {
    let model = lookup("coated").unwrap();
    let golden = load_brdf("coated", &*model);
    let ours = evaluate(&*model, &golden.cases, DType::F32);
    compare_brdf(&golden, &ours, &F32).assert_clean("coated (f32) vs Mitsuba");
}

/// Which formula of `coated` a [`Perturbed`] model gets wrong.
#[derive(Clone, Copy, Debug)]
enum Perturbation {
    /// Schlick's Fresnel with exponent 4 instead of 5 in both lobes.
    SchlickExponent4,
    /// The second lobe reads the first lobe's roughness.
    SharedRoughness,
}

/// `coated` rebuilt from core's public lobes with one formula changed.
struct Perturbed {
    base: Brdf,
    how: Perturbation,
}

/// The GGX lobe of `photomat_core::lobes::ggx_specular` with Schlick's exponent 4.
fn lobe_schlick4(geometry: &ShadingGeometry, f0: &Tensor, roughness: &Tensor) -> Result<Tensor> {
    let alpha = alpha_from_roughness(roughness)?;
    let weight = (1.0 - geometry.cos_d.clamp(0.0, 1.0)?)?.powf(4.0)?;
    let f = f0.broadcast_add(&(1.0 - f0)?.broadcast_mul(&weight)?)?;
    ggx_lobe(geometry, &f, &alpha)
}

impl DifferentiableBrdf for Perturbed {
    fn name(&self) -> String {
        "coated".into()
    }

    fn params(&self) -> &[ParamSpec] {
        self.base.params()
    }

    fn eval(&self, wi: &Tensor, wo: &Tensor, maps: &MaterialMaps) -> Result<Tensor> {
        let geometry = ShadingGeometry::new(wi, wo, &constant3([0.0, 0.0, 1.0], wi)?)?;
        let diffuse = lambert(&geometry, maps.get("diffuse")?)?;
        let (s1, r1, s2, r2) = (
            maps.get("specular")?,
            maps.get("roughness")?,
            maps.get("specular2")?,
            maps.get("roughness2")?,
        );
        let (lobe1, lobe2) = match self.how {
            Perturbation::SchlickExponent4 => (
                lobe_schlick4(&geometry, s1, r1)?,
                lobe_schlick4(&geometry, s2, r2)?,
            ),
            Perturbation::SharedRoughness => (
                ggx_specular(&geometry, s1, r1)?,
                ggx_specular(&geometry, s2, r1)?,
            ),
        };
        Ok(((diffuse + lobe1)? + lobe2)?)
    }
}

fn perturbed_failures(how: Perturbation) -> Vec<String> {
    let model = Perturbed {
        base: lookup("coated").unwrap(),
        how,
    };
    let golden = load_brdf("coated", &model);
    let ours = evaluate(&model, &golden.cases, DType::F64);
    let report = compare_brdf(&golden, &ours, &F64);
    eprintln!("{}", report.summary(&format!("perturbed coated ({how:?})")));
    report.failures
}

#[test]
fn coated_golden_bites_schlick_exponent_4() {
    let failures = perturbed_failures(Perturbation::SchlickExponent4);
    assert!(
        failures.iter().filter(|f| f.contains("f·cos θ_o")).count() > 100,
        "Schlick exponent 4 instead of 5 must fail the value comparison on most cases, got {} failures",
        failures.len()
    );
}

#[test]
fn coated_golden_bites_shared_roughness() {
    let failures = perturbed_failures(Perturbation::SharedRoughness);
    assert!(
        failures.iter().any(|f| f.contains("f·cos θ_o"))
            && failures.iter().any(|f| f.contains("/ d roughness2")),
        "a second lobe reading the first lobe's roughness must fail values and roughness2 gradients, got {} failures",
        failures.len()
    );
}
