//! The plugin registry: models register a const [`BrdfRegistration`] with
//! [`register_brdf!`](crate::register_brdf) and are built **by name** with [`lookup`].
//!
//! Follows inventory's real users (typetag, yara-x; `shared/STYLE.md`): records are const,
//! the macro expands through `$crate` so plugin crates never name `inventory`, listings are
//! sorted, duplicate names are an error, and an unknown name lists the known ones.
//!
//! Linking pitfall: a crate that depends on a plugin crate but never names it in code sees
//! none of its plugins. Binaries and tests that use plugins write `use photomat_brdfs as _;`.

use crate::brdf::Brdf;
use crate::param::ParamSpec;
use crate::plugin_spec::PluginSpec;
use crate::{Error, Result};
use std::collections::BTreeMap;

/// A scalar construction argument of a model (Mitsuba's plugin properties), e.g. `scale`.
/// Arguments are not maps: they are fixed per model instance and never differentiated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArgSpec {
    pub name: &'static str,
    pub default: f64,
    /// Inclusive valid range.
    pub range: (f64, f64),
    pub doc: &'static str,
}

/// The const record a plugin submits.
pub struct BrdfRegistration {
    /// Registered name: the file stem of the plugin's source file.
    pub name: &'static str,
    /// One line for `photomat brdfs`.
    pub summary: &'static str,
    /// For models: every parameter map. For adapters: the maps the adapter adds.
    pub params: &'static [ParamSpec],
    /// For adapters: the nested model's maps it replaces (empty for models).
    pub replaces: &'static [&'static str],
    /// Whether the model wraps exactly one nested model (an adapter).
    pub takes_nested: bool,
    /// Scalar construction arguments.
    pub args: &'static [ArgSpec],
    /// Builds an instance from validated arguments.
    pub construct: fn(&BrdfArgs) -> Result<Brdf>,
}

/// Validated construction arguments handed to a plugin's constructor.
pub struct BrdfArgs {
    canonical: String,
    nested: Option<Brdf>,
    values: BTreeMap<&'static str, f64>,
}

impl BrdfArgs {
    /// Canonical specification of the instance being built (what its `name()` returns).
    pub fn canonical_name(&self) -> &str {
        &self.canonical
    }

    /// The nested model (adapters only; the registry guarantees presence when
    /// `takes_nested` is set).
    pub fn nested(&self) -> Result<Brdf> {
        self.nested
            .clone()
            .ok_or_else(|| Error::Invalid(format!("'{}' needs a nested model", self.canonical)))
    }

    /// A scalar argument's value (given or default).
    pub fn value(&self, name: &str) -> Result<f64> {
        self.values
            .get(name)
            .copied()
            .ok_or_else(|| Error::Invalid(format!("'{}' has no argument '{name}'", self.canonical)))
    }
}

inventory::collect!(BrdfRegistration);

/// Register a model or adapter. Expands through `$crate`, so plugin crates depend on
/// `photomat-core` only:
///
/// ```ignore
/// photomat_core::register_brdf!(BrdfRegistration { name: "lambert", /* … */ });
/// ```
#[macro_export]
macro_rules! register_brdf {
    ($registration:expr $(,)?) => {
        $crate::__private::inventory::submit! { $registration }
    };
}

/// Every registration, sorted by name; an error if a name is registered twice.
pub fn registrations() -> Result<Vec<&'static BrdfRegistration>> {
    sorted_unique(inventory::iter::<BrdfRegistration>.into_iter().collect())
}

/// Sorted registered names (the registry guard tests compare this list).
pub fn registered_names() -> Result<Vec<&'static str>> {
    Ok(registrations()?.into_iter().map(|r| r.name).collect())
}

/// Sort by name and reject duplicates.
pub fn sorted_unique(mut regs: Vec<&BrdfRegistration>) -> Result<Vec<&BrdfRegistration>> {
    regs.sort_by_key(|r| r.name);
    if let Some(pair) = regs.windows(2).find(|p| p[0].name == p[1].name) {
        return Err(Error::DuplicateBrdf(pair[0].name.to_string()));
    }
    Ok(regs)
}

/// Build a model from a specification string such as `ggx` or `height(ggx, scale=0.02)`.
pub fn lookup(spec: &str) -> Result<Brdf> {
    build(&PluginSpec::parse(spec)?, spec)
}

fn build(spec: &PluginSpec, full_text: &str) -> Result<Brdf> {
    let regs = registrations()?;
    let reg = regs
        .iter()
        .find(|r| r.name == spec.name)
        .ok_or_else(|| Error::UnknownBrdf {
            name: spec.name.clone(),
            known: regs.iter().map(|r| r.name.to_string()).collect(),
        })?;
    let bad = |reason: String| Error::BadSpec {
        spec: full_text.to_string(),
        reason,
    };
    let nested = match (reg.takes_nested, spec.nested.as_slice()) {
        (true, [inner]) => Some(build(inner, full_text)?),
        (true, _) => {
            return Err(bad(format!(
                "'{}' wraps exactly one nested model, e.g. {}(ggx)",
                reg.name, reg.name
            )));
        }
        (false, []) => None,
        (false, _) => return Err(bad(format!("'{}' takes no nested model", reg.name))),
    };
    let mut values = BTreeMap::new();
    for (key, value) in &spec.values {
        let arg = reg.args.iter().find(|a| a.name == key).ok_or_else(|| {
            let valid: Vec<_> = reg.args.iter().map(|a| a.name).collect();
            bad(format!(
                "'{}' has no argument '{key}' (valid: {})",
                reg.name,
                if valid.is_empty() {
                    "none".to_string()
                } else {
                    valid.join(", ")
                }
            ))
        })?;
        if !(arg.range.0..=arg.range.1).contains(value) {
            return Err(bad(format!(
                "argument {key}={value} of '{}' is outside [{}, {}]",
                reg.name, arg.range.0, arg.range.1
            )));
        }
        values.insert(arg.name, *value);
    }
    for arg in reg.args {
        values.entry(arg.name).or_insert(arg.default);
    }
    let canonical = PluginSpec {
        name: reg.name.to_string(),
        nested: nested
            .iter()
            .map(|n| PluginSpec::parse(&n.name()))
            .collect::<Result<_>>()?,
        values: reg
            .args
            .iter()
            .map(|a| (a.name.to_string(), values[a.name]))
            .collect(),
    }
    .to_string();
    let args = BrdfArgs {
        canonical,
        nested,
        values,
    };
    (reg.construct)(&args)
}
