//! `photomat demo`: the bundled default job before any trained model exists. Generates a
//! procedural, tileable material of one of the simulator's families (glazed tiles by default),
//! writes it as a material folder and shows it: a render under the centred flash, an orbit
//! contact sheet, and a sheet of its maps (e.g. diffuse, specular, roughness, derived normal,
//! height).

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use candle_core::Device;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::lights::DEFAULT_ORBIT_RADIUS;
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::previews::map_previews;
use photomat_core::sheet::contact_sheet;
use photomat_core::{Highlight, LightSet, lookup, render};
use photomat_data::procedural::{family, family_names};

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (created): material/, render.png, orbit.png, maps.png.
    #[arg(long, value_name = "DIR", default_value = "demo")]
    pub out: PathBuf,

    /// Resolution of the material (texels per side).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(8..=4096))]
    pub size: u32,

    // The help text lists the registered families.
    #[arg(long, default_value = "tiles", help = family_help())]
    pub family: String,

    /// Seed of the procedural material: the same seed gives the same material.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,

    /// Highlight positions of the orbit sheet.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub orbit: u32,
}

fn family_help() -> String {
    format!("Procedural family: {}", family_names().join(", "))
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let family = family(&args.family)?;
    let brdf = lookup(&family.brdf())?;
    let size = args.size as usize;
    let maps = family.generate(size, args.seed, &Device::Cpu)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create '{}'", args.out.display()))?;

    let material_dir = args.out.join("material");
    save_maps(&material_dir, brdf.as_ref(), &maps, &SaveOptions::default())?;

    let centre = render(brdf.as_ref(), &maps, &[Highlight::CENTER])?;
    let render_path = args.out.join("render.png");
    write_png(
        &render_path,
        &PlanarImage::from_tensor(&centre)?,
        PngBits::Eight,
    )?;

    let tiles = LightSet::orbit(args.orbit as usize, DEFAULT_ORBIT_RADIUS)?
        .highlights()
        .iter()
        .map(|h| {
            Ok(PlanarImage::from_tensor(&render(
                brdf.as_ref(),
                &maps,
                &[*h],
            )?)?)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let orbit_path = args.out.join("orbit.png");
    write_png(&orbit_path, &contact_sheet(&tiles, 0.0)?, PngBits::Eight)?;

    let maps_path = args.out.join("maps.png");
    let previews = map_previews(brdf.as_ref(), &maps)?;
    write_png(
        &maps_path,
        &contact_sheet(
            &previews.iter().map(|(_, p)| p.clone()).collect::<Vec<_>>(),
            0.0,
        )?,
        PngBits::Eight,
    )?;

    let names: Vec<_> = previews.iter().map(|(n, _)| n.as_str()).collect();
    let paths = [material_dir, render_path, orbit_path, maps_path];
    report(args, family.name(), &brdf.name(), &paths, &names, out)
}

/// The lines after a run: what was written where.
fn report(
    args: &Args,
    family: &str,
    model: &str,
    [material_dir, render_path, orbit_path, maps_path]: &[PathBuf; 4],
    names: &[&str],
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    let size = args.size;
    writeln!(
        out,
        "procedural material '{}' (seed {}, {size}×{size}), model {}",
        family, args.seed, model
    )?;
    writeln!(
        out,
        "  {}  maps: PNG + EXR + material.json",
        material_dir.display()
    )?;
    writeln!(
        out,
        "  {}  render under the centred flash",
        render_path.display()
    )?;
    writeln!(
        out,
        "  {}  {} flash positions on a circle of radius {DEFAULT_ORBIT_RADIUS}",
        orbit_path.display(),
        args.orbit
    )?;
    writeln!(
        out,
        "  {}  maps, left to right: {}",
        maps_path.display(),
        names.join(", ")
    )?;
    writeln!(
        out,
        "next: photomat render --maps {} --light 0.2,-0.1 --out lit.png",
        material_dir.display()
    )?;
    Ok(())
}
