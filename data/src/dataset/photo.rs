//! Reading one flash photo for `photomat prepare`: format sniffing, JPEG sanity checks, EXIF
//! orientation, centre crop to a square and a linear-light resize to the working size.
//!
//! Reads JPEG and PNG, 8- or 16-bit, grey, grey+alpha, RGB or RGBA (alpha is dropped, grey is
//! replicated). Every way a file can be unusable is a [`Rejection`] with a reason a person
//! can act on; nothing here panics on bad input (the prepare loop also catches decoder panics).
//!
//! Colour: photos are treated as gamma-2.2 encoded (`docs/conventions.md`, "Image values").
//! Resizing averages light, so it runs on linearised values (Lanczos3, the `image` crate's
//! resampler), and the result is re-encoded with gamma 2.2 and quantised to 8 bits, exactly what
//! the dataset stores.

use std::io::Cursor;

use image::imageops::FilterType;
use image::metadata::Orientation;
use image::{DynamicImage, ImageDecoder, ImageFormat, ImageReader, Rgb32FImage};
use photomat_core::image_io::{self, PlanarImage};
use photomat_core::render::DISPLAY_GAMMA;

/// Why a file is not in the dataset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rejection(pub String);

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

fn reject<T>(reason: impl Into<String>) -> Result<T, Rejection> {
    Err(Rejection(reason.into()))
}

/// How a photo becomes a square image of the working size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Framing {
    /// Side of the prepared image.
    pub size: usize,
    /// Reject non-square photos instead of centre-cropping them.
    pub reject_non_square: bool,
}

impl Framing {
    /// Smallest accepted side of a photo: a quarter of the working size. Upscaling by more
    /// than 4× invents three quarters of every pixel row; such a photo only blurs the dataset.
    pub fn min_side(&self) -> usize {
        self.size.div_ceil(4).max(1)
    }
}

/// A decoded, oriented, cropped and resized photo.
#[derive(Debug, Clone)]
pub struct PreparedPhoto {
    /// (3, size, size) display values, quantised to 8-bit levels (`k/255`).
    pub image: PlanarImage,
    /// `[width, height]` of the photo after orientation, before cropping.
    pub source_size: [usize; 2],
    /// Maps continuous `(row, col)` of the photo *as stored in the file* (before orientation)
    /// to the prepared image.
    pub transform: PixelTransform,
}

/// The orientation + crop + scale a prepared image went through, for moving points with it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelTransform {
    /// Size `(width, height)` of the photo as stored in the file.
    pub stored: (usize, usize),
    pub orientation: Orientation,
    /// Top-left `(row, col)` of the square crop in the oriented photo.
    pub crop_origin: (usize, usize),
    /// Side of the square crop.
    pub crop_side: usize,
    /// Side of the prepared image.
    pub size: usize,
}

impl PixelTransform {
    /// Continuous `(row, col)` of the stored photo → continuous `(row, col)` of the prepared
    /// image (pixel (i, j) spans [i, i+1)×[j, j+1)).
    pub fn apply(&self, row: f64, col: f64) -> (f64, f64) {
        let (w, h) = (self.stored.0 as f64, self.stored.1 as f64);
        // `image`'s orientations: Rotate90 is clockwise; the *FlipH ones rotate, then flip.
        let (r, c) = match self.orientation {
            Orientation::NoTransforms => (row, col),
            Orientation::Rotate90 => (col, h - row),
            Orientation::Rotate180 => (h - row, w - col),
            Orientation::Rotate270 => (w - col, row),
            Orientation::FlipHorizontal => (row, w - col),
            Orientation::FlipVertical => (h - row, col),
            Orientation::Rotate90FlipH => (col, row),
            Orientation::Rotate270FlipH => (w - col, h - row),
        };
        let scale = self.size as f64 / self.crop_side as f64;
        (
            (r - self.crop_origin.0 as f64) * scale,
            (c - self.crop_origin.1 as f64) * scale,
        )
    }
}

