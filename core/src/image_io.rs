//! Image files for photomat: planar f32 images ↔ 8/16-bit PNG and float32 EXR, and atomic
//! file writes. Sheets of images (grids, contact sheets) live in [`crate::sheet`].
//!
//! [`PlanarImage`] is the exchange type: a CHW `Vec<f32>` that converts to and from NCHW
//! tensors. PNG values are the *stored* values in [0, 1] (whatever encoding the caller chose:
//! display gamma, `0.5·n + 0.5`, …); EXR values are written as they are. Channel layouts:
//!
//! | channels | PNG       | EXR channel names            |
//! |----------|-----------|------------------------------|
//! | 1        | grey      | `Y`                          |
//! | 3        | RGB       | `R`, `G`, `B`                |
//! | 4        | RGBA      | `R`, `G`, `B`, `A`           |
//! | other    | –         | `C00`, `C01`, …              |
//!
//! Every writer goes through [`write_atomic`]: the bytes land in a temporary file in the
//! destination's folder and are renamed over the destination, so a reader never sees a
//! half-written file and an interrupted write leaves the previous file intact. Every error
//! names the file and the problem.
//!
//! Every reader checks the size in the file's header against [`MAX_PIXELS`] before it
//! allocates pixels, and decodes under [`decode_limits`]: a few-kilobyte file whose header
//! claims 65000×65000 is an error naming the file and the limit, not a 24 GB allocation.

use std::fs::{self, File};
use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use candle_core::{DType, Device, Tensor};
use image::codecs::png::PngEncoder;
use image::{DynamicImage, ImageBuffer, ImageDecoder, ImageEncoder, ImageFormat, ImageReader};

use crate::{Error, Result};

/// Most pixels (width × height) a photo or map file may have: 100 megapixels, four times a
/// 50 MP phone photo, and as 16-bit RGBA still only 800 MB to decode (`docs/datasets.md`).
pub const MAX_PIXELS: u64 = 100_000_000;

/// Refuse a `width`×`height` header over [`MAX_PIXELS`], with the reason as text.
pub fn check_pixel_limit(width: u64, height: u64) -> std::result::Result<(), String> {
    let pixels = width.saturating_mul(height);
    if pixels > MAX_PIXELS {
        return Err(format!(
            "too large: the header claims {width}×{height} = {pixels} pixels, over photomat's \
             limit of {MAX_PIXELS} ({} megapixels, photomat_core::image_io::MAX_PIXELS)",
            MAX_PIXELS / 1_000_000
        ));
    }
    Ok(())
}

/// The `image` crate's decoding limits matching [`MAX_PIXELS`]: no side beyond it, and no
/// decoder buffer beyond that many 16-bit RGBA pixels (8 bytes each).
pub fn decode_limits() -> image::Limits {
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_PIXELS as u32);
    limits.max_image_height = Some(MAX_PIXELS as u32);
    limits.max_alloc = Some(MAX_PIXELS * 8);
    limits
}

/// Bit depth of a written PNG. Serialised as the number 8 or 16.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "u8", into = "u8")]
pub enum PngBits {
    /// 8 bits per channel: 256 levels, enough for display images and gamma-encoded albedos.
    Eight,
    /// 16 bits per channel: 65 536 levels, keeps linear maps (roughness, height) smooth.
    #[default]
    Sixteen,
}

impl PngBits {
    /// Bits per channel.
    pub fn bits(self) -> u8 {
        match self {
            PngBits::Eight => 8,
            PngBits::Sixteen => 16,
        }
    }

    /// Largest integer sample value (255 or 65 535).
    pub fn max_value(self) -> f32 {
        match self {
            PngBits::Eight => u8::MAX as f32,
            PngBits::Sixteen => u16::MAX as f32,
        }
    }
}

impl From<PngBits> for u8 {
    fn from(bits: PngBits) -> u8 {
        bits.bits()
    }
}

impl TryFrom<u8> for PngBits {
    type Error = String;

    fn try_from(bits: u8) -> std::result::Result<Self, String> {
        match bits {
            8 => Ok(PngBits::Eight),
            16 => Ok(PngBits::Sixteen),
            other => Err(format!("PNG bit depth must be 8 or 16, not {other}")),
        }
    }
}

/// A planar f32 image.
///
/// # Layout
/// `data[(c·height + row)·width + col]`, row 0 at the top: the memory layout of one NCHW
/// tensor item.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarImage {
    pub channels: usize,
    pub height: usize,
    pub width: usize,
    pub data: Vec<f32>,
}

