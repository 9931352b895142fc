//! The plugin registry: each plugin declares itself once with
//! [`register_brdf!`](crate::register_brdf), which submits a const [`BrdfRegistration`], and
//! models are built **by name** with [`lookup`].
//!
//! Follows inventory's real users (typetag, yara-x): records are const, the macro expands
//! through `$crate` so plugin crates never name `inventory`, listings are sorted, duplicate
//! names are an error, and an unknown name lists the known ones. Each record also notes the
//! source file and module that registered it, so tests can check Mitsuba's layout rule
//! "file stem = registered name" and a plugin crate can list its own models
//! ([`registrations_from`]).
//!
//! Linking pitfall: a crate that depends on a plugin crate but never names it in code sees
//! none of its plugins. Binaries and tests that use plugins write `use photomat_brdfs as _;`.

use crate::brdf::Brdf;
use crate::param::ParamSpec;
use crate::plugin_spec::{ArgValue, PluginSpec};
use crate::{Error, Result};
use std::collections::BTreeMap;

/// A construction argument of a model (Mitsuba's plugin properties): a number such as the
/// height adapter's `scale`, or a choice among words such as `ggx`'s `shadowing`. Arguments are
/// not maps: they are fixed per model instance and never differentiated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArgSpec {
    pub name: &'static str,
    pub kind: ArgKind,
    pub doc: &'static str,
}

/// What values an argument takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArgKind {
    /// A finite number in an inclusive range.
    Number { default: f64, range: (f64, f64) },
    /// One of these words; the first is the default. A choice at its default is left out of
    /// the canonical specification, so that names written before the choice existed (in
    /// estimator.json and material.json) keep naming the same model.
    Choice { words: &'static [&'static str] },
}

impl ArgSpec {
    /// A numeric argument.
    pub const fn number(
        name: &'static str,
        default: f64,
        range: (f64, f64),
        doc: &'static str,
    ) -> Self {
        ArgSpec {
            name,
            kind: ArgKind::Number { default, range },
            doc,
        }
    }

    /// A choice argument; `words[0]` is the default.
    pub const fn choice(
        name: &'static str,
        words: &'static [&'static str],
        doc: &'static str,
    ) -> Self {
        ArgSpec {
            name,
            kind: ArgKind::Choice { words },
            doc,
        }
    }

    /// The value used when a specification does not give one.
    pub fn default_value(&self) -> ArgValue {
        match self.kind {
            ArgKind::Number { default, .. } => ArgValue::Number(default),
            ArgKind::Choice { words } => ArgValue::Word(words[0].to_string()),
        }
    }

    /// `value` checked against this argument: a number in range or one of the words.
    fn check(&self, value: &ArgValue) -> std::result::Result<(), String> {
        match (self.kind, value) {
            (ArgKind::Number { range, .. }, ArgValue::Number(v)) => {
                if (range.0..=range.1).contains(v) {
                    Ok(())
                } else {
                    Err(format!(
                        "argument {}={v} is outside [{}, {}]",
                        self.name, range.0, range.1
                    ))
                }
            }
            (ArgKind::Choice { words }, ArgValue::Word(w)) if words.contains(&w.as_str()) => Ok(()),
            (ArgKind::Choice { words }, value) => Err(format!(
                "argument {}={value} is not one of: {}",
                self.name,
                words.join(", ")
            )),
            (ArgKind::Number { .. }, ArgValue::Word(w)) => {
                Err(format!("argument {}={w} must be a number", self.name))
            }
        }
    }
}

/// The const record a plugin submits (written by [`register_brdf!`](crate::register_brdf)).
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
    /// Construction arguments (numbers and choices).
    pub args: &'static [ArgSpec],
    /// Builds an instance from validated arguments.
    pub construct: fn(&BrdfArgs) -> Result<Brdf>,
    /// `file!()` of the registration: the plugin's source file.
    pub file: &'static str,
    /// `module_path!()` of the registration; its first segment is the registering crate.
    pub module: &'static str,
}

impl BrdfRegistration {
    /// Stem of [`Self::file`] (`ggx` for `brdf-plugins/src/ggx.rs`), which must equal the
    /// registered name; `None` if the path has no UTF-8 stem.
    pub fn file_stem(&self) -> Option<&'static str> {
        std::path::Path::new(self.file)
            .file_stem()
            .and_then(|s| s.to_str())
    }

    /// The crate that registered the plugin (`photomat_brdfs` for the built-ins).
    pub fn crate_name(&self) -> &'static str {
        self.module.split("::").next().unwrap_or(self.module)
    }
}

/// Validated construction arguments handed to a plugin's constructor.
pub struct BrdfArgs {
    registration: &'static BrdfRegistration,
    canonical: String,
    nested: Option<Brdf>,
    values: BTreeMap<&'static str, ArgValue>,
}

impl BrdfArgs {
    /// The registration of the plugin being built (its maps, replaced maps, arguments).
    pub fn registration(&self) -> &'static BrdfRegistration {
        self.registration
    }

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

    /// A numeric argument's value (given or default).
    pub fn value(&self, name: &str) -> Result<f64> {
        match self.values.get(name) {
            Some(ArgValue::Number(v)) => Ok(*v),
            _ => Err(Error::Invalid(format!(
                "'{}' has no numeric argument '{name}'",
                self.canonical
            ))),
        }
    }

    /// A choice argument's word (given or default), as the registration spells it.
    pub fn choice(&self, name: &str) -> Result<&'static str> {
        let words = self.registration.args.iter().find_map(|a| match a.kind {
            ArgKind::Choice { words } if a.name == name => Some(words),
            _ => None,
        });
        match (words, self.values.get(name)) {
            (Some(words), Some(ArgValue::Word(w))) => {
                words.iter().copied().find(|x| x == w).ok_or_else(|| {
                    Error::Invalid(format!("'{}': {name}={w} is no choice", self.canonical))
                })
            }
            _ => Err(Error::Invalid(format!(
                "'{}' has no choice argument '{name}'",
                self.canonical
            ))),
        }
    }
}

