//! `photomat brdf-eval`: evaluate a model at given directions and parameter values and print
//! JSON, so that users and external checks can script the models.
//!
//! Input (`--cases FILE.json`, or `-` for stdin):
//!
//! ```json
//! {"cases": [{"wi": [0, 0, 1], "wo": [0.6, 0, 0.8],
//!             "params": {"diffuse": [0.5, 0.5, 0.5], "roughness": 0.3}}]}
//! ```
//!
//! - `wi`, `wo`: directions in the material's frame (x right, y up, z out of the surface),
//!   normalised before use (they need not be unit length; zero vectors are an error).
//! - `params`: values per map of the model (`photomat brdfs` lists them); a 1-channel value may
//!   be a bare number. **Missing maps take the spec default** and every value used is echoed in
//!   the output. Values are used as given, without range checks, so that models can be probed
//!   at and beyond the ends of their ranges.
//!
//! Output (stdout), per case: `wi`, `wo` (normalised), `params` (all of them), `value` =
//! `f·cos θ_o` (rgb, what `DifferentiableBrdf::eval` returns), `f` = value / cos θ_o with
//! `cos θ_o = normalize(n)·wo` for the case's shading normal n (the `normal` map, the normal an
//! adapter derives, or +z for models without one), null where that cosine is ≤ 0; with
//! `--grad`, `grad[param][out_channel][param_channel]` = ∂value[out_channel] /
//! ∂param[param_channel] (null for maps the model marks non-differentiable).
//!
//! All cases are evaluated at once as independent texels: maps (N, C, 1, 1), directions
//! (N, 3, 1, 1). Cases lie along the batch axis rather than along a row, so that spatial
//! adapters (the height adapter's wrap-around differences) never mix neighbouring cases: a
//! lone texel has no slope, and `height(…)` sees a flat surface. Gradients use candle autodiff:
//! one backward pass per output channel of the sum over cases, which separates per case
//! because cases are independent. `--f64` evaluates in f64 (default f32).

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::PathBuf;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor, Var};
use photomat_core::{Brdf, MaterialMaps, ParamSpec, lookup};
use serde::{Deserialize, Serialize};

use crate::common::shortest;

/// Shortest direction accepted before normalising: a zero vector has no direction, and 1e-12
/// is far below any deliberately written component.
const MIN_DIRECTION_LENGTH: f64 = 1e-12;

/// Printed after `photomat brdf-eval --help`.
const CASES_HELP: &str = "\
Cases file (JSON):
  {\"cases\": [{\"wi\": [0, 0, 1], \"wo\": [0.6, 0, 0.8],
              \"params\": {\"diffuse\": [0.5, 0.5, 0.5], \"roughness\": 0.3}}]}
wi, wo: directions in the material's frame (z up), normalised before use.
params: per map of the model (see `photomat brdfs`); missing maps take the spec default.
Output per case: params used, value = f·cos θo (rgb), f (null where cos θo ≤ 0 w.r.t. the
case's shading normal) and, with --grad, grad[param][out_channel][param_channel].";

#[derive(Debug, clap::Args)]
#[command(after_help = CASES_HELP)]
pub struct Args {
    /// Model specification, e.g. ggx or height(ggx, scale=0.05).
    #[arg(long, value_name = "SPEC")]
    pub brdf: String,

    /// JSON file of cases ('-' reads stdin); schema below.
    #[arg(long, value_name = "FILE.json")]
    pub cases: PathBuf,

    /// Also print the Jacobian of every value w.r.t. every parameter.
    #[arg(long)]
    pub grad: bool,

    /// Evaluate in f64 instead of f32.
    #[arg(long = "f64")]
    pub double: bool,
}

/// The input file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CasesFile {
    pub cases: Vec<CaseIn>,
}

/// One input case.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaseIn {
    pub wi: Vec<f64>,
    pub wo: Vec<f64>,
    #[serde(default)]
    pub params: BTreeMap<String, Values>,
}

/// A parameter value: a list of channel values, or a bare number for 1-channel maps.
#[derive(Debug, Clone, PartialEq)]
pub struct Values(pub Vec<f64>);

