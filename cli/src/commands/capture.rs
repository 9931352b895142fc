//! `photomat capture PHOTO --brdf SPEC|auto --out DIR [--overwrite] [--start constant|gan]
//! [--size 256] [--steps 400] [--fov DEG] [--highlight ROW,COL] [--prior] [--model MODEL]
//! [--prior-steps 100] [--anchor μ] [--tolerance T] [--warmup-steps 100] [--no-vignetting]
//! [--ambient] [--uniform MAP,…] [--known DIR] [--relief] [--full-size-steps 100] [--gltf]
//! [--mtlx]`: one phone flash photo → maps of a named BRDF model (docs/capture.md). The work is
//! the library's `photomat_capture::CaptureJob`: from constant maps, or with `--start gan`
//! (`--prior`, `--model`) from the model folder's generator prior when the folder has an
//! estimator for SPEC; with `--brdf auto` the model is chosen among the folder's estimators.
//! The job checks the model, the output folder and the memory before it starts and writes DIR
//! whole when it ends (an earlier capture is refused unless `--overwrite`; an interrupted or
//! killed capture leaves DIR as it was): DIR/material/ (loadable by every command),
//! DIR/export/ (renderer textures, and the glTF / MaterialX documents asked for),
//! DIR/sheet.png (photo | [M's relighting | E's maps] | re-render | ×4 error), DIR/relit.png
//! (the maps under eight new flash positions) and DIR/capture.json (geometry, highlight, gain,
//! losses, timings). This command builds the job, shows progress and prints its report.

use std::io::Write;
use std::path::PathBuf;

use photomat_capture::{
    CaptureJob, CaptureOptions, Exports, FOV_RANGE, JobOutcome, PRIOR_REFINEMENT_STEPS,
    PriorOptions, StartFrom,
};
use photomat_estimator::model_choice::{BrdfChoice, DEFAULT_TOLERANCE};

use crate::common::{interruption, model_dir, parse_pair, steps_bar, stop_flag};

