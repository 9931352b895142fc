//! Which options of the direct capture (from constant maps, no generator prior) relight
//! best? Captures photos with known maps once per configuration and judges each fit by its
//! renders under eight flash positions the photo did not show
//! ([`photomat_capture::evaluate::held_out_l1`]).
//!
//! ```text
//! cargo run --release -p photomat-capture --example direct_fit_sweep -- SET WARMUP[:FLAGS][,…] [FIRST COUNT [SIZE]]
//! ```
//! Columns: L1 photo is the fit's data term (display values, fitted gain and vignetting); L1
//! input the linear render under the photo's flash against the photo, colour-scaled.
//! WARMUP is [`CaptureOptions::warmup_steps`]; FLAGS: `v` fits the vignetting, `a` the
//! ambient light, `u` holds
//! specular and roughness uniform, `h` the height (flat normals), `f` runs every step at the
//! full size (no coarse stage, [`CaptureOptions::full_size_steps`]), `d` captures at the
//! default field of view (the photo's EXIF focal length, else a phone's 67°) instead of the
//! true one, `k` holds the true diffuse, specular and roughness maps
//! ([`CaptureOptions::known_maps`]: what one photo says of the relief when the reflectance is
//! known), `s` weighs the smoothness prior 100× the default (0.2).
//! The truth rows of a Mitsuba set also render the true maps with flat normals and with the
//! relief scaled by ¼, ½ and ¾ (the normal's tilt scaled in slope), with their mean normal
//! error: how close to the true relief a fit must come to relight within a given error; and
//! they capture the photo with every true map held (only the camera terms fitted), with the
//! true relief and flat: how much of the photo the relief explains against what no map can. SIZE: the capture size
//! of simulator folders (default 256).
//! SET: either a Mitsuba capture set (`validation/run.sh --capture-set`: each photo has
//! `held_out` renders and truth maps in its pixel grid; captured at 320² with its true field
//! of view), or a `photomat simulate` folder (truth maps at the photo's resolution; captured
//! at 256² with the simulator's 90°, the truth rendered at its own resolution and box-filtered
//! to 256²). Both capture in `height(ggx, scale=0.02)` at the true highlight, so that the
//! detector's misses do not enter the comparison. Mitsuba sets also get the per-map errors.

use std::path::PathBuf;

use anyhow::Context;
use candle_core::Tensor;
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_capture::evaluate::{
    channel_scale, held_out_l1, map_errors, mean_normal_angle_degrees, radiance_on_square,
    read_held_out,
};
use photomat_capture::{CaptureOptions, capture, new_flash_positions};
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::map_files::load_maps;
use photomat_core::{Highlight, MaterialMaps, lookup};