impl<'de> Deserialize<'de> for Values {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Values;

            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number or a list of numbers")
            }

            fn visit_f64<E>(self, v: f64) -> Result<Values, E> {
                Ok(Values(vec![v]))
            }

            fn visit_i64<E>(self, v: i64) -> Result<Values, E> {
                Ok(Values(vec![v as f64]))
            }

            fn visit_u64<E>(self, v: u64) -> Result<Values, E> {
                Ok(Values(vec![v as f64]))
            }

            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Values, A::Error> {
                let mut values = Vec::new();
                while let Some(v) = seq.next_element::<f64>()? {
                    values.push(v);
                }
                Ok(Values(values))
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

/// The printed result.
#[derive(Debug, Serialize)]
pub struct Output {
    /// Canonical model specification.
    pub brdf: String,
    /// "f32" or "f64".
    pub dtype: &'static str,
    pub cases: Vec<CaseOut>,
}

/// One evaluated case.
#[derive(Debug, Serialize)]
pub struct CaseOut {
    pub wi: [f64; 3],
    pub wo: [f64; 3],
    pub params: BTreeMap<&'static str, Vec<f64>>,
    pub value: [f64; 3],
    pub f: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub grad: Option<BTreeMap<&'static str, Option<Vec<Vec<f64>>>>>,
}

/// A validated case.
struct Case {
    wi: [f64; 3],
    wo: [f64; 3],
    /// Per spec of the model, in spec order.
    params: Vec<Vec<f64>>,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let brdf = lookup(&args.brdf).context("invalid --brdf")?;
    let text = read_cases_text(&args.cases)?;
    let source = if args.cases.as_os_str() == "-" {
        "stdin".to_string()
    } else {
        args.cases.display().to_string()
    };
    let file: CasesFile =
        serde_json::from_str(&text).with_context(|| format!("{source}: not a valid cases file"))?;
    let dtype = if args.double { DType::F64 } else { DType::F32 };
    let output = evaluate(&brdf, &file.cases, dtype, args.grad)
        .with_context(|| format!("{source}: cannot evaluate the cases"))?;
    // Serialised first, so that write errors (a closed pipe) arrive as plain io errors.
    writeln!(out, "{}", serde_json::to_string_pretty(&output)?)?;
    Ok(())
}

fn read_cases_text(path: &PathBuf) -> anyhow::Result<String> {
    if path.as_os_str() == "-" {
        let mut text = String::new();
        std::io::stdin()
            .read_to_string(&mut text)
            .context("cannot read the cases from stdin")?;
        return Ok(text);
    }
    std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
}

/// Evaluate `cases` of `brdf` in `dtype`, with Jacobians if `grad`.
pub fn evaluate(brdf: &Brdf, cases: &[CaseIn], dtype: DType, grad: bool) -> anyhow::Result<Output> {
    if cases.is_empty() {
        bail!("the file has no cases (\"cases\": [] )");
    }
    let specs = brdf.params();
    let cases: Vec<Case> = cases
        .iter()
        .enumerate()
        .map(|(k, c)| validate(c, specs).with_context(|| format!("case {k}")))
        .collect::<anyhow::Result<_>>()?;
    let n = cases.len();
    let device = Device::Cpu;

    // (N, C, 1, 1) per map and (N, 3, 1, 1) per direction: case k is batch item k.
    let batch = |c: usize, value: &dyn Fn(&Case) -> &[f64]| -> anyhow::Result<Tensor> {
        let data: Vec<f64> = cases.iter().flat_map(|case| value(case).to_vec()).collect();
        Ok(Tensor::from_vec(data, (n, c, 1, 1), &device)?.to_dtype(dtype)?)
    };
    let wi = batch(3, &|c| &c.wi)?;
    let wo = batch(3, &|c| &c.wo)?;
    let mut vars = Vec::with_capacity(specs.len());
    let mut maps = MaterialMaps::new();
    for (i, spec) in specs.iter().enumerate() {
        let var = Var::from_tensor(&batch(spec.channels, &|c| &c.params[i])?)?;
        maps.insert(spec.name, var.as_tensor().clone());
        vars.push(var);
    }
    let value = brdf
        .eval(&wi, &wo, &maps)
        .with_context(|| format!("model '{}' failed to evaluate", brdf.name()))?;
    let values = per_case(&value, n)?;
    let cosines = shading_cosines(brdf, &maps, &cases)?;

    let mut grads: Vec<BTreeMap<&'static str, Option<Vec<Vec<f64>>>>> = vec![BTreeMap::new(); n];
    if grad {
        // by_output[o][i]: per-case rows of ∂(Σ_k value_k[o]) / ∂map_i, None for a map the
        // model never reads (its derivative is 0). Cases are independent, so row k is
        // ∂value_k[o] / ∂map_i of case k.
        let by_output = (0..3)
            .map(|o| -> anyhow::Result<Vec<Option<Vec<Vec<f64>>>>> {
                let store = value.narrow(1, o, 1)?.sum_all()?.backward()?;
                vars.iter()
                    .map(|var| {
                        store
                            .get(var.as_tensor())
                            .map(|g| per_case(g, n))
                            .transpose()
                    })
                    .collect()
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        for (i, spec) in specs.iter().enumerate() {
            for (k, g) in grads.iter_mut().enumerate() {
                let jacobian = spec.differentiable.then(|| {
                    by_output
                        .iter()
                        .map(|maps| match &maps[i] {
                            Some(rows) => rows[k].clone(),
                            None => vec![0.0; spec.channels],
                        })
                        .collect()
                });
                g.insert(spec.name, jacobian);
            }
        }
    }

    let out_cases = cases
        .iter()
        .zip(values)
        .zip(cosines)
        .zip(grads)
        .map(|(((case, v), cos), g)| {
            let value = [v[0], v[1], v[2]];
            CaseOut {
                wi: case.wi,
                wo: case.wo,
                params: specs
                    .iter()
                    .map(|s| s.name)
                    .zip(case.params.clone())
                    .collect(),
                value,
                f: (cos > 0.0).then(|| value.map(|x| x / cos)),
                grad: grad.then_some(g),
            }
        })
        .collect();
    Ok(Output {
        brdf: brdf.name(),
        dtype: if dtype == DType::F64 { "f64" } else { "f32" },
        cases: out_cases,
    })
}

/// Check one case against the model's specs and fill in defaults.
fn validate(case: &CaseIn, specs: &[ParamSpec]) -> anyhow::Result<Case> {
    let wi = direction("wi", &case.wi)?;
    let wo = direction("wo", &case.wo)?;
    if let Some(unknown) = case
        .params
        .keys()
        .find(|k| !specs.iter().any(|s| s.name == *k))
    {
        let valid: Vec<&str> = specs.iter().map(|s| s.name).collect();
        bail!(
            "unknown parameter '{unknown}' (valid: {})",
            valid.join(", ")
        );
    }
    let params = specs
        .iter()
        .map(|spec| {
            let values = match case.params.get(spec.name) {
                Some(v) => v.0.clone(),
                None => spec.default.iter().copied().map(shortest).collect(),
            };
            if values.len() != spec.channels {
                bail!(
                    "parameter '{}' has {} channel(s), got {} value(s)",
                    spec.name,
                    spec.channels,
                    values.len()
                );
            }
            if let Some(v) = values.iter().find(|v| !v.is_finite()) {
                bail!("parameter '{}' has a non-finite value {v}", spec.name);
            }
            let (lo, hi) = (spec.range.0 as f64, spec.range.1 as f64);
            if let Some(v) = values.iter().find(|v| !(lo..=hi).contains(*v)) {
                bail!(
                    "parameter '{}' has the value {v}, outside its range [{lo}, {hi}] \
                     (`photomat brdfs` lists every map's range)",
                    spec.name
                );
            }
            Ok(values)
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(Case { wi, wo, params })
}

/// A finite, non-zero 3-vector, normalised.
fn direction(name: &str, v: &[f64]) -> anyhow::Result<[f64; 3]> {
    let [x, y, z] = v else {
        bail!(
            "'{name}' must be a 3-vector [x, y, z], got {} component(s)",
            v.len()
        );
    };
    let len = (x * x + y * y + z * z).sqrt();
    if !len.is_finite() || len < MIN_DIRECTION_LENGTH {
        bail!("'{name}' = {v:?} is not a usable direction (zero or non-finite)");
    }
    Ok([x / len, y / len, z / len])
}

/// Rows of a (N, C, 1, 1) tensor as f64 vectors, one per case.
fn per_case(t: &Tensor, n: usize) -> anyhow::Result<Vec<Vec<f64>>> {
    let flat = t.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()?;
    let c = t.dims().get(1).copied().unwrap_or(0);
    if t.rank() != 4 || flat.len() != n * c || c == 0 {
        bail!("expected a ({n}, C, 1, 1) tensor, got shape {:?}", t.dims());
    }
    Ok(flat.chunks(c).map(<[f64]>::to_vec).collect())
}

/// `normalize(n)·wo` per case, with n the shading normal the innermost model sees.
fn shading_cosines(brdf: &Brdf, maps: &MaterialMaps, cases: &[Case]) -> anyhow::Result<Vec<f64>> {
    let detached = maps.map_tensors(|t| Ok(t.detach()))?;
    let shading = brdf.shading_maps(&detached)?;
    let normals = match shading.get("normal") {
        Ok(normal) => {
            let normal = normal
                .broadcast_as((cases.len(), 3, 1, 1))
                .with_context(|| {
                    format!(
                        "shading normal of shape {:?} does not fit the cases",
                        normal.dims()
                    )
                })?;
            per_case(&normal.contiguous()?, cases.len())?
        }
        Err(_) => vec![vec![0.0, 0.0, 1.0]; cases.len()],
    };
    Ok(normals
        .iter()
        .zip(cases)
        .map(|(n, case)| {
            let len = n.iter().map(|x| x * x).sum::<f64>().sqrt();
            if len == 0.0 {
                return 0.0; // a zero normal has no upper hemisphere: f is undefined
            }
            n.iter().zip(case.wo).map(|(a, b)| a * b).sum::<f64>() / len
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direction_normalises_and_rejects_bad_vectors() {
        assert_eq!(direction("wi", &[0.0, 0.0, 2.0]).unwrap(), [0.0, 0.0, 1.0]);
        assert!(
            direction("wi", &[0.0, 1.0])
                .unwrap_err()
                .to_string()
                .contains("3-vector")
        );
        assert!(direction("wo", &[0.0, 0.0, 0.0]).is_err());
        assert!(direction("wo", &[f64::NAN, 0.0, 1.0]).is_err());
    }
}