/// Where the fit starts, on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Start {
    /// Constant maps with a uniform warm-up.
    Constant,
    /// The relief prior (--prior-model, else the model folder's priors/ for --brdf): its
    /// prediction of the maps, relief included, refined and held near it.
    Prior,
    /// The generator prior of the model folder (--model, else the default one): its GAN
    /// inverted to the photo, decoded by its estimator for --brdf.
    Gan,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The flash photo (JPEG or PNG; EXIF orientation applied, centre-cropped to a square),
    /// taken straight down with the phone's flash on, as for training photos.
    #[arg(value_name = "PHOTO")]
    pub photo: PathBuf,

    /// BRDF model of the maps, e.g. ggx or "height(ggx)" (`photomat brdfs` lists them), or
    /// `auto`: the cheapest model (fewest map channels) the model folder has an estimator for
    /// whose decoding of the inverted generator is within --tolerance of the best one's L1
    /// (linear radiance) against M's relighting of it, under the photo's flash and eight
    /// others; implies --prior. capture.json and material.json record the choice and every
    /// candidate's error.
    #[arg(long, value_name = "SPEC|auto")]
    pub brdf: String,

    /// With --brdf auto: accepted L1 above the best model's, relative (0.1 = 10 %).
    #[arg(long, value_name = "T", default_value_t = DEFAULT_TOLERANCE, value_parser = parse_weight)]
    pub tolerance: f64,

    /// Output folder: written whole when the capture ends (a killed or interrupted capture
    /// leaves it as it was); an earlier capture in it is refused unless --overwrite.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Replace an earlier capture in DIR, whole.
    #[arg(long)]
    pub overwrite: bool,

    /// Where the fit starts [default: prior when the model folder has a relief prior for
    /// --brdf, else constant; gan with --prior or --model].
    #[arg(long, value_enum, value_name = "FROM")]
    pub start: Option<Start>,

    /// A relief prior's folder (a `photomat train-prior` run, or a model folder's
    /// priors/NAME/); implies --start prior.
    #[arg(long, value_name = "DIR")]
    pub prior_model: Option<PathBuf>,

    /// Side of the maps: the photo is resampled to N² before fitting [default: 256].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(16..=2048))]
    pub size: Option<u32>,

    /// Optimisation steps [default: 400; 100 from the relief prior].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub steps: Option<u32>,

    /// The flash highlight as continuous pixel ROW,COL of the N×N square, instead of
    /// detecting it.
    #[arg(long, value_name = "ROW,COL", value_parser = parse_pixel)]
    pub highlight: Option<(f64, f64)>,

    /// The camera's field of view across the photo's longer side, in degrees (5 … 150), the
    /// camera looking straight down with the flash beside the lens. It sets the photographed
    /// square's size relative to the flash's distance [default: from the lens the photo's EXIF
    /// records, its focal length and sensor pitch or its 35 mm equivalent focal length (26 mm
    /// on 4:3 gives 67°), else 67, a phone's main camera; 90 is the geometry of the training
    /// data and of `photomat simulate`'s photos, whose EXIF records it, docs/conventions.md].
    #[arg(long, value_name = "DEG", value_parser = parse_fov)]
    pub fov: Option<f64>,

    /// Start the fit from the generator prior of the default model folder ($PHOTOMAT_MODEL,
    /// else the bundled models/demo): the generator inverted to the photo, its material
    /// decoded by the estimator for --brdf. Off by default: on simulated photos of the eight
    /// families the bundled model's prior relit better on five and worse on three (fabric,
    /// paint, tiles), worse on average, at 3–4× the time (docs/benchmarks/capture.md, "`photomat
    /// capture` with the generator prior"). The same as --start gan.
    #[arg(long)]
    pub prior: bool,

    /// Model folder whose generator prior starts the fit (its GAN, and an estimator for
    /// --brdf at the root or under estimators/); implies --prior. Without an estimator for
    /// --brdf the fit starts from constant maps, with a note.
    #[arg(long, value_name = "DIR")]
    pub model: Option<PathBuf>,

    /// Steps of the generator inversion before the refinement [default: 100].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub prior_steps: Option<u32>,

    /// Weight of the term that holds the refined raw maps near the prior's (0: none)
    /// [default: 0.05].
    #[arg(long, value_name = "MU", value_parser = parse_weight)]
    pub anchor: Option<f64>,

    /// Maps fitted as one value over the whole photo, comma-separated (e.g. `height`: flat
    /// normals; `specular,roughness`), so that they cannot paint the photo's highlight in.
    /// The names are the model's maps (`photomat brdfs`) [default: none].
    #[arg(long, value_name = "MAP,…", value_delimiter = ',')]
    pub uniform: Vec<String>,

    /// A material folder (as `capture`, `sample` or `simulate` write one) whose maps are
    /// known: each of its maps that --brdf's model takes is held at its values through the
    /// whole fit (e.g. a diffuse albedo from a cross-polarised photo) and the photo sets the
    /// others; its maps must be --size texels square. capture.json lists the maps held.
    #[arg(long, value_name = "DIR")]
    pub known: Option<PathBuf>,

    /// Steps of the uniform warm-up of a fit from constant maps: one value per map channel,
    /// the exposure, the vignetting and the ambient light, fitted to the photo at 64² before
    /// the per-texel fit starts from them (0: none, and no vignetting or ambient light)
    /// [default: 100].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(0..=100_000))]
    pub warmup_steps: Option<u32>,

    /// Take the photo as free of vignetting instead of fitting the lens's falloff (a
    /// quadratic loss towards the corners) in the warm-up; capture.json records the fitted
    /// strength.
    #[arg(long)]
    pub no_vignetting: bool,

    /// Fit a dim, uniform ambient light (reflected by the diffuse and specular maps) in the
    /// warm-up and the fit, instead of taking the photo as taken in a dark room; capture.json
    /// records the fitted radiance, in units of the flash's at the photo's centre.
    #[arg(long)]
    pub ambient: bool,

    /// Of --steps, how many run at the full size in a capture of 1024² or more from constant
    /// maps; the others run on the photo box-filtered to 512²…1023² (the size halved while
    /// the half is 512 or more and the size even), a quarter of the texels per halving, and start the full-size
    /// steps from their maps upsampled (capture.json records the split) [default: 100].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(0..=100_000))]
    pub full_size_steps: Option<u32>,

    /// Fit the relief (the height or normal map) texel by texel in a fit from constant maps.
    /// Off by default: it is held flat, which relit independent test photos better under new
    /// flashes than the relief one flash paints in (docs/capture.md, "Fit").
    #[arg(long)]
    pub relief: bool,

    /// Also write export/material.gltf (glTF 2.0 with KHR_materials_specular) beside the
    /// renderer textures that export/ always holds.
    #[arg(long)]
    pub gltf: bool,

    /// Also write export/material.mtlx (MaterialX 1.38, UsdPreviewSurface) beside the
    /// renderer textures.
    #[arg(long)]
    pub mtlx: bool,
}

/// A finite weight ≥ 0.
fn parse_weight(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("'{text}' is not a weight ≥ 0")),
    }
}

