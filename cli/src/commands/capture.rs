//! `photomat capture PHOTO --brdf SPEC --out DIR [--size 256] [--steps 400] [--fov 67]
//! [--highlight ROW,COL]`: one phone flash photo → maps of a named BRDF model. The fit is the
//! library's `photomat_capture::capture` (docs/capture.md); this command reads the file, locks
//! DIR, shows progress and writes DIR/material/ (loadable by every command), DIR/sheet.png
//! (photo | re-render | ×4 error), DIR/relit.png (the maps under eight new flash positions) and
//! DIR/capture.json (geometry, highlight, gain, losses, timings).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use photomat_capture::{CaptureOptions, FOV_RANGE, capture, write_capture};
use photomat_core::{FolderLock, lookup};

use crate::common::{parse_pair, steps_bar};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The flash photo (JPEG or PNG; EXIF orientation applied, centre-cropped to a square),
    /// taken straight down with the phone's flash on, as for training photos.
    #[arg(value_name = "PHOTO")]
    pub photo: PathBuf,

    /// BRDF model of the maps, e.g. ggx or "height(ggx)" (`photomat brdfs` lists them).
    #[arg(long, value_name = "SPEC")]
    pub brdf: String,

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
    /// square's size relative to the flash's distance [default: 67, a phone's main camera at
    /// 26 mm equivalent; 90 is the geometry of the training data, docs/conventions.md].
    #[arg(long, value_name = "DEG", value_parser = parse_fov)]
    pub fov: Option<f64>,
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
    let brdf = lookup(&args.brdf).context("invalid --brdf")?;
    let bytes = std::fs::read(&args.photo)
        .with_context(|| format!("cannot read '{}'", args.photo.display()))?;
    let defaults = CaptureOptions::default();
    let options = CaptureOptions {
        size: args.size.map_or(defaults.size, |n| n as usize),
        steps: args.steps.map_or(defaults.steps, |k| k as usize),
        highlight: args.highlight,
        fov_degrees: args.fov.unwrap_or(defaults.fov_degrees),
        ..defaults
    };
    let _lock = FolderLock::acquire(&args.out, "photomat capture")?;
    let bar = steps_bar(options.steps as u64, 0);
    let name = args.photo.display().to_string();
    let result = capture(&bytes, &name, &brdf, &options, &mut |step, loss| {
        bar.set_position(step as u64);
        bar.set_message(format!("loss {loss:.4}"));
    });
    bar.finish_and_clear();
    let result = result?;
    write_capture(&result, &args.out)?;
    let (row, col) = result.highlight.pixel;
    writeln!(
        out,
        "captured {} as {} ({}², a square of {:.3} at flash height 1 from a {}° field of view; \
         flash above pixel ({row:.1}, {col:.1}) by {}, gain {:.3}): \
         loss {:.4} → {:.4} in {} steps, {:.1} s",
        name,
        brdf.name(),
        options.size,
        result.side,
        result.fov_degrees,
        result.highlight.source,
        result.gain,
        result.losses.first().copied().unwrap_or(f64::NAN),
        result.losses.last().copied().unwrap_or(f64::NAN),
        result.losses.len(),
        result.seconds
    )?;
    let dir = args.out.display();
    writeln!(
        out,
        "  {dir}/material/  the maps (photomat render --maps {dir}/material --orbit 8)"
    )?;
    writeln!(out, "  {dir}/sheet.png  photo | re-render | ×4 error")?;
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
