//! Sheets of equal-size images: the one grid layout behind every PNG sheet photomat writes
//! (sample contact sheets, training panels and sample grids, orbit sheets), and the square
//! resize that fits renders and map previews to a sheet's tile size, and the centre crop that
//! shows a large image's texels one to one in a tile.
//!
//! Tiles are laid out left to right, top to bottom, [`CONTACT_SHEET_GAP`] pixels of a
//! background value between them and no outer border.

use crate::image_io::PlanarImage;
use crate::{Error, Result};

/// Gap between sheet tiles, in pixels.
pub const CONTACT_SHEET_GAP: usize = 4;

/// Rows of tiles, one row per inner vector; rows may differ in length (the sheet is as wide
/// as the longest, short rows leave `background`). Every tile must have the shape of the first.
///
/// # Shapes
/// tiles (C, h, w), `rows` rows, at most `cols` per row →
/// (C, rows·h + (rows−1)·gap, cols·w + (cols−1)·gap).
pub fn grid(rows: &[Vec<PlanarImage>], background: f32) -> Result<PlanarImage> {
    let first = rows
        .iter()
        .flatten()
        .next()
        .ok_or_else(|| Error::Invalid("an image sheet needs at least one image".into()))?;
    let (c, h, w) = (first.channels, first.height, first.width);
    if let Some(t) = rows
        .iter()
        .flatten()
        .find(|t| (t.channels, t.height, t.width) != (c, h, w))
    {
        return Err(Error::Invalid(format!(
            "image sheet tiles differ in shape: {c}×{h}×{w} and {}×{}×{}",
            t.channels, t.height, t.width
        )));
    }
    let gap = CONTACT_SHEET_GAP;
    let columns = rows.iter().map(Vec::len).max().unwrap_or(1);
    let (sheet_h, sheet_w) = (rows.len() * (h + gap) - gap, columns * (w + gap) - gap);
    let mut sheet = PlanarImage::filled(c, sheet_h, sheet_w, background);
    for (r, row) in rows.iter().enumerate() {
        for (k, tile) in row.iter().enumerate() {
            let (top, left) = (r * (h + gap), k * (w + gap));
            for ch in 0..c {
                for y in 0..h {
                    let src = (ch * h + y) * w;
                    let dst = (ch * sheet_h + top + y) * sheet_w + left;
                    sheet.data[dst..dst + w].copy_from_slice(&tile.data[src..src + w]);
                }
            }
        }
    }
    Ok(sheet)
}

/// Columns and rows of a contact sheet of `n` tiles: ⌈√n⌉ columns, as many rows as needed.
pub fn contact_sheet_grid(n: usize) -> (usize, usize) {
    let columns = (1..=n.max(1)).find(|c| c * c >= n).unwrap_or(1);
    (columns, n.div_ceil(columns).max(1))
}

/// Tiles of equal size and channel count laid out row by row on a [`contact_sheet_grid`]
/// ([`grid`] of rows of ⌈√n⌉ tiles).
///
/// # Shapes
/// n tiles of (C, h, w) → (C, rows·h + (rows−1)·gap, cols·w + (cols−1)·gap).
pub fn contact_sheet(tiles: &[PlanarImage], background: f32) -> Result<PlanarImage> {
    if tiles.is_empty() {
        return Err(Error::Invalid(
            "a contact sheet needs at least one image".into(),
        ));
    }
    let (columns, _) = contact_sheet_grid(tiles.len());
    let rows: Vec<Vec<PlanarImage>> = tiles.chunks(columns).map(<[_]>::to_vec).collect();
    grid(&rows, background)
}

/// `image` resized to `side`×`side` (square in, square out): the mean of the source texels
/// each output pixel covers when shrinking, nearest texel when enlarging (sharp previews).
///
/// # Shapes
/// (C, h, w) → (C, side, side).
pub fn resize_square(image: &PlanarImage, side: usize) -> PlanarImage {
    let (h, w) = (image.height, image.width);
    if (h, w) == (side, side) {
        return image.clone();
    }
    let span = |i: usize, from: usize| {
        let lo = i * from / side;
        let hi = ((i + 1) * from).div_ceil(side).max(lo + 1).min(from);
        lo..hi
    };
    let mut out = PlanarImage::filled(image.channels, side, side, 0.0);
    for c in 0..image.channels {
        for y in 0..side {
            let rows = span(y, h);
            for x in 0..side {
                let cols = span(x, w);
                let n = (rows.len() * cols.len()) as f32;
                let sum: f32 = rows
                    .clone()
                    .flat_map(|r| cols.clone().map(move |col| (r, col)))
                    .map(|(r, col)| image.get(c, r, col))
                    .sum();
                out.data[(c * side + y) * side + x] = sum / n;
            }
        }
    }
    out
}

