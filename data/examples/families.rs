//! Look at the procedural families: renders every family under a centred phone flash for a
//! few seeds, writes one contact sheet per family (renders, then the maps of the first seed)
//! and one overview sheet (a row per family), and prints the generation time per material.
//!
//! ```text
//! cargo run -p photomat-data --example families -- [OUT_DIR] [SIZE] [SEEDS]
//! ```
//! Defaults: `/tmp/photomat-families`, 256, 4.

use std::path::PathBuf;
use std::time::Instant;

use candle_core::Device;
use photomat_brdfs as _; // link the built-in BRDF plugins
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::sheet::contact_sheet;
use photomat_core::{Highlight, encode_display, lookup, render};
use photomat_data::procedural::families;

/// Gap between images of a sheet, in pixels.
const GAP: usize = 4;

/// Images of equal shape laid out as `rows`, GAP pixels of black between them.
fn grid(rows: &[Vec<PlanarImage>]) -> PlanarImage {
    let first = &rows[0][0];
    let (c, h, w) = (first.channels, first.height, first.width);
    let columns = rows.iter().map(Vec::len).max().unwrap_or(1);
    let (sheet_h, sheet_w) = (rows.len() * (h + GAP) - GAP, columns * (w + GAP) - GAP);
    let mut sheet = PlanarImage::filled(c, sheet_h, sheet_w, 0.0);
    for (r, row) in rows.iter().enumerate() {
        for (k, tile) in row.iter().enumerate() {
            for ch in 0..c {
                for y in 0..h {
                    let src = (ch * h + y) * w;
                    let dst = (ch * sheet_h + r * (h + GAP) + y) * sheet_w + k * (w + GAP);
                    sheet.data[dst..dst + w].copy_from_slice(&tile.data[src..src + w]);
                }
            }
        }
    }
    sheet
}

/// A map as a 3-channel display image: colours gamma-encoded, scalars as grey.
fn preview(map: &candle_core::Tensor, gamma: bool) -> photomat_core::Result<PlanarImage> {
    let image = PlanarImage::from_tensor(map)?;
    let image = if image.channels == 1 {
        PlanarImage::new(3, image.height, image.width, image.data.repeat(3))?
    } else {
        image
    };
    Ok(if gamma {
        PlanarImage::from_tensor(&encode_display(&image.to_tensor(&Device::Cpu)?)?)?
    } else {
        image
    })
}

fn main() -> photomat_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = PathBuf::from(
        args.first()
            .map_or("/tmp/photomat-families", String::as_str),
    );
    let size: usize = args
        .get(1)
        .map_or(Ok(256), |s| s.parse())
        .expect("SIZE: a number");
    let seeds: u64 = args
        .get(2)
        .map_or(Ok(4), |s| s.parse())
        .expect("SEEDS: a number");
    std::fs::create_dir_all(&out).map_err(|e| photomat_core::Error::file(&out, e))?;
    let device = Device::Cpu;
    let mut overview = Vec::new();
    for family in families() {
        let brdf = lookup(&family.brdf())?;
        let (mut renders, mut seconds, mut first_maps) = (Vec::new(), 0.0, None);
        for seed in 0..seeds {
            let start = Instant::now();
            let maps = family.generate(size, seed, &device)?;
            seconds += start.elapsed().as_secs_f64();
            let image = render(brdf.as_ref(), &maps, &[Highlight::CENTER])?;
            renders.push(PlanarImage::from_tensor(&image)?);
            first_maps.get_or_insert(maps);
        }
        let maps = first_maps.expect("at least one seed");
        let mut previews = Vec::new();
        for (name, map) in maps.iter() {
            previews.push(preview(
                map,
                !name.starts_with("rough") && name != "height",
            )?);
        }
        let path = out.join(format!("{}.png", family.name()));
        write_png(&path, &grid(&[renders.clone(), previews]), PngBits::Eight)?;
        println!(
            "{:<14} {:<28} {:>7.1} ms per {size}² material  {}",
            family.name(),
            brdf.name(),
            1e3 * seconds / seeds as f64,
            path.display()
        );
        overview.push(renders);
    }
    let path = out.join("families.png");
    write_png(&path, &grid(&overview), PngBits::Eight)?;
    // Also a square sheet of every family's first seed, for a quick look.
    let firsts: Vec<PlanarImage> = overview.iter().map(|r| r[0].clone()).collect();
    write_png(
        &out.join("first-seeds.png"),
        &contact_sheet(&firsts, 0.0)?,
        PngBits::Eight,
    )?;
    println!(
        "overview (a row per family, a column per seed): {}",
        path.display()
    );
    Ok(())
}
