//! Registry guard and lookup errors: the built-in plugins are linked into test binaries
//! (the linking pitfall of `photomat_core::registry`), names are unique, sorted and equal to
//! their files' stems, and bad names or specifications fail with messages a user can act on.

use photomat_core::registry::sorted_unique;
use photomat_core::{
    BrdfArgs, BrdfRegistration, Error, Result, lookup, registered_names, registrations,
};
use photomat_tests::{expected_builtins, model};

#[test]
fn registry_lists_exactly_the_builtins_sorted() {
    // One plugin per file of brdf-plugins/src: the guard adapts to a new file by itself.
    let expected = expected_builtins();
    assert!(expected.contains(&"ggx".to_string()), "{expected:?}");
    assert_eq!(registered_names().unwrap(), expected);
    assert_eq!(photomat_tests::brdfs::builtin_names().unwrap(), expected);
}

#[test]
fn registry_file_stem_equals_registered_name() {
    // Every crate linked into this binary: the built-ins and nothing else.
    for r in registrations().unwrap() {
        photomat_core::testing::check_file_stems(r.crate_name()).unwrap();
    }
}

#[test]
fn registry_innermost_is_the_shading_model() {
    for (spec, inner) in [
        ("ggx", "ggx"),
        ("height(ggx)", "ggx"),
        ("height(lambert, scale=0.5)", "lambert"),
    ] {
        assert_eq!(model(spec).innermost().name(), inner, "{spec}");
    }
    let plain = model("coated");
    assert!(std::sync::Arc::ptr_eq(&plain.innermost(), &plain));
}

#[test]
fn registry_unknown_name_lists_known_names() {
    let err = lookup("gxx")
        .err()
        .expect("unknown name must fail")
        .to_string();
    assert!(err.contains("'gxx'"), "{err}");
    let known = expected_builtins().join(", ");
    assert!(err.contains(&known), "{err}");
    // Unknown names nested inside an adapter are reported the same way.
    let err = lookup("height(blinn)").err().unwrap().to_string();
    assert!(err.contains("'blinn'") && err.contains(&known), "{err}");
}

fn never_built(_: &BrdfArgs) -> Result<photomat_core::Brdf> {
    unreachable!("only the duplicate check runs")
}

const fn registration(name: &'static str) -> BrdfRegistration {
    BrdfRegistration {
        name,
        summary: "",
        params: &[],
        replaces: &[],
        takes_nested: false,
        args: &[],
        construct: never_built,
        file: file!(),
        module: module_path!(),
    }
}

#[test]
fn registry_duplicate_names_are_an_error() {
    static A: BrdfRegistration = registration("ggx");
    static B: BrdfRegistration = registration("lambert");
    static C: BrdfRegistration = registration("ggx");
    let err = sorted_unique(vec![&A, &B, &C])
        .err()
        .expect("duplicates must fail");
    assert!(
        matches!(&err, Error::DuplicateBrdf(n) if n == "ggx"),
        "{err}"
    );
    let ok = sorted_unique(vec![&B, &A]).unwrap();
    assert_eq!(
        ok.iter().map(|r| r.name).collect::<Vec<_>>(),
        ["ggx", "lambert"]
    );
}

#[test]
fn registry_channel_counts_follow_the_param_specs() {
    for (spec, n) in [
        ("lambert", 6),
        ("ggx", 10),
        ("coated", 11),
        ("height(ggx)", 8),
        ("height(lambert)", 4),
    ] {
        assert_eq!(model(spec).channels(), n, "{spec}");
    }
    let names: Vec<_> = model("height(ggx)")
        .params()
        .iter()
        .map(|p| p.name)
        .collect();
    assert_eq!(names, ["diffuse", "specular", "roughness", "height"]);
}

#[test]
fn registry_canonical_names_round_trip() {
    for spec in [
        "ggx",
        "height(ggx)",
        "height( ggx , scale = 0.1 )",
        "height(lambert, scale=0.5)",
    ] {
        let canonical = model(spec).name();
        assert_eq!(model(&canonical).name(), canonical, "{spec}");
    }
    assert_eq!(model("height(ggx)").name(), "height(ggx, scale=0.02)");
}

#[test]
fn registry_choice_arguments_are_named_only_when_not_default() {
    // Names written before `ggx` had choices (estimator.json, material.json) keep naming the
    // default model, and a variant's name rebuilds the variant.
    assert_eq!(
        model("ggx(shadowing=separable, fresnel=schlick)").name(),
        "ggx"
    );
    assert_eq!(
        model("ggx(fresnel=constant, shadowing=correlated)").name(),
        "ggx(shadowing=correlated, fresnel=constant)"
    );
    assert_eq!(
        model("height(ggx(shadowing=implicit))").name(),
        "height(ggx(shadowing=implicit), scale=0.02)"
    );
    for spec in ["ggx(shadowing=correlated)", "height(ggx(fresnel=constant))"] {
        let canonical = model(spec).name();
        assert_eq!(model(&canonical).name(), canonical, "{spec}");
    }
}

#[test]
fn registry_bad_specifications_explain_themselves() {
    let cases = [
        ("height", "wraps exactly one nested model"),
        ("ggx(lambert)", "takes no nested model"),
        ("height(ggx, depth=2)", "no argument 'depth' (valid: scale)"),
        ("lambert(scale=1)", "no argument 'scale' (valid: none)"),
        (
            "ggx(scale=1)",
            "no argument 'scale' (valid: shadowing, fresnel)",
        ),
        (
            "ggx(shadowing=smith)",
            "shadowing=smith is not one of: separable, correlated, implicit",
        ),
        (
            "ggx(fresnel=1)",
            "fresnel=1 is not one of: schlick, constant",
        ),
        ("height(ggx, scale=wide)", "scale=wide must be a number"),
        ("height(ggx, scale=5)", "outside [0, 1]"),
        ("height(coated)", "has no 'normal' map to replace"),
        ("height(height(ggx))", "has no 'normal' map to replace"),
        ("height(ggx", "expected ',' or ')'"),
    ];
    for (spec, needle) in cases {
        let err = lookup(spec)
            .err()
            .unwrap_or_else(|| panic!("{spec} must fail"))
            .to_string();
        assert!(err.contains(needle), "{spec}: {err}");
    }
}
