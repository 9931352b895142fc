//! `photomat capture` on flash photos this project did not make: the Mitsuba-rendered set of
//! `validation/run.sh --capture-set` (texture photos with known maps, camera tilt, flash
//! offset, vignetting, noise, JPEG), each captured four ways and judged against its truth:
//!
//! - `constant`: the constant maps a direct capture starts from (the floor);
//! - `direct`: `capture` from those constant maps (without `--prior`);
//! - `E only`: the prior's maps before refinement (E on the inverted generator);
//! - `prior`: `capture_with_prior`, inversion then refinement (`--prior`).
//!
//! ```text
//! validation/run.sh --count 8 --seed 1 --capture-set --out capval
//! cargo run --release -p photomat-capture --example mitsuba_validation -- capval MODEL [SHEET.png]
//! ```
//! MODEL: a model folder with a `height(ggx, …)` estimator (e.g. models/demo); the direct fit
//! captures in the same specification, relief scale included.
//! Each photo is captured at its own 320² with its true field of view and the default
//! detector's highlight; FIRST and COUNT take a slice of the set (to run halves side by side). Measures ([`photomat_capture::evaluate`]): the display L1 under the
//! photo's flash (against the photo) and under the eight held-out flashes (against Mitsuba's
//! renders of the true material, registered to the photo's pixels), each after one
//! per-channel scale; the per-map RMSEs (diffuse and specular after the colour scale of the
//! held-out renders) and the mean normal error in degrees. SHEET, when
//! given, gets a row per photo: photo | truth, direct, E only, prior under held-out flash 0 |
//! truth's, direct's and prior's normals.

use std::path::PathBuf;

use anyhow::Context;
use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_capture::evaluate::{
    MapErrors, channel_scale, held_out_l1, map_errors, radiance_on_square, read_held_out,
};
use photomat_capture::{CaptureOptions, GanPrior, PriorOptions, capture, capture_with_prior};
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::map_files::load_maps;
use photomat_core::render::DISPLAY_GAMMA;
use photomat_core::sheet::grid;
use photomat_core::{Brdf, Highlight, MaterialMaps, encode_display};

const SIZE: usize = 320;
const METHODS: [&str; 4] = ["constant", "direct", "E only", "prior"];

/// One method's result on one photo.
struct Scored {
    input_l1: f64,
    held_l1: f64,
    maps: MapErrors,
    /// Linear radiance under the held-out flashes (8, 3, N, N).
    held: Tensor,
    /// Shading normals (1, 3, N, N).
    normal: Tensor,
}

fn score(
    brdf: &Brdf,
    maps: &MaterialMaps,
    photo_flash: Highlight,
    photo_linear: &Tensor,
    lights: &[Highlight],
    side: f64,
    truth: (&Brdf, &MaterialMaps, &Tensor),
) -> anyhow::Result<Scored> {
    let (truth_brdf, truth_maps, truth_held) = truth;
    let input = radiance_on_square(brdf, maps, &[photo_flash], side)?;
    let held = radiance_on_square(brdf, maps, lights, side)?;
    let scale = channel_scale(&held, truth_held)?;
    Ok(Scored {
        input_l1: held_out_l1(&input, photo_linear)?,
        held_l1: held_out_l1(&held, truth_held)?,
        maps: map_errors(brdf, maps, &scale, truth_brdf, truth_maps)?,
        held,
        normal: brdf.shading_maps(maps)?.get("normal")?.clone(),
    })
}

/// Display image of one linear render, exposed like the held-out measure's truth.
fn shown(t: &Tensor, exposure: f64) -> anyhow::Result<PlanarImage> {
    Ok(PlanarImage::from_tensor(
        &encode_display(&(t * exposure)?)?.squeeze(0)?,
    )?)
}

fn shown_normal(n: &Tensor) -> anyhow::Result<PlanarImage> {
    Ok(PlanarImage::from_tensor(
        &((n.squeeze(0)? * 0.5)? + 0.5)?.clamp(0.0, 1.0)?,
    )?)
}

/// The `photomat` binary's allocator, so that the seconds reported are the command's.
#[global_allocator]
static GLOBAL: photomat_kernels::alloc::FastAllocator = photomat_kernels::alloc::FastAllocator;

