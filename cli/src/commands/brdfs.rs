//! `photomat brdfs [--json]`: every registered model, sorted by name, with its summary, its
//! scalar arguments, its parameter table and its channel count n (the estimator's output
//! width). Adapters list the maps they add and replace, and the n of an example instance
//! built by name (e.g. `height(ggx)`: n = 8).

use std::io::Write;

use anyhow::Context;
use photomat_core::param::total_channels;
use photomat_core::{
    ArgKind, ArgValue, BrdfRegistration, ColorSpace, Encoding, ParamSpec, lookup, registrations,
};
use serde::Serialize;

use crate::common::shortest;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Print machine-readable JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

/// The `--json` document.
#[derive(Debug, Serialize)]
struct Listing<'a> {
    models: &'a [ModelInfo],
}

/// One model of the listing (also the JSON schema of `--json`).
#[derive(Debug, Serialize)]
pub struct ModelInfo {
    pub name: &'static str,
    pub summary: &'static str,
    /// Whether the model wraps a nested model (`height(ggx)`).
    pub adapter: bool,
    /// For adapters: the nested model's maps it replaces.
    pub replaces: Vec<&'static str>,
    pub args: Vec<ArgInfo>,
    /// For models: every map; for adapters: the maps the adapter adds.
    pub params: Vec<ParamInfo>,
    /// n, the total channel count; null for adapters (see `example`).
    pub channels: Option<usize>,
    /// For adapters: an instance wrapping a registered model, built by name.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub example: Option<ExampleInfo>,
}

/// A scalar construction argument.
#[derive(Debug, Serialize)]
pub struct ArgInfo {
    pub name: &'static str,
    pub default: ArgValue,
    /// Numeric arguments: the inclusive valid range.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
    /// Choice arguments: the words accepted, the default first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub choices: Option<Vec<&'static str>>,
    pub doc: &'static str,
}

/// One parameter map.
#[derive(Debug, Serialize)]
pub struct ParamInfo {
    pub name: &'static str,
    pub channels: usize,
    pub range: [f64; 2],
    pub encoding: &'static str,
    pub color_space: ColorSpace,
    pub default: Vec<f64>,
    pub differentiable: bool,
    pub doc: &'static str,
}

/// An adapter instance such as `height(ggx)`.
#[derive(Debug, Serialize)]
pub struct ExampleInfo {
    pub spec: String,
    /// n of the instance (null if it could not be built).
    pub channels: Option<usize>,
    /// The instance's maps in channel order.
    pub params: Vec<&'static str>,
    /// Why the instance could not be built, if it could not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let models = list_models()?;
    if args.json {
        // Serialised first, so that write errors (a closed pipe) arrive as plain io errors.
        let json = serde_json::to_string_pretty(&Listing { models: &models })?;
        writeln!(out, "{json}")?;
    } else {
        write!(out, "{}", format_text(&models))?;
    }
    Ok(())
}

/// Every registered model, sorted by name.
pub fn list_models() -> anyhow::Result<Vec<ModelInfo>> {
    let regs = registrations().context("cannot list the BRDF registry")?;
    Ok(regs.iter().map(|reg| describe(reg, &regs)).collect())
}

fn describe(reg: &BrdfRegistration, all: &[&'static BrdfRegistration]) -> ModelInfo {
    ModelInfo {
        name: reg.name,
        summary: reg.summary,
        adapter: reg.takes_nested,
        replaces: reg.replaces.to_vec(),
        args: reg
            .args
            .iter()
            .map(|a| ArgInfo {
                name: a.name,
                default: a.default_value(),
                range: match a.kind {
                    ArgKind::Number { range, .. } => Some([range.0, range.1]),
                    ArgKind::Choice { .. } => None,
                },
                choices: match a.kind {
                    ArgKind::Choice { words } => Some(words.to_vec()),
                    ArgKind::Number { .. } => None,
                },
                doc: a.doc,
            })
            .collect(),
        params: reg.params.iter().map(param_info).collect(),
        channels: (!reg.takes_nested).then(|| total_channels(reg.params)),
        example: reg.takes_nested.then(|| example(reg, all)),
    }
}

fn param_info(spec: &ParamSpec) -> ParamInfo {
    ParamInfo {
        name: spec.name,
        channels: spec.channels,
        range: [shortest(spec.range.0), shortest(spec.range.1)],
        encoding: encoding_name(spec.encoding),
        color_space: spec.color_space,
        default: spec.default.iter().copied().map(shortest).collect(),
        differentiable: spec.differentiable,
        doc: spec.doc,
    }
}

fn encoding_name(encoding: Encoding) -> &'static str {
    match encoding {
        Encoding::Linear => "linear",
        Encoding::Gamma22 => "gamma2.2",
        Encoding::UnitNormal => "unit-normal",
    }
}

