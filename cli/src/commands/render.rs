//! `photomat render`: a material folder rendered under the collocated flash
//! (`docs/conventions.md`, "Geometry and radiometry") and
//! written as an 8-bit PNG of display-encoded values (`clamp(x, 0, 1)^(1/2.2)`).
//!
//! `--light X,Y` renders one image with the highlight at (X, Y) in plane coordinates (the
//! material spans [−½, ½]², +y up, so `0,0` is the centre and `-0.5,0.5` the top-left
//! corner). `--orbit N` renders N highlights evenly spaced on a circle of radius `--radius`
//! around the centre, at angles θ_k = 2π(k + ½)/N counter-clockwise from +x (N = 4 gives the
//! reference tool's diagonal positions 45°, 135°, 225°, 315°), and writes them as one contact
//! sheet, row by row, ⌈√N⌉ columns, separated by a small black gap.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use candle_core::{DType, Device};
use clap::ArgGroup;
use photomat_core::flash::PLANE_SIDE;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::lights::DEFAULT_ORBIT_RADIUS;
use photomat_core::map_files::load_maps;
use photomat_core::sheet::contact_sheet;
use photomat_core::{Highlight, LightSet, lookup, render_with};

use crate::common::orbit_lights;

/// Most orbit positions accepted: a sheet of 32×32 renders is already unreadable.
const MAX_ORBIT: u32 = 1024;

#[derive(Debug, clap::Args)]
#[command(group(ArgGroup::new("flash").required(true).args(["light", "orbit"])))]
pub struct Args {
    /// Material folder (material.json next to its PNG/EXR maps).
    #[arg(long, value_name = "DIR")]
    pub maps: PathBuf,

    /// Highlight position in plane coordinates, e.g. 0,0 (centre) or -0.2,0.1; the material
    /// spans [-0.5, 0.5] in x (right) and y (up).
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = parse_light)]
    pub light: Option<Highlight>,

    /// Render N highlights evenly spaced on a circle and write them as one contact sheet.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=MAX_ORBIT as i64))]
    pub orbit: Option<u32>,

    /// Model specification overriding the manifest's, e.g. lambert or height(ggx, scale=0.05)
    /// (the folder must hold every map it takes).
    #[arg(long, value_name = "SPEC")]
    pub brdf: Option<String>,

    /// Radius of the --orbit circle in plane coordinates (0.5 reaches the edge midpoints).
    #[arg(
        long,
        value_name = "R",
        default_value_t = DEFAULT_ORBIT_RADIUS,
        allow_hyphen_values = true
    )]
    pub radius: f64,

    /// Output PNG file.
    #[arg(long, value_name = "FILE.png")]
    pub out: PathBuf,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    check_png_name(&args.out)?;
    let lights = match (args.light, args.orbit) {
        (Some(light), None) => LightSet::single(light),
        (None, Some(n)) => orbit_lights(n, args.radius)?,
        _ => bail!("give exactly one of --light X,Y and --orbit N"),
    };
    let highlights = lights.highlights();
    let brdf = match &args.brdf {
        Some(spec) => Some(lookup(spec).context("invalid --brdf")?),
        None => None,
    };
    let material = load_maps(&args.maps, brdf)
        .with_context(|| format!("cannot load the material in '{}'", args.maps.display()))?;
    let model = material.brdf.name();
    let (_, size, _) = material.maps.batch_and_size()?;
    // Maps of a spatial model record their texel size: the lights are placed relative to the
    // material's own world extent, as `sample` rendered them.
    let side = material
        .maps
        .texel_size()
        .map_or(PLANE_SIDE, |t| t * size as f64);
    // One highlight at a time: the renderer's intermediates scale with the batch, and a
    // 1024² render is a fraction of a second.
    let tiles = highlights
        .iter()
        .map(|h| {
            let geometry =
                LightSet::single(*h).geometry_on(size, side, DType::F32, &Device::Cpu)?;
            let image = render_with(material.brdf.as_ref(), &material.maps, &geometry)
                .with_context(|| {
                    format!("cannot render '{model}' at highlight ({}, {})", h.x, h.y)
                })?;
            Ok(PlanarImage::from_tensor(&image)?)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (width, height) = (tiles[0].width, tiles[0].height);
    let image = if args.orbit.is_some() {
        contact_sheet(&tiles, 0.0)?
    } else {
        tiles.into_iter().next().expect("one highlight")
    };
    write_png(&args.out, &image, PngBits::Eight)?;
    writeln!(
        out,
        "wrote {} ({}×{}): {} render(s) of {width}×{height} texels, model {model}",
        args.out.display(),
        image.width,
        image.height,
        highlights.len(),
    )?;
    Ok(())
}

/// Parse `X,Y` into a highlight position.
pub fn parse_light(text: &str) -> Result<Highlight, String> {
    let usage =
        || format!("expected X,Y (two numbers separated by a comma, e.g. 0.1,-0.2), got '{text}'");
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y] = parts.as_slice() else {
        return Err(usage());
    };
    let (Ok(x), Ok(y)) = (x.parse::<f64>(), y.parse::<f64>()) else {
        return Err(usage());
    };
    if !(x.is_finite() && y.is_finite()) {
        return Err(format!(
            "the highlight position must be finite, got '{text}'"
        ));
    }
    Ok(Highlight::new(x, y))
}

/// Renders are written as PNG: refuse names that promise another format.
fn check_png_name(path: &Path) -> anyhow::Result<()> {
    let is_png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        bail!("--out must name a .png file, got '{}'", path.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_light_accepts_signed_numbers() {
        assert_eq!(parse_light("-0.2,0.1").unwrap(), Highlight::new(-0.2, 0.1));
        assert_eq!(parse_light(" 0 , 1e-1 ").unwrap(), Highlight::new(0.0, 0.1));
    }

    #[test]
    fn parse_light_rejects_malformed_text() {
        for bad in ["", "0.1", "0.1,0.2,0.3", "a,b", "0.1;0.2", "inf,0", "NaN,0"] {
            let err = parse_light(bad).unwrap_err();
            assert!(err.contains(bad), "{bad}: {err}");
        }
    }
}