/// A field of view within [`FOV_RANGE`] degrees.
fn parse_fov(text: &str) -> Result<f64, String> {
    let (lo, hi) = FOV_RANGE;
    match text.trim().parse::<f64>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!(
            "'{text}' is not a field of view in {lo} … {hi} degrees"
        )),
    }
}

/// `ROW,COL`: two finite numbers.
fn parse_pixel(text: &str) -> Result<(f64, f64), String> {
    parse_pair(text, "ROW,COL")
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let job = job(args)?;
    let stop = stop_flag()?;
    let job = CaptureJob {
        options: CaptureOptions {
            stop: Some(stop.clone()),
            ..job.options
        },
        ..job
    };
    let prior_steps = match job.start {
        StartFrom::Gan => job.prior_options.steps,
        _ if job.brdf.is_auto() => job.prior_options.steps,
        StartFrom::Constant | StartFrom::Prior => 0,
    };
    let bar = steps_bar((prior_steps + job.options.steps) as u64, 0);
    let outcome = job.run(&mut |step, loss| {
        let phase = if step <= prior_steps {
            "inversion"
        } else {
            "refinement"
        };
        bar.set_position(step as u64);
        bar.set_message(format!("{phase} loss {loss:.4}"));
    });
    bar.finish_and_clear();
    match outcome? {
        JobOutcome::Done(report) => {
            for note in &report.notes {
                writeln!(out, "{note}")?;
            }
            writeln!(out, "{report}")?;
            Ok(())
        }
        JobOutcome::Stopped => {
            eprintln!(
                "interrupted: nothing was written; {} is as it was. Run the same command again \
                 to capture the photo",
                args.out.display()
            );
            Err(interruption().into())
        }
    }
}

/// Where a capture starts without --start: from the relief prior when the default model folder
/// has one for the named model, else from constant maps.
fn default_start(brdf: &BrdfChoice) -> anyhow::Result<StartFrom> {
    let BrdfChoice::Named(spec) = brdf else {
        return Ok(StartFrom::Constant);
    };
    let model = photomat_core::lookup(spec)?;
    let has_prior = model_dir(None)
        .ok()
        .map(|dir| photomat_prior::find_prior(&dir, &model))
        .transpose()?
        .flatten()
        .is_some();
    Ok(if has_prior {
        StartFrom::Prior
    } else {
        StartFrom::Constant
    })
}

/// The job the flags describe: the model checked by name, the model folder resolved when the
/// fit starts from the generator prior (or chooses the model).
fn job(args: &Args) -> anyhow::Result<CaptureJob> {
    let brdf = BrdfChoice::parse(&args.brdf, args.tolerance)?;
    let start = match args.start {
        Some(Start::Gan) => StartFrom::Gan,
        Some(Start::Prior) => StartFrom::Prior,
        Some(Start::Constant) => StartFrom::Constant,
        None if args.prior || args.model.is_some() => StartFrom::Gan,
        None if args.prior_model.is_some() => StartFrom::Prior,
        None => default_start(&brdf)?,
    };
    let model_dir = match start {
        StartFrom::Gan | StartFrom::Prior => Some(model_dir(args.model.as_deref())?),
        StartFrom::Constant if brdf.is_auto() => Some(model_dir(args.model.as_deref())?),
        StartFrom::Constant => None,
    };
    let defaults = CaptureOptions::default();
    let options = CaptureOptions {
        size: args.size.map_or(defaults.size, |n| n as usize),
        steps: args.steps.map_or(
            if start == StartFrom::Prior {
                PRIOR_REFINEMENT_STEPS
            } else {
                defaults.steps
            },
            |k| k as usize,
        ),
        highlight: args.highlight,
        fov_degrees: args.fov,
        anchor: args.anchor.unwrap_or(defaults.anchor),
        uniform_maps: args.uniform.clone(),
        relief: args.relief,
        warmup_steps: args
            .warmup_steps
            .map_or(defaults.warmup_steps, |k| k as usize),
        vignetting: defaults.vignetting && !args.no_vignetting,
        ambient: defaults.ambient || args.ambient,
        full_size_steps: args
            .full_size_steps
            .map_or(defaults.full_size_steps, |k| k as usize),
        ..defaults
    };
    let prior_options = PriorOptions {
        steps: args
            .prior_steps
            .map_or(PriorOptions::default().steps, |k| k as usize),
        ..PriorOptions::default()
    };
    Ok(CaptureJob {
        photo: args.photo.clone(),
        out: args.out.clone(),
        brdf,
        start,
        model_dir,
        options,
        prior_options,
        prior_dir: args.prior_model.clone(),
        known: args.known.clone(),
        exports: Exports {
            gltf: args.gltf,
            mtlx: args.mtlx,
        },
        overwrite: args.overwrite,
    })
}
