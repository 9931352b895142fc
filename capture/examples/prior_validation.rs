//! Does the generator prior give better maps than a fit from constant maps? For the first
//! `PER_FAMILY` photos of each family of a `photomat simulate` folder, captures the photo
//! three ways and judges each by its maps' renders under eight flash positions the photo did
//! not show ([`photomat_capture::new_flash_positions`]) against the ground-truth material's:
//!
//! - `direct`: `capture` from constant maps (the default, without `--prior`);
//! - `E only`: the prior's maps before refinement (E on the inverted generator);
//! - `prior`: `capture_with_prior`, the inversion then the refinement (`--prior`).
//!
//! ```text
//! cargo run --release -p photomat-capture --example prior_validation -- SIM MODEL [PER_FAMILY] [ANCHOR]
//! ```
//! SIM: a `photomat simulate` folder of square photos (truth/, simulation.json); MODEL: a
//! model folder with a `height(ggx, …)` estimator (e.g. models/demo): the captures use its
//! specification, relief scale included, whatever the truth's model is. Captures at 256²
//! with the field of view 90°, the simulator's geometry (side 2 at flash height 1).
//!
//! The error is [`photomat_capture::evaluate::held_out_l1`]: the L1 of display-encoded images
//! over the eight held-out lights, the truth exposed to a mean of 0.18 and each fit given the
//! truth's per-channel means (the photo's exposure and white balance are unknowns of the
//! capture, so a global colour scale is not counted against it). The truth is rendered at its
//! own resolution and box-filtered to 256².

use std::path::PathBuf;

use anyhow::Context;
use candle_core::Device;
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_capture::evaluate::{held_out_l1, radiance_on_square};
use photomat_capture::{
    CaptureOptions, GanPrior, PriorOptions, capture, capture_with_prior, new_flash_positions,
};
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::map_files::load_maps;

const SIZE: usize = 256;

/// The `photomat` binary's allocator, so that the seconds reported are the command's.
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn main() -> anyhow::Result<()> {
    // SAFETY: nothing has started a thread yet: this is the first statement of `main`.
    unsafe { photomat_kernels::threads::set_up_like_the_binary() };
    photomat_kernels::alloc::keep_freed_pages();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: prior_validation SIM MODEL [PER_FAMILY] [ANCHOR]";
    let sim = PathBuf::from(args.first().context(usage)?);
    let model = PathBuf::from(args.get(1).context(usage)?);
    let per_family: usize = args.get(2).map_or(Ok(1), |s| s.parse())?;
    let anchor: f64 = args
        .get(3)
        .map_or(Ok(CaptureOptions::default().anchor), |s| s.parse())?;

    // The model's `height(ggx, …)` estimator sets the relief scale both fits capture in.
    let mut prior = GanPrior::open_all(&model, &Device::Cpu)?;
    prior.retain_estimators(|b| b.name().starts_with("height(ggx"));
    let brdf = prior.estimators().first().map(|e| e.brdf().clone());
    let brdf =
        brdf.with_context(|| format!("'{}' has no height(ggx) estimator", model.display()))?;
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sim.join("simulation.json"))?)?;
    let photos = record["photos"]
        .as_array()
        .context("simulation.json: no photos")?;
    let mut chosen: Vec<&serde_json::Value> = Vec::new();
    for p in photos {
        if chosen.iter().filter(|c| c["family"] == p["family"]).count() < per_family {
            chosen.push(p);
        }
    }
    let options = CaptureOptions {
        size: SIZE,
        fov_degrees: Some(90.0),
        anchor,
        ..CaptureOptions::default()
    };
    let lights = new_flash_positions(PHOTO_SIDE);
    println!(
        "{SIZE}² captures in {}, {} + {} steps, anchor {anchor}; display L1 under 8 held-out flashes",
        brdf.name(),
        PriorOptions::default().steps,
        options.steps
    );
    println!(
        "| photo | family | direct | E only | prior | fit L1 direct / prior | seconds direct / prior |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut totals = [0.0f64; 3];
    for photo in &chosen {
        let file = sim.join(photo["photo"].as_str().context("no photo")?);
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
        let held_truth = radiance_on_square(&truth.brdf, &truth_maps, &lights, PHOTO_SIDE)?
            .avg_pool2d(full / SIZE)?;
        let bytes = std::fs::read(&file)?;
        let name = file.display().to_string();
        let direct = capture(&bytes, &name, &brdf, &options, &mut |_, _| {})?;
        let with_prior = capture_with_prior(
            &bytes,
            &name,
            &brdf,
            &options,
            Some((&prior, &PriorOptions::default())),
            &mut |_, _| {},
        )?;
        let prior_used = with_prior.prior.as_ref().context("no prior used")?;
        let errors = [
            held_out_l1(
                &radiance_on_square(&brdf, &direct.maps, &lights, PHOTO_SIDE)?,
                &held_truth,
            )?,
            held_out_l1(
                &radiance_on_square(&brdf, &prior_used.maps, &lights, PHOTO_SIDE)?,
                &held_truth,
            )?,
            held_out_l1(
                &radiance_on_square(&brdf, &with_prior.maps, &lights, PHOTO_SIDE)?,
                &held_truth,
            )?,
        ];
        for (t, e) in totals.iter_mut().zip(errors) {
            *t += e;
        }
        let fit_l1 = |c: &photomat_capture::Capture| -> anyhow::Result<f64> {
            Ok((&c.render - &c.photo)?
                .abs()?
                .mean_all()?
                .to_scalar::<f32>()? as f64)
        };
        println!(
            "| {} | {family} | {:.4} | {:.4} | {:.4} | {:.4} / {:.4} | {:.0} / {:.0} |",
            photo["photo"].as_str().unwrap_or("?"),
            errors[0],
            errors[1],
            errors[2],
            fit_l1(&direct)?,
            fit_l1(&with_prior)?,
            direct.seconds,
            prior_used.inversion.seconds + with_prior.seconds,
        );
    }
    let n = chosen.len() as f64;
    println!(
        "| mean of {} | | {:.4} | {:.4} | {:.4} | | |",
        chosen.len(),
        totals[0] / n,
        totals[1] / n,
        totals[2] / n
    );
    Ok(())
}
