//! `photomat capture PHOTO --brdf SPEC|auto --out DIR [--size 256] [--steps 400] [--fov DEG]
//! [--highlight ROW,COL] [--prior] [--model MODEL] [--prior-steps 100] [--anchor μ]
//! [--tolerance T] [--warmup-steps 100] [--no-vignetting] [--ambient] [--uniform MAP,…]
//! [--known DIR] [--relief] [--full-size-steps 100] [--gltf] [--mtlx]`:
//! one phone flash photo → maps of a named BRDF model. The fit is the
//! library's `photomat_capture::capture_with_prior` (docs/capture.md): from constant maps, or,
//! with `--prior` or `--model`, from the model folder's generator prior when the folder has an
//! estimator for SPEC; with `--brdf auto`, `photomat_capture::capture_auto` chooses the model
//! among the folder's estimators. This command
//! reads the file, locks DIR, shows progress and writes DIR/material/ (loadable by every
//! command), DIR/export/ (renderer textures, and the glTF / MaterialX documents asked for),
//! DIR/sheet.png (photo | [M's relighting | E's maps] | re-render | ×4 error),
//! DIR/relit.png (the maps under eight new flash positions) and DIR/capture.json (geometry,
//! highlight, gain, losses, timings).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use candle_core::Device;
use photomat_capture::{
    CaptureOptions, Exports, FOV_RANGE, GanPrior, PriorOptions, capture_auto, capture_with_prior,
    write_capture,
};
use photomat_core::map_files::load_maps;
use photomat_core::{Brdf, FolderLock, MaterialMaps, lookup};
use photomat_estimator::sample::choice::DEFAULT_TOLERANCE;

use crate::common::{model_dir, parse_pair, steps_bar};

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

    /// Output folder (created and locked while it is written).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Side of the maps: the photo is resampled to N² before fitting [default: 256].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(16..=2048))]
    pub size: Option<u32>,

    /// Optimisation steps [default: 400].
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
    /// capture` with the generator prior").
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

