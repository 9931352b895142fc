//! The library's contact sheet, `contact_sheet.png`: a sample of its materials, spread over
//! the index, each as diffuse | normal | roughness | height | its render under a flash above
//! the centre of the photo's square (photomat's own renderer), so that a person can see what
//! was imported at a glance (docs/data.md, "Looking at the library").

use std::path::Path;

use candle_core::{DType, Device};
use photomat_core::flash::PHOTO_SIDE;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::previews::map_previews;
use photomat_core::sheet::{grid, resize_square};
use photomat_core::{FlashGeometry, Highlight, encode_display, render_radiance_with};

use crate::index::{LibraryIndex, folders};

/// The sheet's file at the library's root.
pub const SHEET_FILE: &str = "contact_sheet.png";
/// Materials on the sheet: 24 rows of five tiles, a sample of every part of the index.
pub const SHEET_MATERIALS: usize = 24;
/// Side of each tile.
const TILE: usize = 128;
/// Materials per row of the sheet.
const PER_ROW: usize = 2;

/// The tiles of one material of the library at `dir`: diffuse, normal, roughness, height and
/// a flash render, each [`TILE`]².
pub fn material_tiles(
    dir: &Path,
    entry: &crate::index::IndexEntry,
) -> anyhow::Result<Vec<PlanarImage>> {
    let f = folders(dir, entry);
    let ggx = f.load_ggx()?;
    let height = f.load_height()?;
    let previews = map_previews(ggx.brdf.as_ref(), &ggx.maps)?;
    let pick = |name: &str| {
        previews
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, image)| resize_square(image, TILE))
    };
    let height_preview = map_previews(height.brdf.as_ref(), &height.maps)?
        .into_iter()
        .find(|(n, _)| n == "height")
        .map(|(_, image)| resize_square(&image, TILE));
    let side = ggx.maps.batch_and_size()?.1;
    let geometry = FlashGeometry::with_side(
        &[Highlight::new(0.0, 0.0)],
        side,
        PHOTO_SIDE,
        DType::F32,
        &Device::Cpu,
    )?;
    let render = encode_display(&render_radiance_with(
        ggx.brdf.as_ref(),
        &ggx.maps,
        &geometry,
    )?)?;
    let render = resize_square(&PlanarImage::from_tensor(&render.squeeze(0)?)?, TILE);
    Ok([
        pick("diffuse"),
        pick("normal"),
        pick("roughness"),
        height_preview,
        Some(render),
    ]
    .into_iter()
    .flatten()
    .collect())
}

/// Writes the sheet of [`SHEET_MATERIALS`] materials of the library at `dir`, evenly spaced
/// over its index.
pub fn write_contact_sheet(dir: &Path, index: &LibraryIndex) -> anyhow::Result<()> {
    let n = index.materials.len();
    let shown = SHEET_MATERIALS.min(n);
    let mut tiles = Vec::new();
    for k in 0..shown {
        let entry = &index.materials[k * n / shown];
        tiles.push(material_tiles(dir, entry)?);
    }
    let rows: Vec<Vec<PlanarImage>> = tiles.chunks(PER_ROW).map(|c| c.concat()).collect();
    // The last row may hold fewer materials: pad it with black tiles to the sheet's width.
    let width = rows.first().map_or(0, Vec::len);
    let rows: Vec<Vec<PlanarImage>> = rows
        .into_iter()
        .map(|mut row| {
            row.resize(width, PlanarImage::filled(3, TILE, TILE, 0.0));
            row
        })
        .collect();
    write_png(&dir.join(SHEET_FILE), &grid(&rows, 0.0)?, PngBits::Eight)?;
    Ok(())
}