/// Decode `bytes` (the content of one file) and prepare it with `framing`.
pub fn prepare_photo(bytes: &[u8], framing: Framing) -> Result<PreparedPhoto, Rejection> {
    let format = sniff(bytes)?;
    if format == ImageFormat::Jpeg {
        check_jpeg(bytes)?;
    }
    let name = format_name(format);
    let mut reader = ImageReader::new(Cursor::new(bytes));
    reader.set_format(format);
    reader.limits(image_io::decode_limits());
    let mut decoder = reader
        .into_decoder()
        .or_else(|e| reject(format!("corrupt {name}: {e}")))?;
    let (w0, h0) = decoder.dimensions();
    // The header's size before any pixel buffer: a small file may claim 65000×65000.
    image_io::check_pixel_limit(w0 as u64, h0 as u64).map_err(Rejection)?;
    let (w0, h0) = (w0 as usize, h0 as usize);
    let min_side = framing.min_side();
    if w0.min(h0) < min_side {
        return reject(format!(
            "too small: {w0}×{h0} pixels; the shorter side must be at least {min_side} \
             (a quarter of the {0}² working size)",
            framing.size
        ));
    }
    if framing.reject_non_square && w0 != h0 {
        return reject(format!(
            "not square ({w0}×{h0}) and --reject-non-square was given"
        ));
    }
    // A malformed Exif block is not worth losing the photo: read it as "no rotation".
    let orientation = decoder.orientation().unwrap_or(Orientation::NoTransforms);
    let mut image = DynamicImage::from_decoder(decoder).or_else(|e| {
        reject(match e {
            image::ImageError::Unsupported(u) => format!("unsupported {name}: {u}"),
            e => format!("corrupt {name}: {e}"),
        })
    })?;
    image.apply_orientation(orientation);
    let (w, h) = (image.width() as usize, image.height() as usize);
    let side = w.min(h);
    let crop_origin = ((h - side) / 2, (w - side) / 2);
    let cropped = image.crop_imm(
        crop_origin.1 as u32,
        crop_origin.0 as u32,
        side as u32,
        side as u32,
    );
    let planar = resize_linear(cropped.into_rgb32f(), framing.size);
    Ok(PreparedPhoto {
        image: planar,
        source_size: [w, h],
        transform: PixelTransform {
            stored: (w0, h0),
            orientation,
            crop_origin,
            crop_side: side,
            size: framing.size,
        },
    })
}

/// The file's format from its first bytes, or why it is not a photo photomat reads.
fn sniff(bytes: &[u8]) -> Result<ImageFormat, Rejection> {
    if bytes.is_empty() {
        return reject("empty file");
    }
    match image::guess_format(bytes) {
        Ok(f @ (ImageFormat::Jpeg | ImageFormat::Png)) => Ok(f),
        Ok(other) => reject(format!(
            "unsupported image format {}: photos are read as JPEG or PNG",
            other
                .extensions_str()
                .first()
                .unwrap_or(&"?")
                .to_uppercase()
        )),
        Err(_) => reject("not an image: the content is neither JPEG nor PNG"),
    }
}

fn format_name(format: ImageFormat) -> &'static str {
    match format {
        ImageFormat::Png => "PNG",
        _ => "JPEG",
    }
}

/// Checks the decoder (lenient with broken JPEGs, it fills missing data with grey) does not
/// make: the frame must have 1 or 3 components (4 is CMYK/YCCK, whose conversion needs the
/// print profile phones never write) and the file must reach its end-of-image marker.
fn check_jpeg(bytes: &[u8]) -> Result<(), Rejection> {
    let mut i = 2; // after SOI (FF D8), which sniffing checked
    let mut components = None;
    loop {
        // Markers may be preceded by any number of FF fill bytes.
        while i < bytes.len() && bytes[i] == 0xFF && bytes.get(i + 1) == Some(&0xFF) {
            i += 1;
        }
        if i + 4 > bytes.len() {
            return reject("truncated JPEG: the file ends inside its headers");
        }
        if bytes[i] != 0xFF {
            return reject(format!("corrupt JPEG: no marker at byte {i}"));
        }
        let marker = bytes[i + 1];
        let length = u16::from_be_bytes([bytes[i + 2], bytes[i + 3]]) as usize;
        if length < 2 || i + 2 + length > bytes.len() {
            return reject(format!(
                "truncated JPEG: segment FF{marker:02X} at byte {i} runs past the end of the file"
            ));
        }
        let segment = &bytes[i + 4..i + 2 + length];
        // SOF0–SOF15 except DHT (C4), JPG (C8) and DAC (CC): the frame header.
        if (0xC0..=0xCF).contains(&marker) && !matches!(marker, 0xC4 | 0xC8 | 0xCC) {
            components = segment.get(5).copied();
            if let Some(n) = components
                && n == 4
            {
                return reject(
                    "unsupported JPEG colour space: 4 components (CMYK or YCCK); \
                     convert the photo to sRGB",
                );
            }
        }
        if marker == 0xDA {
            // Start of scan: entropy-coded data follows. Inside it FF is always followed by
            // 00 (stuffing), a restart marker or another marker, so FF D9 is the real end.
            if components.is_none() {
                return reject("corrupt JPEG: scan data before any frame header");
            }
            let data = &bytes[i + 2 + length..];
            if data.windows(2).any(|w| w == [0xFF, 0xD9]) {
                return Ok(());
            }
            return reject(
                "truncated JPEG: no end-of-image marker (the file ends inside the image data)",
            );
        }
        i += 2 + length;
    }
}

