//! Texture files decoded into planar images: PNG (grey, palette, RGB, with or without alpha),
//! JPEG, TGA and DDS (DXT1/3/5, the top mip: 0 A.D.'s terrain caches `*.png.cached.dds`), by
//! the `image` crate, under photomat's pixel limit checked on the header before any pixel is
//! decoded (docs/data.md, "Importing").
//!
//! Values are the stored ones in [0, 1], four channels (RGBA; alpha 1 where the file has none),
//! as [`photomat_core::image_io::PlanarImage`]. What the channels mean is the caller's: a base
//! colour is display-encoded, a normal map holds `0.5·n + 0.5`.

use std::io::Cursor;

use image::{DynamicImage, ImageFormat, ImageReader};
use photomat_core::image_io::{PlanarImage, check_pixel_limit, decode_limits};
use photomat_core::{Error, Result};

/// Extensions of the texture files the importer reads (compared in lower case; `.dds` covers
/// 0 A.D.'s `*.png.cached.dds`).
pub const TEXTURE_EXTENSIONS: [&str; 5] = ["png", "jpg", "jpeg", "tga", "dds"];

/// Whether `path` names a texture file the importer reads.
pub fn is_texture(path: &str) -> bool {
    let lower = path.to_lowercase();
    TEXTURE_EXTENSIONS
        .iter()
        .any(|ext| lower.ends_with(&format!(".{ext}")))
}

/// The format of a texture file from its name, the magic bytes deciding where the name says
/// nothing the `image` crate knows (e.g. a `.cached.dds` it would guess right anyway).
fn format_of(name: &str, bytes: &[u8]) -> Result<ImageFormat> {
    let lower = name.to_lowercase();
    let by_name = ImageFormat::from_path(&lower).ok();
    let by_magic = image::guess_format(bytes).ok();
    // TGA has no magic bytes: only its name says what it is.
    by_magic
        .or(by_name)
        .ok_or_else(|| Error::file(name, "is not a PNG, JPEG, TGA or DDS file"))
}

/// The width and height in the header of the texture `bytes` (`name` for errors), without
/// decoding pixels.
pub fn dimensions(bytes: &[u8], name: &str) -> Result<(usize, usize)> {
    let format = format_of(name, bytes)?;
    let reader = ImageReader::with_format(Cursor::new(bytes), format);
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| Error::file(name, format!("cannot read the image header: {e}")))?;
    Ok((w as usize, h as usize))
}

/// Decodes the texture `bytes` (`name` for errors) into 4 channels of stored values in [0, 1].
pub fn decode_rgba(bytes: &[u8], name: &str) -> Result<PlanarImage> {
    let (w, h) = dimensions(bytes, name)?;
    check_pixel_limit(w as u64, h as u64).map_err(|reason| Error::file(name, reason))?;
    let format = format_of(name, bytes)?;
    let mut reader = ImageReader::with_format(Cursor::new(bytes), format);
    reader.limits(decode_limits());
    let image = reader
        .decode()
        .map_err(|e| Error::file(name, format!("cannot decode: {e}")))?;
    Ok(planar_rgba(&image))
}

/// A decoded image as 4 planar channels in [0, 1].
fn planar_rgba(image: &DynamicImage) -> PlanarImage {
    let rgba = image.to_rgba32f();
    let (w, h) = (rgba.width() as usize, rgba.height() as usize);
    let plane = w * h;
    let mut data = vec![0.0f32; 4 * plane];
    for (i, pixel) in rgba.pixels().enumerate() {
        for c in 0..4 {
            data[c * plane + i] = pixel.0[c].clamp(0.0, 1.0);
        }
    }
    PlanarImage {
        channels: 4,
        height: h,
        width: w,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use photomat_core::image_io::{PngBits, encode_png};

    #[test]
    fn a_grey_png_decodes_to_rgba_with_opaque_alpha() {
        let grey = PlanarImage::new(1, 2, 3, vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]).unwrap();
        let bytes = encode_png(&grey, PngBits::Sixteen).unwrap();
        assert_eq!(dimensions(&bytes, "g.png").unwrap(), (3, 2));
        let rgba = decode_rgba(&bytes, "g.png").unwrap();
        assert_eq!((rgba.channels, rgba.height, rgba.width), (4, 2, 3));
        for c in 0..3 {
            assert!((rgba.get(c, 1, 0) - 0.6).abs() < 1e-4);
        }
        assert_eq!(rgba.get(3, 1, 2), 1.0);
    }

    #[test]
    fn a_file_that_is_no_image_fails_naming_it() {
        let err = decode_rgba(b"plain text", "textures/rock_n.png")
            .unwrap_err()
            .to_string();
        assert!(err.contains("textures/rock_n.png"), "{err}");
    }
}