/// The maps of the material folder `dir` that `brdf` takes (the others are named in a note
/// on `out`); a folder that holds none of them is an error.
fn known_maps(dir: &Path, brdf: &Brdf, out: &mut dyn Write) -> anyhow::Result<MaterialMaps> {
    let loaded = load_maps(dir, None)
        .with_context(|| format!("--known: cannot load '{}'", dir.display()))?;
    let takes: Vec<&str> = brdf.params().iter().map(|p| p.name).collect();
    let mut held = MaterialMaps::new();
    let mut skipped = Vec::new();
    for (name, map) in loaded.maps.iter() {
        if takes.contains(&name) {
            held.insert(name, map.clone());
        } else {
            skipped.push(name);
        }
    }
    if held.names().is_empty() {
        bail!(
            "--known: '{}' has none of {}'s maps ({}); it has {}",
            dir.display(),
            brdf.name(),
            takes.join(", "),
            loaded.maps.names().join(", ")
        );
    }
    if !skipped.is_empty() {
        writeln!(
            out,
            "note: --known: {} of '{}' not held ({} does not take them)",
            skipped.join(", "),
            dir.display(),
            brdf.name()
        )?;
    }
    Ok(held)
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
    let auto = args.brdf.trim() == "auto";
    let brdf = if auto {
        None
    } else {
        Some(lookup(&args.brdf).context("invalid --brdf")?)
    };
    let bytes = std::fs::read(&args.photo)
        .with_context(|| format!("cannot read '{}'", args.photo.display()))?;
    let known_maps = match (&args.known, &brdf) {
        (None, _) => None,
        (Some(_), None) => bail!("--known needs a named --brdf: `auto` chooses the model later"),
        (Some(dir), Some(brdf)) => Some(known_maps(dir, brdf, out)?),
    };
    let defaults = CaptureOptions::default();
    let options = CaptureOptions {
        known_maps,
        size: args.size.map_or(defaults.size, |n| n as usize),
        steps: args.steps.map_or(defaults.steps, |k| k as usize),
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
    let prior = match &brdf {
        _ if !(auto || args.prior || args.model.is_some()) => None,
        None => {
            let dir = model_dir(args.model.as_deref())?;
            Some(GanPrior::open_all(&dir, &Device::Cpu)?)
        }
        Some(brdf) => {
            let dir = model_dir(args.model.as_deref())?;
            let prior = GanPrior::open(&dir, brdf, &Device::Cpu)?;
            if prior.is_none() {
                writeln!(
                    out,
                    "note: '{}' has no estimator for {}: fitting from constant maps (train one \
                     with `photomat train-estimator --gan {0} --brdf '{1}' --out {0}/estimators/NAME`)",
                    dir.display(),
                    brdf.name()
                )?;
            }
            prior
        }
    };
    let _lock = FolderLock::acquire(&args.out, "photomat capture")?;
    let prior_steps = if prior.is_some() {
        prior_options.steps
    } else {
        0
    };
    let bar = steps_bar((prior_steps + options.steps) as u64, 0);
    let name = args.photo.display().to_string();
    let prior_arg = prior.as_ref().map(|p| (p, &prior_options));
    let mut show = |step: usize, loss: f64| {
        let phase = if step <= prior_steps {
            "inversion"
        } else {
            "refinement"
        };
        bar.set_position(step as u64);
        bar.set_message(format!("{phase} loss {loss:.4}"));
    };
    let result = match (&brdf, prior_arg) {
        (Some(brdf), prior_arg) => {
            capture_with_prior(&bytes, &name, brdf, &options, prior_arg, &mut show)
        }
        (None, Some(prior_arg)) => capture_auto(
            &bytes,
            &name,
            &options,
            prior_arg,
            args.tolerance,
            &mut show,
        ),
        (None, None) => unreachable!("--brdf auto always opens the model folder"),
    };
    bar.finish_and_clear();
    let result = result?;
    let exports = Exports {
        gltf: args.gltf,
        mtlx: args.mtlx,
    };
    let textures = write_capture(&result, &args.out, exports)?;
    let (row, col) = result.highlight.pixel;
    writeln!(
        out,
        "captured {} as {} ({}², a square of {:.3} at flash height 1 from a {:.1}° field of view ({}); \
         flash above pixel ({row:.1}, {col:.1}) by {}, gain {:.3}{}): \
         loss {:.4} → {:.4} in {} steps, {:.1} s",
        name,
        result.brdf.name(),
        options.size,
        result.side,
        result.fov.degrees,
        result.fov.source,
        result.highlight.source,
        result.gain,
        result
            .vignetting
            .map_or(String::new(), |a| format!(", vignetting {a:.3}"))
            + &result
                .ambient
                .map_or(String::new(), |c| format!(", ambient {c:.3}")),
        result.losses.first().copied().unwrap_or(f64::NAN),
        result.losses.last().copied().unwrap_or(f64::NAN),
        result.losses.len(),
        result.seconds
    )?;
    if let Some(coarse) = &result.coarse {
        writeln!(
            out,
            "  of which {} steps at {}² in {:.1} s, the last {} at {}²",
            coarse.steps,
            coarse.size,
            coarse.seconds,
            result.losses.len() - coarse.steps,
            options.size
        )?;
    }
    if let Some(prior) = &result.prior {
        let inversion = &prior.inversion;
        writeln!(
            out,
            "  generator prior from {}: inversion loss {:.4} → {:.4} in {} steps, {:.1} s",
            prior.model,
            inversion.losses.first().copied().unwrap_or(f64::NAN),
            inversion.losses.last().copied().unwrap_or(f64::NAN),
            inversion.losses.len(),
            inversion.seconds
        )?;
    }
    if let Some(selection) = &result.selection {
        let errors: Vec<String> = selection
            .candidates
            .iter()
            .map(|c| format!("{} {:.4}", c.brdf, c.l1_linear))
            .collect();
        writeln!(
            out,
            "  --brdf auto (tolerance {}): {} of {} (linear L1 of E's maps: {})",
            selection.tolerance,
            selection.chosen,
            selection.candidates.len(),
            errors.join(", ")
        )?;
    }
    let dir = args.out.display();
    writeln!(
        out,
        "  {dir}/material/  the maps (photomat render --maps {dir}/material --orbit 8)"
    )?;
    let documents = match (args.gltf, args.mtlx) {
        (true, true) => " and material.{gltf,mtlx}",
        (true, false) => " and material.gltf",
        (false, true) => " and material.mtlx",
        (false, false) => "",
    };
    writeln!(
        out,
        "  {dir}/export/  renderer textures ({}){documents}",
        textures.files().join(", ")
    )?;
    let panels = if result.prior.is_some() {
        "photo | M's relighting | E's maps | re-render | ×4 error"
    } else {
        "photo | re-render | ×4 error"
    };
    writeln!(out, "  {dir}/sheet.png  {panels}")?;
    writeln!(
        out,
        "  {dir}/relit.png  the maps under eight new flash positions"
    )?;
    writeln!(
        out,
        "  {dir}/capture.json  geometry, highlight, gain, losses, timings"
    )?;
    Ok(())
}
