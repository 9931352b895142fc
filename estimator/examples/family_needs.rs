//! Which BRDF model each simulated family needs (`--brdf auto`'s question, asked of the
//! simulator's own materials): for one material per family of a `photomat simulate` folder,
//! each candidate model's maps are fitted by direct optimisation through the differentiable
//! renderer to the ground-truth material's renders under the reference's five flash
//! positions, then judged under four held-out ones. The choice is `--brdf auto`'s rule
//! ([`photomat_estimator::sample::choice::choose`]): the cheapest model (fewest map channels)
//! whose held-out error is within the tolerance of the best one's.
//!
//! ```text
//! cargo run --release -p photomat-estimator --example family_needs -- SIM [SIZE] [STEPS] [SPECS] [TOLERANCE]
//! ```
//! SIM: a `photomat simulate` folder (truth/, simulation.json). Defaults: 128, 400,
//! `lambert,height(ggx),ggx,coated`, 0.1.
//!
//! The ground truth is rendered at its own resolution and box-filtered to SIZE (as `prepare`
//! shrinks photos); the fits are made at SIZE. The error is the L1 of linear radiance over the
//! held-out lights relative to the truth's mean radiance there; the fit minimises the L1 of
//! display-encoded images (what photos store) over the five reference lights. Several lights
//! separate what one photo cannot (a highlight painted into the diffuse map fits one photo,
//! not five), so this measures what a model can express of a family, not what a single photo
//! can tell.

use std::path::PathBuf;

use anyhow::Context;
use candle_core::{DType, Device, Tensor, Var};
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::map_files::load_maps;
use photomat_core::render::render_radiance_with;
use photomat_core::{Brdf, FlashGeometry, LightSet, SplitMix64, encode_display, lookup};
use photomat_estimator::sample::choice::{Candidate, choose};
use photomat_train::{Adam, AdamConfig};

/// Held-out lights beside the reference five, drawn as `photomat trade` draws its own.
const HELD_OUT: usize = 4;

fn scalar(t: &Tensor) -> anyhow::Result<f64> {
    Ok(t.to_dtype(DType::F64)?.to_scalar::<f64>()?)
}

/// Maps of `brdf` fitted to `target` (display-encoded renders under `geometry`'s lights) by
/// `steps` Adam steps from raw maps of 0.
///
/// # Shapes
/// target (L, 3, N, N) → maps (1, C, N, N).
fn fit(
    brdf: &Brdf,
    target: &Tensor,
    geometry: &FlashGeometry,
    steps: usize,
) -> anyhow::Result<photomat_core::MaterialMaps> {
    let (_, _, n, _) = target.dims4()?;
    let texel = Some(PHOTO_SIDE / n as f64);
    let raw = Var::zeros((1, brdf.channels(), n, n), DType::F32, target.device())?;
    // capture's step size: raw maps decode through tanh-like maps, so 0.05 moves a map by a
    // few % of its range.
    let mut adam = Adam::new(
        vec![("raw".into(), raw.clone())],
        AdamConfig {
            lr: 0.05,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
    )?;
    for _ in 0..steps {
        let maps = brdf.decode(raw.as_tensor())?.with_texel_size(texel);
        let rendered = encode_display(&render_radiance_with(brdf.as_ref(), &maps, geometry)?)?;
        let loss = (rendered - target)?.abs()?.mean_all()?;
        adam.step(&loss.backward()?)?;
    }
    Ok(brdf
        .decode(&raw.as_tensor().detach())?
        .with_texel_size(texel))
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let sim = PathBuf::from(
        args.first()
            .context("usage: family_needs SIM [SIZE] [STEPS] [SPECS] [TOLERANCE]")?,
    );
    let size: usize = args.get(1).map_or(Ok(128), |s| s.parse())?;
    let steps: usize = args.get(2).map_or(Ok(400), |s| s.parse())?;
    let specs = photomat_core::plugin_spec::split_list(
        args.get(3)
            .map_or("lambert,height(ggx),ggx,coated", String::as_str),
    )?;
    let tolerance: f64 = args.get(4).map_or(Ok(0.1), |s| s.parse())?;

    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim.join("simulation.json"))?)?;
    let photos = record["photos"]
        .as_array()
        .context("simulation.json: no photos")?;
    let mut families: Vec<&serde_json::Value> = Vec::new();
    for p in photos {
        if !families.iter().any(|f| f["family"] == p["family"]) {
            families.push(p);
        }
    }
    let device = Device::Cpu;
    let reference = LightSet::reference();
    let mut rng = SplitMix64(0x6661_6d69_6c79);
    let held_out = LightSet::uniform(HELD_OUT, || 0.25 + 0.5 * rng.next_unit());
    let mut brdfs: Vec<Brdf> = specs.iter().map(|s| lookup(s)).collect::<Result<_, _>>()?;
    brdfs.sort_by_key(|b| (b.channels(), b.name()));

    println!(
        "{size}² fits, {steps} steps on the 5 reference lights, error on {HELD_OUT} held-out lights, \
         tolerance {tolerance}"
    );
    println!(
        "| family | truth | {} | chosen |",
        brdfs
            .iter()
            .map(|b| b.name())
            .collect::<Vec<_>>()
            .join(" | ")
    );
    for photo in families {
        let family = photo["family"].as_str().unwrap_or("?");
        let truth = load_maps(
            &sim.join(photo["truth"].as_str().context("no truth")?),
            None,
        )?;
        let (_, full, _) = truth.maps.batch_and_size()?;
        let truth_maps = truth
            .maps
            .clone()
            .with_texel_size(Some(PHOTO_SIDE / full as f64));
        let truth_render = |lights: &LightSet| -> anyhow::Result<Tensor> {
            let geometry = lights.geometry_on(full, PHOTO_SIDE, DType::F32, &device)?;
            let radiance = render_radiance_with(truth.brdf.as_ref(), &truth_maps, &geometry)?;
            Ok(radiance.avg_pool2d(full / size)?)
        };
        let target = encode_display(&truth_render(&reference)?)?;
        let held_truth = truth_render(&held_out)?;
        let fit_geometry = reference.geometry_on(size, PHOTO_SIDE, DType::F32, &device)?;
        let held_geometry = held_out.geometry_on(size, PHOTO_SIDE, DType::F32, &device)?;
        let mut candidates = Vec::new();
        let mut cells = Vec::new();
        for brdf in &brdfs {
            let maps = fit(brdf, &target, &fit_geometry, steps)?;
            let fitted =
                encode_display(&render_radiance_with(brdf.as_ref(), &maps, &fit_geometry)?)?;
            let fit_l1 = scalar(&(fitted - &target)?.abs()?.mean_all()?)?;
            let relit = render_radiance_with(brdf.as_ref(), &maps, &held_geometry)?;
            let error = scalar(&(&relit - &held_truth)?.abs()?.mean_all()?)?
                / scalar(&held_truth.mean_all()?)?;
            cells.push(format!("{error:.3} ({fit_l1:.4})"));
            candidates.push(Candidate {
                brdf: brdf.name(),
                channels: brdf.channels(),
                l1: fit_l1,
                l1_linear: error,
            });
        }
        let chosen = choose(&candidates, tolerance)
            .map_or("none".to_string(), |k| candidates[k].brdf.clone());
        println!(
            "| {family} | {} | {} | {chosen} |",
            truth.brdf.name(),
            cells.join(" | ")
        );
    }
    Ok(())
}