/// Build the adapter around `ggx` when it qualifies (the paper's configuration), else around
/// the first registered plain model that has every map the adapter replaces.
fn example(adapter: &BrdfRegistration, all: &[&'static BrdfRegistration]) -> ExampleInfo {
    let fits = |r: &&&BrdfRegistration| {
        !r.takes_nested
            && adapter
                .replaces
                .iter()
                .all(|m| r.params.iter().any(|p| p.name == *m))
    };
    let nested = all
        .iter()
        .filter(fits)
        .find(|r| r.name == "ggx")
        .or_else(|| all.iter().find(fits));
    let Some(nested) = nested else {
        return ExampleInfo {
            spec: format!("{}(MODEL)", adapter.name),
            channels: None,
            params: Vec::new(),
            error: Some(format!(
                "no registered model has the maps it replaces ({})",
                adapter.replaces.join(", ")
            )),
        };
    };
    let spec = format!("{}({})", adapter.name, nested.name);
    match lookup(&spec) {
        Ok(model) => ExampleInfo {
            channels: Some(model.channels()),
            params: model.params().iter().map(|p| p.name).collect(),
            spec,
            error: None,
        },
        Err(e) => ExampleInfo {
            spec,
            channels: None,
            params: Vec::new(),
            error: Some(e.to_string()),
        },
    }
}

/// Human-readable listing: a header line per model, then its argument and map tables.
pub fn format_text(models: &[ModelInfo]) -> String {
    let mut text = String::new();
    for (i, m) in models.iter().enumerate() {
        if i > 0 {
            text.push('\n');
        }
        let n = match (&m.channels, &m.example) {
            (Some(n), _) => format!("n = {n}"),
            (
                None,
                Some(ExampleInfo {
                    spec,
                    channels: Some(n),
                    ..
                }),
            ) => {
                format!("adapter; {spec}: n = {n}")
            }
            (
                None,
                Some(ExampleInfo {
                    spec,
                    error: Some(e),
                    ..
                }),
            ) => {
                format!("adapter; {spec}: {e}")
            }
            _ => "adapter".to_string(),
        };
        text.push_str(&format!("{}  ({n})\n  {}\n", m.name, m.summary));
        if !m.replaces.is_empty() {
            text.push_str(&format!(
                "  replaces the nested model's: {}\n",
                m.replaces.join(", ")
            ));
        }
        if let Some(ExampleInfo { spec, params, .. }) =
            m.example.as_ref().filter(|e| !e.params.is_empty())
        {
            text.push_str(&format!("  {spec} maps: {}\n", params.join(", ")));
        }
        if !m.args.is_empty() {
            let mut rows = vec![row(["argument", "default", "values", "description"])];
            rows.extend(m.args.iter().map(|a| {
                let values = match (&a.range, &a.choices) {
                    (Some(range), _) => format!("[{}, {}]", range[0], range[1]),
                    (None, Some(words)) => words.join(" | "),
                    (None, None) => String::new(),
                };
                row([a.name, &a.default.to_string(), &values, a.doc])
            }));
            text.push_str(&table(&rows));
        }
        let mut rows = vec![row([
            if m.adapter { "adds" } else { "map" },
            "ch",
            "range",
            "encoding",
            "default",
            "grad",
            "description",
        ])];
        rows.extend(m.params.iter().map(|p| {
            let default: Vec<String> = p.default.iter().map(|v| v.to_string()).collect();
            row([
                p.name,
                &p.channels.to_string(),
                &format!("[{}, {}]", p.range[0], p.range[1]),
                p.encoding,
                &default.join(" "),
                if p.differentiable { "yes" } else { "no" },
                p.doc,
            ])
        }));
        text.push_str(&table(&rows));
    }
    text
}

fn row<const N: usize>(cells: [&str; N]) -> Vec<String> {
    cells.iter().map(|c| c.to_string()).collect()
}

/// Left-aligned columns, two spaces apart, indented by two; the last column is not padded.
fn table(rows: &[Vec<String>]) -> String {
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0);
    let widths: Vec<usize> = (0..columns)
        .map(|c| {
            rows.iter()
                .filter_map(|r| r.get(c))
                .map(|s| s.chars().count())
                .max()
                .unwrap_or(0)
        })
        .collect();
    let mut text = String::new();
    for r in rows {
        let mut line = String::from("  ");
        for (c, cell) in r.iter().enumerate() {
            line.push_str(cell);
            if c + 1 < r.len() {
                line.push_str(&" ".repeat(widths[c] - cell.chars().count() + 2));
            }
        }
        text.push_str(line.trim_end());
        text.push('\n');
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_aligns_columns() {
        let text = table(&[row(["a", "bb", "c"]), row(["ccc", "d", "e"])]);
        assert_eq!(text, "  a    bb  c\n  ccc  d   e\n");
    }
}