inventory::collect!(BrdfRegistration);

/// Declare a model or an adapter, once: its name, summary, maps and arguments go into the
/// registry record, and the registry builds instances that carry them, so a plugin writes
/// only its maths. Expands through `$crate`, so plugin crates depend on `photomat-core` only.
///
/// A model gives its parameter maps and a constructor of its [`Reflectance`]; the instance is
/// a [`ModelBrdf`] named by its canonical specification:
///
/// ```ignore
/// use photomat_core::param::common::{DIFFUSE, NORMAL};
/// photomat_core::register_brdf! {
///     name: "lambert",            // = the file stem: src/lambert.rs
///     summary: "ideal diffuse reflector ρ/π",
///     params: &[DIFFUSE, NORMAL],
///     model: |_args| Ok(Lambert), // Lambert: Reflectance
/// }
/// ```
///
/// An adapter gives the maps it adds and the nested model's maps it replaces, and a
/// constructor of its [`MapAdapter`]; the instance is an [`AdaptedBrdf`]:
///
/// ```ignore
/// photomat_core::register_brdf! {
///     name: "height",
///     summary: "nested model's normal map from a height map",
///     adds: &[HEIGHT],
///     replaces: &["normal"],
///     args: &[ArgSpec::number("scale", 0.02, (0.0, 1.0), "…")],
///     adapter: |args| Ok(HeightToNormal { scale: args.value("scale")? }),
/// }
/// ```
///
/// `args` (construction arguments: numbers read with [`BrdfArgs::value`], choices with
/// [`BrdfArgs::choice`]) is optional in both.
///
/// [`Reflectance`]: crate::model::Reflectance
/// [`ModelBrdf`]: crate::model::ModelBrdf
/// [`MapAdapter`]: crate::adapter::MapAdapter
/// [`AdaptedBrdf`]: crate::adapter::AdaptedBrdf
#[macro_export]
macro_rules! register_brdf {
    (@args) => { &[] };
    (@args $args:expr) => { $args };
    (@submit $name:expr, $summary:expr, $params:expr, $replaces:expr, $nested:expr,
     $args:expr, $construct:ident) => {
        $crate::__private::inventory::submit! {
            $crate::registry::BrdfRegistration {
                name: $name,
                summary: $summary,
                params: $params,
                replaces: $replaces,
                takes_nested: $nested,
                args: $args,
                construct: $construct,
                file: ::core::file!(),
                module: ::core::module_path!(),
            }
        }
    };
    (
        name: $name:expr,
        summary: $summary:expr,
        params: $params:expr,
        $(args: $args:expr,)?
        model: $model:expr $(,)?
    ) => {
        const _: () = {
            fn construct(
                args: &$crate::registry::BrdfArgs,
            ) -> $crate::Result<$crate::brdf::Brdf> {
                let reflectance: fn(&$crate::registry::BrdfArgs) -> $crate::Result<_> = $model;
                Ok(::std::sync::Arc::new($crate::model::ModelBrdf::new(
                    args,
                    reflectance(args)?,
                )))
            }
            $crate::register_brdf!(@submit $name, $summary, $params, &[], false,
                $crate::register_brdf!(@args $($args)?), construct);
        };
    };
    (
        name: $name:expr,
        summary: $summary:expr,
        adds: $adds:expr,
        replaces: $replaces:expr,
        $(args: $args:expr,)?
        adapter: $adapter:expr $(,)?
    ) => {
        const _: () = {
            fn construct(
                args: &$crate::registry::BrdfArgs,
            ) -> $crate::Result<$crate::brdf::Brdf> {
                let adapter: fn(&$crate::registry::BrdfArgs) -> $crate::Result<_> = $adapter;
                Ok(::std::sync::Arc::new($crate::adapter::AdaptedBrdf::new(
                    args,
                    adapter(args)?,
                )?))
            }
            $crate::register_brdf!(@submit $name, $summary, $adds, $replaces, true,
                $crate::register_brdf!(@args $($args)?), construct);
        };
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

/// The registrations made by crate `crate_name` (as `module_path!()` spells it, e.g.
/// `photomat_brdfs`), sorted by name: how a plugin crate lists its own models.
pub fn registrations_from(crate_name: &str) -> Result<Vec<&'static BrdfRegistration>> {
    Ok(registrations()?
        .into_iter()
        .filter(|r| r.crate_name() == crate_name)
        .collect())
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
        arg.check(value)
            .map_err(|reason| bad(format!("'{}': {reason}", reg.name)))?;
        values.insert(arg.name, value.clone());
    }
    for arg in reg.args {
        values
            .entry(arg.name)
            .or_insert_with(|| arg.default_value());
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
            .filter(|a| {
                // A choice at its default is left out (see `ArgKind::Choice`).
                !matches!(a.kind, ArgKind::Choice { .. }) || values[a.name] != a.default_value()
            })
            .map(|a| (a.name.to_string(), values[a.name].clone()))
            .collect(),
    }
    .to_string();
    let args = BrdfArgs {
        registration: reg,
        canonical,
        nested,
        values,
    };
    (reg.construct)(&args)
}