/// The `photomat` binary's allocator, so that the seconds reported are the command's.
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn main() -> anyhow::Result<()> {
    // SAFETY: nothing has started a thread yet: this is the first statement of `main`.
    unsafe { photomat_kernels::threads::set_up_like_the_binary() };
    photomat_kernels::alloc::keep_freed_pages();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: direct_fit_sweep SET WARMUP[:FLAGS][,…] [FIRST COUNT [SIZE]]";
    let set = PathBuf::from(args.first().context(usage)?);
    let configs: Vec<(usize, String)> = args
        .get(1)
        .context(usage)?
        .split(',')
        .filter(|s| !s.is_empty())
        .map(|s| -> anyhow::Result<(usize, String)> {
            let mut parts = s.split(':');
            let warmup = parts.next().context(usage)?.parse()?;
            let flags = parts.next().unwrap_or("").to_string();
            Ok((warmup, flags))
        })
        .collect::<anyhow::Result<_>>()?;
    let first: usize = args.get(2).map_or(Ok(0), |s| s.parse())?;
    let count: usize = args.get(3).map_or(Ok(usize::MAX), |s| s.parse())?;
    let sim_size: usize = args.get(4).map_or(Ok(256), |s| s.parse())?;
    let brdf = lookup("height(ggx, scale=0.02)")?;
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(set.join("simulation.json"))?)?;
    let photos: Vec<&serde_json::Value> = record["photos"]
        .as_array()
        .context("simulation.json: no photos")?
        .iter()
        .skip(first)
        .take(count)
        .collect();
    println!(
        "| photo | family | warm-up:flags | L1 photo | L1 input | L1 held-out | diffuse | specular | roughness | normal ° | seconds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut totals = vec![[0.0f64; 7]; configs.len()];
    for photo in &photos {
        let name = photo["photo"].as_str().context("no photo")?;
        let family = photo["family"].as_str().unwrap_or("?");
        let truth = load_maps(
            &set.join(photo["truth"].as_str().context("no truth")?),
            None,
        )?;
        let px = photo["highlight_px"]
            .as_array()
            .context("no highlight_px")?;
        let (row, col) = (
            px[0].as_f64().context("row")?,
            px[1].as_f64().context("col")?,
        );
        let (_, full, _) = truth.maps.batch_and_size()?;
        // Mitsuba sets: truth in the photo's grid, held-out renders on disk; simulator
        // folders: truth at the photo's resolution, rendered here.
        let (size, fov, lights, truth_held) = match photo.get("held_out") {
            Some(_) => {
                let (lights, renders) = read_held_out(&set, photo)?;
                let fov = photo["camera"]["fov_deg"].as_f64().context("no fov_deg")?;
                (full, fov, lights, renders)
            }
            None => {
                let size = sim_size;
                let lights = new_flash_positions(PHOTO_SIDE);
                let maps = truth
                    .maps
                    .clone()
                    .with_texel_size(Some(PHOTO_SIDE / full as f64));
                let held = radiance_on_square(&truth.brdf, &maps, &lights, PHOTO_SIDE)?
                    .avg_pool2d(full / size)?;
                (size, 90.0, lights, held)
            }
        };
        let scale_px = size as f64 / full as f64;
        let bytes = std::fs::read(set.join(name))?;
        if full == size {
            // The floor of this renderer: the true maps themselves, rendered here.
            let side = photomat_capture::square_side(fov, size, size);
            let maps = truth.maps.clone().with_texel_size(Some(side / size as f64));
            let held = radiance_on_square(&truth.brdf, &maps, &lights, side)?;
            println!(
                "| {name} | {family} | truth maps | | | {:.4} | | | | | |",
                held_out_l1(&held, &truth_held)?
            );
            // What flat normals alone cost: the true maps with their normal map set to +z.
            if let Ok(normal) = maps.get("normal") {
                let up = Tensor::cat(
                    &[
                        normal.narrow(1, 0, 2)?.zeros_like()?,
                        normal.narrow(1, 2, 1)?.ones_like()?,
                    ],
                    1,
                )?;
                let mut flat = maps.clone();
                flat.insert("normal", up.clone());
                let held = radiance_on_square(&truth.brdf, &flat, &lights, side)?;
                println!(
                    "| {name} | {family} | truth maps, flat normals | | | {:.4} | | | | | |",
                    held_out_l1(&held, &truth_held)?
                );
                // How closely the true maps themselves re-render the photo once the camera
                // terms are fitted, with their relief and without: the part of the photo
                // the relief explains, against what no map can (noise, JPEG, the camera's
                // tilt and flash offset, the principled BSDF against ggx).
                for (label, relief) in [("true relief", normal.clone()), ("flat", up.clone())] {
                    let mut known = truth.maps.clone();
                    known.insert("normal", relief);
                    let options = CaptureOptions {
                        size,
                        fov_degrees: Some(fov),
                        highlight: Some((row * scale_px, col * scale_px)),
                        known_maps: Some(known),
                        ..CaptureOptions::default()
                    };
                    let fit = capture(&bytes, name, &truth.brdf, &options, &mut |_, _| {})?;
                    println!(
                        "| {name} | {family} | truth maps held, {label} | {:.4} | | | | | | | |",
                        photo_l1(&fit)?
                    );
                }
                for s in [0.25, 0.5, 0.75] {
                    let scaled = relief_scaled(normal, s)?;
                    let degrees = mean_normal_angle_degrees(&scaled, normal)?;
                    let mut maps = maps.clone();
                    maps.insert("normal", scaled);
                    let held = radiance_on_square(&truth.brdf, &maps, &lights, side)?;
                    println!(
                        "| {name} | {family} | truth maps, relief ×{s} | | | {:.4} | | | | {degrees:.2} | |",
                        held_out_l1(&held, &truth_held)?
                    );
                }
            }
        }
        for (w, (warmup, flags)) in configs.iter().enumerate() {
            let options = CaptureOptions {
                size,
                fov_degrees: (!flags.contains('d')).then_some(fov),
                highlight: Some((row * scale_px, col * scale_px)),
                warmup_steps: *warmup,
                vignetting: flags.contains('v'),
                ambient: flags.contains('a'),
                uniform_maps: if flags.contains('u') {
                    vec!["specular".into(), "roughness".into()]
                } else {
                    Vec::new()
                },
                relief: !flags.contains('h'),
                known_maps: flags
                    .contains('k')
                    .then(|| -> anyhow::Result<MaterialMaps> {
                        let mut known = MaterialMaps::new();
                        for name in ["diffuse", "specular", "roughness"] {
                            known.insert(name, truth.maps.get(name)?.clone());
                        }
                        Ok(known)
                    })
                    .transpose()?,
                smoothness: if flags.contains('s') {
                    100.0 * CaptureOptions::default().smoothness
                } else {
                    CaptureOptions::default().smoothness
                },
                full_size_steps: if flags.contains('f') {
                    usize::MAX
                } else {
                    CaptureOptions::default().full_size_steps
                },
                ..CaptureOptions::default()
            };
            let fit = capture(&bytes, name, &brdf, &options, &mut |_, _| {})?;
            let (r, c) = fit.highlight.pixel;
            let flash = Highlight::from_pixel_on(r, c, size, fit.side);
            let input = radiance_on_square(&brdf, &fit.maps, &[flash], fit.side)?;
            // The held-out flashes above the same pixels of the fit's square as of the true
            // one (they differ when the fit's field of view is not the true one).
            let true_side = photomat_capture::square_side(fov, size, size);
            let fit_lights: Vec<Highlight> = lights
                .iter()
                .map(|l| Highlight::new(l.x * fit.side / true_side, l.y * fit.side / true_side))
                .collect();
            let held = radiance_on_square(&brdf, &fit.maps, &fit_lights, fit.side)?;
            let input_l1 = held_out_l1(&input, &fit.photo.powf(2.2)?)?;
            let held_l1 = held_out_l1(&held, &truth_held)?;
            let errors = if full == size {
                let scale = channel_scale(&held, &truth_held)?;
                let e = map_errors(&brdf, &fit.maps, &scale, &truth.brdf, &truth.maps)?;
                [
                    e.diffuse_rmse,
                    e.specular_rmse,
                    e.roughness_rmse,
                    e.normal_degrees,
                ]
            } else {
                [f64::NAN; 4]
            };
            // In the table's order.
            let values = [
                photo_l1(&fit)?,
                input_l1,
                held_l1,
                errors[0],
                errors[1],
                errors[2],
                errors[3],
            ];
            for (t, v) in totals[w].iter_mut().zip(values) {
                *t += v;
            }
            println!(
                "| {name} | {family} | {warmup}:{flags} | {:.4} | {:.4} | {:.4} | {:.3} | {:.3} | {:.3} | {:.2} | {:.0} |",
                values[0],
                values[1],
                values[2],
                values[3],
                values[4],
                values[5],
                values[6],
                fit.seconds
            );
        }
    }
    let n = photos.len() as f64;
    for (w, (warmup, flags)) in configs.iter().enumerate() {
        let t = totals[w];
        println!(
            "| mean of {} | | {warmup}:{flags} | {:.4} | {:.4} | {:.4} | {:.3} | {:.3} | {:.3} | {:.2} | |",
            photos.len(),
            t[0] / n,
            t[1] / n,
            t[2] / n,
            t[3] / n,
            t[4] / n,
            t[5] / n,
            t[6] / n
        );
    }
    Ok(())
}

/// The fit's data term: mean |re-render − photo| over display values, with the fitted
/// gain and vignetting.
fn photo_l1(fit: &photomat_capture::Capture) -> anyhow::Result<f64> {
    Ok((&fit.render - &fit.photo)?
        .abs()?
        .mean_all()?
        .to_scalar::<f32>()? as f64)
}

/// Unit normals (1, 3, N, N) whose slope is `s` times that of `normal`'s: (s·n_x, s·n_y, n_z)
/// normalised.
fn relief_scaled(normal: &Tensor, s: f64) -> candle_core::Result<Tensor> {
    let tilted = Tensor::cat(
        &[(normal.narrow(1, 0, 2)? * s)?, normal.narrow(1, 2, 1)?],
        1,
    )?;
    tilted.broadcast_div(&tilted.sqr()?.sum_keepdim(1)?.sqrt()?)
}