fn main() -> anyhow::Result<()> {
    // SAFETY: nothing has started a thread yet: this is the first statement of `main`.
    unsafe { photomat_kernels::threads::set_up_like_the_binary() };
    photomat_kernels::alloc::keep_freed_pages();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: mitsuba_validation CAPVAL MODEL [SHEET.png [FIRST COUNT]]";
    let set = PathBuf::from(args.first().context(usage)?);
    let model = PathBuf::from(args.get(1).context(usage)?);
    let sheet = args.get(2).map(PathBuf::from);
    let first: usize = args.get(3).map_or(Ok(0), |s| s.parse())?;
    let count: usize = args.get(4).map_or(Ok(usize::MAX), |s| s.parse())?;

    // The model's `height(ggx, …)` estimator sets the relief scale both fits capture in.
    let mut prior = GanPrior::open_all(&model, &Device::Cpu)?;
    prior.retain_estimators(|b| b.name().starts_with("height(ggx"));
    let brdf = prior.estimators().first().map(|e| e.brdf().clone());
    let brdf =
        brdf.with_context(|| format!("'{}' has no height(ggx) estimator", model.display()))?;
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
        "{SIZE}² captures in {}, {} + {} steps; display L1 under the photo's flash / 8 held-out flashes; \
         diffuse, specular, roughness RMSE; normal error (°)",
        brdf.name(),
        PriorOptions::default().steps,
        CaptureOptions::default().steps
    );
    println!(
        "| photo | texture | highlight error px | method | L1 input | L1 held-out | diffuse | specular | roughness | normal ° | seconds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut totals = [[0.0f64; 6]; 4];
    let mut rows = Vec::new();
    for photo in &photos {
        let name = photo["photo"].as_str().context("no photo")?;
        let texture = photo["family"].as_str().unwrap_or("?");
        let fov = photo["camera"]["fov_deg"].as_f64().context("no fov_deg")?;
        let truth_dir = set.join(
            photo["truth"]
                .as_str()
                .context("no truth: render the set with `validation/run.sh --capture-set`")?,
        );
        let truth = load_maps(&truth_dir, None)?;
        let (lights, truth_held) = read_held_out(&set, photo)?;
        let bytes = std::fs::read(set.join(name))?;
        let mut options = CaptureOptions {
            size: SIZE,
            fov_degrees: Some(fov),
            ..CaptureOptions::default()
        };
        let true_px = photo["highlight_px"]
            .as_array()
            .context("no highlight_px")?;
        let true_px = (
            true_px[0].as_f64().context("row")?,
            true_px[1].as_f64().context("col")?,
        );
        // A photo whose highlight the detector does not find is captured at the true one, and
        // the table says so (its highlight error reads "miss").
        let direct = match capture(&bytes, name, &brdf, &options, &mut |_, _| {}) {
            Ok(direct) => direct,
            Err(error) => {
                eprintln!("{error:#}: capturing at the true highlight");
                options.highlight = Some(true_px);
                capture(&bytes, name, &brdf, &options, &mut |_, _| {})?
            }
        };
        let with_prior = capture_with_prior(
            &bytes,
            name,
            &brdf,
            &options,
            Some((&prior, &PriorOptions::default())),
            &mut |_, _| {},
        )?;
        let prior_used = with_prior.prior.as_ref().context("no prior used")?;
        let side = direct.side;
        let texel = side / SIZE as f64;
        let (row, col) = direct.highlight.pixel;
        let detector_px = if options.highlight.is_some() {
            "miss".to_string()
        } else {
            format!("{:.1}", (row - true_px.0).hypot(col - true_px.1))
        };
        let flash = Highlight::from_pixel_on(row, col, SIZE, side);
        let photo_linear = direct.photo.powf(DISPLAY_GAMMA)?;
        let constant = brdf
            .decode(&Tensor::zeros(
                (1, brdf.channels(), SIZE, SIZE),
                DType::F32,
                &Device::Cpu,
            )?)?
            .with_texel_size(Some(texel));
        let truth_ref = (&truth.brdf, &truth.maps, &truth_held);
        let scored = [&constant, &direct.maps, &prior_used.maps, &with_prior.maps]
            .into_iter()
            .map(|maps| score(&brdf, maps, flash, &photo_linear, &lights, side, truth_ref))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let seconds = [
            0.0,
            direct.seconds,
            prior_used.inversion.seconds,
            prior_used.inversion.seconds + with_prior.seconds,
        ];
        for (m, s) in scored.iter().enumerate() {
            let e = &s.maps;
            let values = [
                s.input_l1,
                s.held_l1,
                e.diffuse_rmse,
                e.specular_rmse,
                e.roughness_rmse,
                e.normal_degrees,
            ];
            for (t, v) in totals[m].iter_mut().zip(values) {
                *t += v;
            }
            println!(
                "| {name} | {texture} | {detector_px} | {} | {:.4} | {:.4} | {:.3} | {:.3} | {:.3} | {:.2} | {:.0} |",
                METHODS[m],
                values[0],
                values[1],
                values[2],
                values[3],
                values[4],
                values[5],
                seconds[m]
            );
        }
        if sheet.is_some() {
            let exposure = 0.18 / truth_held.mean_all()?.to_scalar::<f32>()? as f64;
            let first = |t: &Tensor| t.narrow(0, 0, 1);
            let mut row = vec![PlanarImage::from_tensor(&direct.photo.squeeze(0)?)?];
            row.push(shown(&first(&truth_held)?, exposure)?);
            for s in &scored[1..] {
                // Each fit shown with the per-channel scale the measure gives it.
                let scale = channel_scale(&s.held, &truth_held)?;
                row.push(shown(&first(&s.held.broadcast_mul(&scale)?)?, exposure)?);
            }
            row.push(shown_normal(
                truth.brdf.shading_maps(&truth.maps)?.get("normal")?,
            )?);
            row.push(shown_normal(&scored[1].normal)?);
            row.push(shown_normal(&scored[3].normal)?);
            rows.push(row);
        }
    }
    let n = photos.len() as f64;
    for (m, t) in totals.iter().enumerate() {
        println!(
            "| mean of {} | | | {} | {:.4} | {:.4} | {:.3} | {:.3} | {:.3} | {:.2} | |",
            photos.len(),
            METHODS[m],
            t[0] / n,
            t[1] / n,
            t[2] / n,
            t[3] / n,
            t[4] / n,
            t[5] / n
        );
    }
    if let Some(path) = sheet {
        write_png(&path, &grid(&rows, 0.0)?, PngBits::Eight)?;
    }
    Ok(())
}