/// Linearise (gamma 2.2), resize to `size`² with Lanczos3 (skipped when already that size),
/// clamp the filter's ringing to [0, 1], re-encode and quantise to 8-bit levels.
fn resize_linear(mut image: Rgb32FImage, size: usize) -> PlanarImage {
    for v in image.iter_mut() {
        *v = v.clamp(0.0, 1.0).powf(DISPLAY_GAMMA as f32);
    }
    let resized = if image.width() as usize == size && image.height() as usize == size {
        image
    } else {
        image::imageops::resize(&image, size as u32, size as u32, FilterType::Lanczos3)
    };
    let plane = size * size;
    let mut out = PlanarImage::filled(3, size, size, 0.0);
    let inverse = (1.0 / DISPLAY_GAMMA) as f32;
    for (t, pixel) in resized.pixels().enumerate() {
        for c in 0..3 {
            let encoded = pixel.0[c].clamp(0.0, 1.0).powf(inverse);
            out.data[c * plane + t] = (encoded * 255.0).round() / 255.0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_transform_matches_image_orientation() {
        // Mark one pixel of a 5×3 (w×h) image, orient it with `image`, and check that the
        // transform moves the pixel's centre to the marked pixel's centre.
        let (w, h) = (5u32, 3u32);
        let (row, col) = (0u32, 1u32);
        for orientation in [
            Orientation::NoTransforms,
            Orientation::Rotate90,
            Orientation::Rotate180,
            Orientation::Rotate270,
            Orientation::FlipHorizontal,
            Orientation::FlipVertical,
            Orientation::Rotate90FlipH,
            Orientation::Rotate270FlipH,
        ] {
            let mut img = image::GrayImage::new(w, h);
            img.put_pixel(col, row, image::Luma([255]));
            let mut dynamic = DynamicImage::ImageLuma8(img);
            dynamic.apply_orientation(orientation);
            let (ow, oh) = (dynamic.width() as usize, dynamic.height() as usize);
            let t = PixelTransform {
                stored: (w as usize, h as usize),
                orientation,
                crop_origin: (0, 0),
                crop_side: 1,
                size: 1,
            };
            let (r, c) = t.apply(row as f64 + 0.5, col as f64 + 0.5);
            let (ri, ci) = (r.floor() as u32, c.floor() as u32);
            assert!((ri as usize) < oh && (ci as usize) < ow, "{orientation:?}");
            assert_eq!(
                dynamic.to_luma8().get_pixel(ci, ri).0[0],
                255,
                "{orientation:?}: moved to ({r}, {c})"
            );
        }
    }

    #[test]
    fn check_jpeg_finds_truncation_and_cmyk() {
        let rgb = image::RgbImage::from_pixel(16, 16, image::Rgb([200, 100, 50]));
        let mut jpeg = Vec::new();
        image::codecs::jpeg::JpegEncoder::new(&mut jpeg)
            .encode_image(&rgb)
            .unwrap();
        assert_eq!(check_jpeg(&jpeg), Ok(()));
        let truncated = check_jpeg(&jpeg[..jpeg.len() - 10]).unwrap_err();
        assert!(truncated.0.starts_with("truncated JPEG"), "{truncated}");
        let headers_only = check_jpeg(&jpeg[..40]).unwrap_err();
        assert!(
            headers_only.0.starts_with("truncated JPEG"),
            "{headers_only}"
        );
    }
}