impl PlanarImage {
    /// An image from planar data; error if `data.len() != channels·height·width`.
    pub fn new(channels: usize, height: usize, width: usize, data: Vec<f32>) -> Result<Self> {
        if data.len() != channels * height * width {
            return Err(Error::Invalid(format!(
                "planar image of {channels}×{height}×{width} needs {} values, got {}",
                channels * height * width,
                data.len()
            )));
        }
        Ok(Self {
            channels,
            height,
            width,
            data,
        })
    }

    /// An image with every sample equal to `value`.
    pub fn filled(channels: usize, height: usize, width: usize, value: f32) -> Self {
        Self {
            channels,
            height,
            width,
            data: vec![value; channels * height * width],
        }
    }

    /// From a tensor of shape (C, H, W) or (1, C, H, W), any float dtype, any device.
    pub fn from_tensor(tensor: &Tensor) -> Result<Self> {
        let chw = match tensor.rank() {
            3 => tensor.clone(),
            4 if tensor.dim(0)? == 1 => tensor.squeeze(0)?,
            _ => {
                return Err(Error::Invalid(format!(
                    "an image tensor must be (C, H, W) or (1, C, H, W), got {:?}",
                    tensor.dims()
                )));
            }
        };
        let (channels, height, width) = chw.dims3()?;
        let data = chw.to_dtype(DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
        Self::new(channels, height, width, data)
    }

    /// One image per item of a (B, C, H, W) tensor, any float dtype, any device.
    pub fn batch_from_tensor(batch: &Tensor) -> Result<Vec<Self>> {
        (0..batch.dim(0)?)
            .map(|i| Self::from_tensor(&batch.get(i)?))
            .collect()
    }

    /// As a (1, C, H, W) f32 tensor on `device`.
    pub fn to_tensor(&self, device: &Device) -> Result<Tensor> {
        Ok(Tensor::from_slice(
            &self.data,
            (1, self.channels, self.height, self.width),
            device,
        )?)
    }

    /// The `height`×`width` window whose top-left texel is (`top`, `left`), every channel;
    /// error if it does not fit.
    ///
    /// # Shapes
    /// (C, H, W) → (C, height, width).
    pub fn window(&self, top: usize, left: usize, height: usize, width: usize) -> Result<Self> {
        if top + height > self.height || left + width > self.width {
            return Err(Error::Invalid(format!(
                "a {height}×{width} window at ({top}, {left}) does not fit a {}×{} image",
                self.height, self.width
            )));
        }
        let mut data = Vec::with_capacity(self.channels * height * width);
        for c in 0..self.channels {
            for row in top..top + height {
                let start = (c * self.height + row) * self.width + left;
                data.extend_from_slice(&self.data[start..start + width]);
            }
        }
        Self::new(self.channels, height, width, data)
    }

    /// Sample of channel `c` at (`row`, `col`).
    pub fn get(&self, c: usize, row: usize, col: usize) -> f32 {
        self.data[(c * self.height + row) * self.width + col]
    }

    /// Number of texels (`height·width`).
    pub fn texels(&self) -> usize {
        self.height * self.width
    }

    /// Channel, row and column of flat index `i` into [`Self::data`].
    pub fn position(&self, i: usize) -> (usize, usize, usize) {
        let plane = self.texels();
        (i / plane, (i % plane) / self.width, i % self.width)
    }

    /// Channel 0 alone, as a one-channel image.
    pub fn first_channel(&self) -> Self {
        Self {
            channels: 1,
            data: self.data[..self.texels()].to_vec(),
            ..self.clone()
        }
    }

    /// A one-channel image repeated into `channels` equal channels.
    pub fn repeat_channel(&self, channels: usize) -> Result<Self> {
        if self.channels != 1 {
            return Err(Error::Invalid(format!(
                "only a one-channel image can be repeated into channels, this one has {}",
                self.channels
            )));
        }
        Ok(Self {
            channels,
            data: self.data.repeat(channels),
            ..self.clone()
        })
    }

    /// Bilinear sample of channel `c` at continuous pixel coordinates (`row`, `col`) (pixel
    /// (i, j) spans [i, i+1) × [j, j+1), so (i + ½, j + ½) returns it exactly), the image
    /// repeated periodically in both directions: how a tileable material is read at any point.
    pub fn sample_periodic(&self, c: usize, row: f64, col: f64) -> f32 {
        let (y, x) = (row - 0.5, col - 0.5);
        let (y0, x0) = (y.floor(), x.floor());
        let (fy, fx) = ((y - y0) as f32, (x - x0) as f32);
        let wrap = |i: f64, n: usize| i.rem_euclid(n as f64) as usize;
        let (r0, r1) = (wrap(y0, self.height), wrap(y0 + 1.0, self.height));
        let (c0, c1) = (wrap(x0, self.width), wrap(x0 + 1.0, self.width));
        let top = self.get(c, r0, c0) * (1.0 - fx) + self.get(c, r0, c1) * fx;
        let bottom = self.get(c, r1, c0) * (1.0 - fx) + self.get(c, r1, c1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// The same image with `f` applied to every sample.
    pub fn map(&self, f: impl Fn(f32) -> f32) -> Self {
        Self {
            data: self.data.iter().map(|&v| f(v)).collect(),
            ..self.clone()
        }
    }
}

/// Write `bytes` to `path` atomically: into a temporary file in the same folder (so the
/// rename stays on one file system), flushed to disk, then renamed over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let file_name = path
        .file_name()
        .ok_or_else(|| Error::file(path, "is not a file path"))?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp = dir.join(format!(
        ".{}.{}-{}.tmp",
        file_name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let mut file = File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        // Best effort: the temporary file is garbage whatever happened.
        let _ = fs::remove_file(&tmp);
        Error::file(path, format!("cannot write: {e}"))
    })
}

/// Encode `image` (values in [0, 1], clamped; NaN writes 0) as a PNG of `bits` per channel.
pub fn encode_png(image: &PlanarImage, bits: PngBits) -> Result<Vec<u8>> {
    encode_png_inner(image, bits, None)
}

fn encode_png_inner(image: &PlanarImage, bits: PngBits, exif: Option<&[u8]>) -> Result<Vec<u8>> {
    let (w, h) = (image.width as u32, image.height as u32);
    let plane = image.texels();
    let scale = bits.max_value();
    // Interleave: PNG pixels are HWC. `as` saturates and maps NaN to 0.
    let quantised: Vec<u16> = (0..plane)
        .flat_map(|t| (0..image.channels).map(move |c| (c, t)))
        .map(|(c, t)| (image.data[c * plane + t].clamp(0.0, 1.0) * scale).round() as u16)
        .collect();
    let bad = || {
        Error::Invalid(format!(
            "PNG holds 1, 3 or 4 channels, the image has {}",
            image.channels
        ))
    };
    let dynamic = match bits {
        PngBits::Sixteen => match image.channels {
            1 => ImageBuffer::from_raw(w, h, quantised).map(DynamicImage::ImageLuma16),
            3 => ImageBuffer::from_raw(w, h, quantised).map(DynamicImage::ImageRgb16),
            4 => ImageBuffer::from_raw(w, h, quantised).map(DynamicImage::ImageRgba16),
            _ => return Err(bad()),
        },
        PngBits::Eight => {
            let bytes: Vec<u8> = quantised.into_iter().map(|v| v as u8).collect();
            match image.channels {
                1 => ImageBuffer::from_raw(w, h, bytes).map(DynamicImage::ImageLuma8),
                3 => ImageBuffer::from_raw(w, h, bytes).map(DynamicImage::ImageRgb8),
                4 => ImageBuffer::from_raw(w, h, bytes).map(DynamicImage::ImageRgba8),
                _ => return Err(bad()),
            }
        }
    }
    .ok_or_else(|| Error::Invalid("PNG buffer size mismatch".into()))?;
    let mut out = Cursor::new(Vec::new());
    let mut encoder = PngEncoder::new(&mut out);
    if let Some(exif) = exif {
        encoder
            .set_exif_metadata(exif.to_vec())
            .map_err(|e| Error::Invalid(format!("PNG EXIF: {e}")))?;
    }
    encoder
        .write_image(dynamic.as_bytes(), w, h, dynamic.color().into())
        .map_err(|e| Error::Invalid(format!("PNG encoding failed: {e}")))?;
    Ok(out.into_inner())
}

/// [`encode_png`] with `exif` (a TIFF structure, as EXIF is stored) in the PNG's `eXIf` chunk.
pub fn encode_png_with_exif(image: &PlanarImage, bits: PngBits, exif: &[u8]) -> Result<Vec<u8>> {
    encode_png_inner(image, bits, Some(exif))
}

/// Write `image` (values in [0, 1]) as a PNG, atomically.
pub fn write_png(path: &Path, image: &PlanarImage, bits: PngBits) -> Result<()> {
    let bytes = encode_png(image, bits).map_err(|e| Error::file(path, e))?;
    write_atomic(path, &bytes)
}

/// Channel count implied by a decoded PNG's colour type, or a description of why it is
/// not one photomat reads.
fn png_channels(color: image::ColorType) -> std::result::Result<(usize, PngBits), String> {
    use image::ColorType as C;
    Ok(match color {
        C::L8 => (1, PngBits::Eight),
        C::L16 => (1, PngBits::Sixteen),
        C::La8 => (2, PngBits::Eight),
        C::La16 => (2, PngBits::Sixteen),
        C::Rgb8 => (3, PngBits::Eight),
        C::Rgb16 => (3, PngBits::Sixteen),
        C::Rgba8 => (4, PngBits::Eight),
        C::Rgba16 => (4, PngBits::Sixteen),
        other => return Err(format!("unsupported PNG pixel type {other:?}")),
    })
}

/// Decode a PNG file into values in [0, 1]: (image, bit depth of the file).
/// Grey → 1 channel, grey+alpha → 2, RGB → 3, RGBA → 4; palette images expand to RGB(A).
pub fn read_png(path: &Path) -> Result<(PlanarImage, PngBits)> {
    let bytes = fs::read(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let mut reader = ImageReader::new(Cursor::new(&bytes));
    reader.set_format(ImageFormat::Png);
    reader.limits(decode_limits());
    let not_png = |e: image::ImageError| Error::file(path, format!("not a readable PNG: {e}"));
    let decoder = reader.into_decoder().map_err(not_png)?;
    let (w, h) = decoder.dimensions();
    check_pixel_limit(w as u64, h as u64).map_err(|e| Error::file(path, e))?;
    let decoded = DynamicImage::from_decoder(decoder).map_err(not_png)?;
    let (channels, bits) = png_channels(decoded.color()).map_err(|e| Error::file(path, e))?;
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    // 8-bit samples widen exactly (v·257), so v16/65535 = v8/255.
    let interleaved: Vec<u16> = match channels {
        1 => decoded.into_luma16().into_raw(),
        2 => decoded.into_luma_alpha16().into_raw(),
        3 => decoded.into_rgb16().into_raw(),
        _ => decoded.into_rgba16().into_raw(),
    };
    let plane = width * height;
    let mut data = vec![0f32; channels * plane];
    for (i, v) in interleaved.into_iter().enumerate() {
        data[(i % channels) * plane + i / channels] = v as f32 / u16::MAX as f32;
    }
    Ok((PlanarImage::new(channels, height, width, data)?, bits))
}

/// A PNG's (channels, height, width) from its header only (no pixel decoding).
pub fn png_header(path: &Path) -> Result<(usize, usize, usize)> {
    let mut reader =
        ImageReader::open(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    reader.set_format(ImageFormat::Png);
    let decoder = reader
        .into_decoder()
        .map_err(|e| Error::file(path, format!("not a readable PNG: {e}")))?;
    let (width, height) = decoder.dimensions();
    let (channels, _) = png_channels(decoder.color_type()).map_err(|e| Error::file(path, e))?;
    Ok((channels, height as usize, width as usize))
}

/// EXR channel names for a `channels`-channel image (see the module table), in channel order.
pub fn exr_channel_names(channels: usize) -> Vec<String> {
    match channels {
        1 => vec!["Y".into()],
        3 => ["R", "G", "B"].map(String::from).to_vec(),
        4 => ["R", "G", "B", "A"].map(String::from).to_vec(),
        n => (0..n).map(|i| format!("C{i:02}")).collect(),
    }
}

/// Encode `image` as a single-layer float32 EXR (ZIP compression, lossless).
pub fn encode_exr(image: &PlanarImage) -> Result<Vec<u8>> {
    use exr::prelude as x;
    if image.channels == 0 || image.texels() == 0 {
        return Err(Error::Invalid(
            "an EXR image needs at least one channel and texel".into(),
        ));
    }
    let plane = image.texels();
    let channels: x::SmallVec<[x::AnyChannel<x::FlatSamples>; 4]> =
        exr_channel_names(image.channels)
            .into_iter()
            .enumerate()
            .map(|(c, name)| {
                let samples = image.data[c * plane..(c + 1) * plane].to_vec();
                x::AnyChannel::new(name.as_str(), x::FlatSamples::F32(samples))
            })
            .collect();
    let layer = x::Layer::new(
        (image.width, image.height),
        x::LayerAttributes::default(),
        x::Encoding::SMALL_LOSSLESS,
        x::AnyChannels::sort(channels),
    );
    let mut out = Cursor::new(Vec::new());
    x::WritableImage::write(&x::Image::from_layer(layer))
        .to_buffered(&mut out)
        .map_err(|e| Error::Invalid(format!("EXR encoding failed: {e}")))?;
    Ok(out.into_inner())
}

/// Write `image` as a float32 EXR with the channel names of [`exr_channel_names`], atomically.
pub fn write_exr(path: &Path, image: &PlanarImage) -> Result<()> {
    let bytes = encode_exr(image).map_err(|e| Error::file(path, e))?;
    write_atomic(path, &bytes)
}

/// Read the first layer of an EXR file; its channel names must be one of photomat's layouts
/// (module table). Samples of any type are converted to f32; values are not checked.
pub fn read_exr(path: &Path) -> Result<PlanarImage> {
    use exr::prelude::{ReadChannels, ReadLayers, read};
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| Error::file(path, format!("not a readable EXR: {e}")))?;
    for header in &meta.headers {
        let size = header.layer_size;
        check_pixel_limit(size.width() as u64, size.height() as u64)
            .map_err(|e| Error::file(path, e))?;
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| Error::file(path, format!("not a readable EXR: {e}")))?;
    let layer = image.layer_data;
    let (width, height) = (layer.size.width(), layer.size.height());
    let found: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    let expected = exr_channel_names(found.len());
    let mut data = Vec::with_capacity(found.len() * width * height);
    for name in &expected {
        let channel = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == *name)
            .ok_or_else(|| {
                Error::file(
                    path,
                    format!(
                        "EXR channels ({}) are not a photomat layout: a {}-channel map uses {}",
                        found.join(", "),
                        found.len(),
                        expected.join(", ")
                    ),
                )
            })?;
        data.extend(channel.sample_data.values_as_f32());
    }
    PlanarImage::new(found.len(), height, width, data).map_err(|e| Error::file(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_sampling_hits_pixel_centres_interpolates_and_wraps() {
        let data: Vec<f32> = (0..2 * 3 * 4).map(|i| (i * i) as f32).collect();
        let image = PlanarImage::new(2, 3, 4, data).unwrap();
        for c in 0..2 {
            for row in 0..3 {
                for col in 0..4 {
                    let (r, q) = (row as f64 + 0.5, col as f64 + 0.5);
                    assert_eq!(image.sample_periodic(c, r, q), image.get(c, row, col));
                    // One period away in either direction reads the same texel.
                    assert_eq!(
                        image.sample_periodic(c, r - 3.0, q + 8.0),
                        image.get(c, row, col)
                    );
                }
            }
        }
        // Half-way between pixel (1, 3) and its right neighbour, which wraps to column 0.
        let expected = 0.5 * (image.get(1, 1, 3) + image.get(1, 1, 0));
        assert_eq!(image.sample_periodic(1, 1.5, 4.0), expected);
        // A quarter down from pixel (2, 1) towards row 0 (wrapped).
        let expected = 0.75 * image.get(0, 2, 1) + 0.25 * image.get(0, 0, 1);
        assert!((image.sample_periodic(0, 2.75, 1.5) - expected).abs() < 1e-4);
    }

    #[test]
    fn png_round_trip_is_within_half_a_step() {
        let data: Vec<f32> = (0..2 * 3 * 3).map(|i| i as f32 / 17.0).collect();
        let image = PlanarImage::new(3, 2, 3, data).unwrap();
        for bits in [PngBits::Eight, PngBits::Sixteen] {
            let bytes = encode_png(&image, bits).unwrap();
            let decoded = image::load_from_memory(&bytes).unwrap();
            assert_eq!(png_channels(decoded.color()).unwrap(), (3, bits));
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("x.png");
            write_png(&path, &image, bits).unwrap();
            let (back, read_bits) = read_png(&path).unwrap();
            assert_eq!(read_bits, bits);
            assert_eq!(png_header(&path).unwrap(), (3, 2, 3));
            // Rounding to the nearest level errs by at most half a step (+ f32 rounding).
            let step = 1.0 / bits.max_value();
            for (a, b) in image.data.iter().zip(&back.data) {
                assert!((a - b).abs() <= 0.5 * step + 1e-6, "{a} vs {b} ({bits:?})");
            }
        }
    }

    #[test]
    fn exr_round_trip_is_exact() {
        for channels in [1, 2, 3, 4, 5] {
            let data: Vec<f32> = (0..channels * 4 * 5)
                .map(|i| (i as f32).sin() * 3.7)
                .collect();
            let image = PlanarImage::new(channels, 4, 5, data).unwrap();
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("x.exr");
            write_exr(&path, &image).unwrap();
            assert_eq!(read_exr(&path).unwrap(), image, "{channels} channels");
        }
    }

    #[test]
    fn write_atomic_leaves_no_temporary_files() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.bin");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("a.bin")]);
    }
}