/// The `side`×`side` window at the centre of a square `image`, texel for texel (a large
/// material's fine structure, which [`resize_square`] averages away in a small tile); an image
/// no larger than `side` is [`resize_square`]d instead.
///
/// # Shapes
/// (C, n, n) → (C, side, side); the window starts at row and column (n − side)/2 (rounded
/// down).
pub fn centre_crop(image: &PlanarImage, side: usize) -> PlanarImage {
    let (h, w) = (image.height, image.width);
    if h <= side || w <= side {
        return resize_square(image, side);
    }
    image
        .window((h - side) / 2, (w - side) / 2, side, side)
        .expect("a window of a side smaller than the image's fits at its centre")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_crop_keeps_the_central_texels_one_to_one() {
        // Texel value = 1000·c + 100·row + col, so every texel says where it came from.
        let (c, n, side) = (2, 9, 4);
        let data = (0..c * n * n)
            .map(|i| (1000 * (i / (n * n)) + 100 * (i / n % n) + i % n) as f32)
            .collect();
        let image = PlanarImage::new(c, n, n, data).unwrap();
        let crop = centre_crop(&image, side);
        assert_eq!((crop.channels, crop.height, crop.width), (c, side, side));
        // (9 − 4)/2 = 2: rows and columns 2 … 5.
        for ch in 0..c {
            for y in 0..side {
                for x in 0..side {
                    let expected = (1000 * ch + 100 * (y + 2) + x + 2) as f32;
                    assert_eq!(crop.get(ch, y, x), expected);
                }
            }
        }
        // No larger than the tile: resized like any other tile.
        let small = PlanarImage::new(1, 2, 2, vec![0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(centre_crop(&small, 4).data, resize_square(&small, 4).data);
    }

    #[test]
    fn contact_sheet_grid_is_near_square() {
        assert_eq!(contact_sheet_grid(1), (1, 1));
        assert_eq!(contact_sheet_grid(4), (2, 2));
        assert_eq!(contact_sheet_grid(5), (3, 2));
        assert_eq!(contact_sheet_grid(8), (3, 3));
        assert_eq!(contact_sheet_grid(10), (4, 3));
    }

    #[test]
    fn contact_sheet_places_tiles_row_major() {
        let tiles: Vec<_> = (0..3)
            .map(|k| PlanarImage::filled(1, 2, 3, k as f32 + 1.0))
            .collect();
        let sheet = contact_sheet(&tiles, 0.0).unwrap();
        assert_eq!(
            (sheet.height, sheet.width),
            (2 * 2 + CONTACT_SHEET_GAP, 2 * 3 + CONTACT_SHEET_GAP)
        );
        assert_eq!(sheet.get(0, 0, 0), 1.0);
        assert_eq!(sheet.get(0, 1, 3 + CONTACT_SHEET_GAP), 2.0);
        assert_eq!(sheet.get(0, 2 + CONTACT_SHEET_GAP, 2), 3.0);
        assert_eq!(
            sheet.get(0, 2 + CONTACT_SHEET_GAP, 3 + CONTACT_SHEET_GAP),
            0.0
        );
        assert_eq!(sheet.get(0, 0, 3), 0.0);
    }

    #[test]
    fn grid_lays_out_rows_of_any_length_with_gaps() {
        let tile = |v| PlanarImage::filled(1, 2, 3, v);
        let sheet = grid(&[vec![tile(1.0), tile(2.0)], vec![tile(3.0)]], 0.5).unwrap();
        let gap = CONTACT_SHEET_GAP;
        assert_eq!((sheet.height, sheet.width), (4 + gap, 6 + gap));
        assert_eq!(sheet.get(0, 0, 3 + gap), 2.0);
        assert_eq!(sheet.get(0, 2 + gap, 0), 3.0);
        assert_eq!(sheet.get(0, 2 + gap, 3 + gap), 0.5);
        assert_eq!(sheet.get(0, 2, 0), 0.5);
        assert!(grid(&[vec![tile(1.0), PlanarImage::filled(1, 2, 2, 0.0)]], 0.0).is_err());
        assert!(grid(&[vec![]], 0.0).is_err());
    }

    #[test]
    fn contact_sheet_is_the_grid_of_its_rows() {
        let tiles: Vec<_> = (0..5)
            .map(|k| PlanarImage::filled(2, 3, 2, k as f32))
            .collect();
        let rows = vec![tiles[..3].to_vec(), tiles[3..].to_vec()];
        assert_eq!(
            contact_sheet(&tiles, 0.25).unwrap(),
            grid(&rows, 0.25).unwrap()
        );
        assert!(contact_sheet(&[], 0.0).is_err());
    }

    #[test]
    fn resize_averages_when_shrinking_and_repeats_when_enlarging() {
        let image = PlanarImage::new(1, 2, 2, vec![0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(resize_square(&image, 1).data, vec![1.5]);
        let big = resize_square(&image, 4);
        assert_eq!(big.get(0, 0, 1), 0.0);
        assert_eq!(big.get(0, 3, 3), 3.0);
        assert_eq!(big.get(0, 2, 1), 2.0);
        assert_eq!(resize_square(&image, 2), image);
    }
}
