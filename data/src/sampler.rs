//! Training crops of flash photos and the matching light positions for the fixed-size G
//! (the reference implementation's crops; contract in docs/datasets.md "Crop sampler"; the
//! spatial G's native-scale patches are [`crate::patch`]).
//!
//! For model size H, a prepared photo (highlight roughly centred) is resized to 2H×2H, so it
//! spans the plane square of side 2 at flash height 1 and every H×H window of it is the unit
//! square of the engine. [`CropSampler`] draws, per batch item and in this order: a photo
//! (uniform), the window's top and left corner (uniform in 0..=H each), and one of the eight
//! symmetries of the square (uniform: identity, three rotations by 90°, four mirrors). The
//! window and the symmetry apply to the image and to the highlight alike; the highlight moves
//! to `(row − top, col − left)` in continuous pixel coordinates and then through the same
//! symmetry, and may lie outside the crop. Each crop comes with its per-pixel ω map from
//! [`FlashGeometry::new`] at the moved highlight.
//!
//! [`LightSampler`] draws highlights for generated samples from the very same distribution
//! (same draws, without loading images). Both are deterministic under their seed: draws come
//! from one [`StdRng`] in a fixed order, images are loaded in parallel afterwards.
//!
//! Resizing happens in linear light (decode gamma 2.2, resample with [`RESIZE_FILTER`], which
//! the `image` crate widens by the scale factor when shrinking, re-encode), so highlights keep
//! their energy. Photos are decoded from disk for every crop (a 512² PNG costs a few
//! milliseconds, small against a GAN step); nothing is cached.
//!
//! The dataset is a `photomat prepare` folder opened with [`FlashDataset::open`]
//! ([`crate::dataset`], `index.json` as in docs/datasets.md).

use candle_core::{DType, Device, Tensor};
use image::Rgb32FImage;
use image::imageops::FilterType;
use photomat_core::flash::FlashGeometry;
use photomat_core::image_io::PlanarImage;
use photomat_core::render::DISPLAY_GAMMA;
use photomat_core::{Error, Highlight, Result};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use crate::dataset::FlashDataset;

/// Resampling filter when the dataset's size is not 2H: the one `photomat prepare` uses, so a
/// photo looks the same whichever step resized it.
pub const RESIZE_FILTER: FilterType = FilterType::Lanczos3;

/// Photo `index` of `dataset` as display values (3, side, side), resized to `side`×`side` in
/// linear light (module docs), and its highlight in the resized photo's pixel coordinates.
/// Errors name the file.
pub fn load_resized(
    dataset: &FlashDataset,
    index: usize,
    side: usize,
) -> Result<(PlanarImage, (f64, f64))> {
    if index >= dataset.len() {
        return Err(Error::Invalid(format!(
            "photo {index} of a dataset of {} photos",
            dataset.len()
        )));
    }
    let photo = dataset.load_image(index)?;
    let size = dataset.size();
    let (row, col) = dataset.highlight_px(index);
    let scale = side as f64 / size as f64;
    if side == size {
        return Ok((photo, (row, col)));
    }
    let plane = size * size;
    // Planar display values → interleaved linear light. Stored 8-bit samples lie in [0, 1].
    let linear: Vec<f32> = (0..plane)
        .flat_map(|t| (0..3).map(move |c| c * plane + t))
        .map(|i| photo.data[i].powf(DISPLAY_GAMMA as f32))
        .collect();
    let buffer = Rgb32FImage::from_raw(size as u32, size as u32, linear)
        .ok_or_else(|| Error::Invalid("image buffer size mismatch".into()))?;
    let resized = image::imageops::resize(&buffer, side as u32, side as u32, RESIZE_FILTER);
    let out_plane = side * side;
    let mut data = vec![0f32; 3 * out_plane];
    for (i, v) in resized.into_raw().into_iter().enumerate() {
        // The filter's negative lobes over- and undershoot at edges: clamp to the displayable
        // range before re-encoding (this also keeps powf away from negative values).
        data[(i % 3) * out_plane + i / 3] = v.clamp(0.0, 1.0).powf(1.0 / DISPLAY_GAMMA as f32);
    }
    Ok((
        PlanarImage::new(3, side, side, data)?,
        (row * scale, col * scale),
    ))
}

/// One of the eight symmetries of the square, as `transpose`, then mirror rows (`flip_rows`:
/// upside down), then mirror columns (`flip_cols`: left–right). The eight combinations are the
/// identity, the rotations by 90°, 180° and 270°, and the four mirrors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Symmetry {
    pub transpose: bool,
    pub flip_rows: bool,
    pub flip_cols: bool,
}

impl Symmetry {
    /// All eight, identity first; `ALL[k]` has bits (transpose, flip_rows, flip_cols) of k.
    pub const ALL: [Symmetry; 8] = {
        let mut all = [Symmetry {
            transpose: false,
            flip_rows: false,
            flip_cols: false,
        }; 8];
        let mut k = 0;
        while k < 8 {
            all[k] = Symmetry {
                transpose: k & 4 != 0,
                flip_rows: k & 2 != 0,
                flip_cols: k & 1 != 0,
            };
            k += 1;
        }
        all
    };

    /// Where the continuous point (row, col) of an H×H image goes (pixel (i, j) spans
    /// [i, i+1)×[j, j+1), so mirroring is `H − row`).
    pub fn point(self, (row, col): (f64, f64), size: usize) -> (f64, f64) {
        let h = size as f64;
        let (r, c) = if self.transpose {
            (col, row)
        } else {
            (row, col)
        };
        (
            if self.flip_rows { h - r } else { r },
            if self.flip_cols { h - c } else { c },
        )
    }

    /// Where pixel (i, j) of an H×H image goes.
    pub fn pixel(self, (i, j): (usize, usize), size: usize) -> (usize, usize) {
        let (r, c) = if self.transpose { (j, i) } else { (i, j) };
        (
            if self.flip_rows { size - 1 - r } else { r },
            if self.flip_cols { size - 1 - c } else { c },
        )
    }

    /// A plane direction or vector (x right, y up, z) under the symmetry: mirroring columns
    /// negates x, mirroring rows negates y, the transpose maps (x, y) to (−y, −x).
    pub fn vector(self, [x, y, z]: [f64; 3]) -> [f64; 3] {
        let (x, y) = if self.transpose { (-y, -x) } else { (x, y) };
        [
            if self.flip_cols { -x } else { x },
            if self.flip_rows { -y } else { y },
            z,
        ]
    }

    /// The image with every pixel moved by [`Self::pixel`]; shape (C, H, H) kept.
    pub fn image(self, image: &PlanarImage) -> Result<PlanarImage> {
        let size = image.height;
        if image.width != size {
            return Err(Error::Invalid(format!(
                "symmetries of the square need a square image, got {}×{}",
                image.height, image.width
            )));
        }
        let plane = size * size;
        let mut out = PlanarImage::filled(image.channels, size, size, 0.0);
        for i in 0..size {
            for j in 0..size {
                let (a, b) = self.pixel((i, j), size);
                for c in 0..image.channels {
                    out.data[c * plane + a * size + b] = image.data[c * plane + i * size + j];
                }
            }
        }
        Ok(out)
    }
}

/// Where one training crop comes from: an H×H window at (`top`, `left`) of the 2H×2H photo,
/// then a symmetry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CropWindow {
    /// Crop side H.
    pub size: usize,
    pub top: usize,
    pub left: usize,
    pub symmetry: Symmetry,
}

impl CropWindow {
    /// The highlight (row, col) of the whole photo in the crop's continuous pixel
    /// coordinates (possibly outside [0, H]).
    pub fn highlight_px(&self, (row, col): (f64, f64)) -> (f64, f64) {
        self.symmetry
            .point((row - self.top as f64, col - self.left as f64), self.size)
    }

    /// The same in crop-plane coordinates (the crop is the unit square).
    pub fn highlight(&self, photo_highlight_px: (f64, f64)) -> Highlight {
        let (row, col) = self.highlight_px(photo_highlight_px);
        Highlight::from_pixel(row, col, self.size)
    }

    /// The crop of `photo` (C, P, P) with P ≥ top + H and P ≥ left + H: (C, H, H).
    pub fn crop(&self, photo: &PlanarImage) -> Result<PlanarImage> {
        let h = self.size;
        let window = photo.window(self.top, self.left, h, h)?;
        self.symmetry.image(&window)
    }
}

/// One draw of the crop distribution: which photo, which window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct CropDraw {
    photo: usize,
    window: CropWindow,
}

/// The crop distribution shared by [`CropSampler`] and [`LightSampler`] (module docs).
fn draw(rng: &mut StdRng, photos: usize, model_size: usize) -> CropDraw {
    let photo = rng.random_range(0..photos);
    let top = rng.random_range(0..=model_size);
    let left = rng.random_range(0..=model_size);
    let symmetry = Symmetry::ALL[rng.random_range(0..8)];
    CropDraw {
        photo,
        window: CropWindow {
            size: model_size,
            top,
            left,
            symmetry,
        },
    }
}

/// A batch of training crops.
#[derive(Debug, Clone)]
pub struct CropBatch {
    /// Crops in the networks' range [−1, 1] (`2·display − 1`), (B, 3, H, H), f32.
    pub images: Tensor,
    /// Per-pixel unit direction to the flash, (B, 3, H, H), f32.
    pub omega: Tensor,
    /// The flash of each crop in crop-plane coordinates (may lie outside the crop).
    pub highlights: Vec<Highlight>,
}

/// Random training crops of a [`FlashDataset`] for an H×H model.
#[derive(Debug, Clone)]
pub struct CropSampler {
    model_size: usize,
    rng: StdRng,
}

impl CropSampler {
    /// A sampler of H×H crops (H = `model_size` ≥ 1), deterministic under `seed`.
    pub fn new(model_size: usize, seed: u64) -> Result<Self> {
        if model_size == 0 {
            return Err(Error::Invalid("the model size must be at least 1".into()));
        }
        Ok(Self {
            model_size,
            rng: StdRng::seed_from_u64(seed),
        })
    }

    /// Model size H.
    pub fn model_size(&self) -> usize {
        self.model_size
    }

    /// `batch` crops with their ω maps and highlights (see [`CropBatch`] for shapes).
    pub fn sample(
        &mut self,
        dataset: &FlashDataset,
        batch: usize,
        device: &Device,
    ) -> Result<CropBatch> {
        if batch == 0 || dataset.is_empty() {
            return Err(Error::Invalid(format!(
                "cannot sample a batch of {batch} from a dataset of {} photos",
                dataset.len()
            )));
        }
        let h = self.model_size;
        let draws: Vec<CropDraw> = (0..batch)
            .map(|_| draw(&mut self.rng, dataset.len(), h))
            .collect();
        let crops = draws
            .par_iter()
            .map(|d| {
                let (photo, highlight_px) = load_resized(dataset, d.photo, 2 * h)?;
                Ok((d.window.crop(&photo)?, d.window.highlight(highlight_px)))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut pixels = Vec::with_capacity(batch * 3 * h * h);
        let mut highlights = Vec::with_capacity(batch);
        for (crop, highlight) in crops {
            pixels.extend(crop.data.iter().map(|v| 2.0 * v - 1.0));
            highlights.push(highlight);
        }
        let images = Tensor::from_vec(pixels, (batch, 3, h, h), device)?;
        let omega = FlashGeometry::new(&highlights, h, DType::F32, device)?.omega;
        Ok(CropBatch {
            images,
            omega,
            highlights,
        })
    }
}

/// Highlights for generated H×H samples, from the distribution of [`CropSampler`]'s crops.
#[derive(Debug, Clone)]
pub struct LightSampler {
    model_size: usize,
    /// Photo highlights in 2H×2H pixel coordinates.
    highlights_px: Vec<(f64, f64)>,
    rng: StdRng,
}

impl LightSampler {
    /// A sampler over `dataset`'s highlights for H×H samples, deterministic under `seed`.
    /// With the seed of a [`CropSampler`] it draws exactly that sampler's highlights.
    pub fn new(dataset: &FlashDataset, model_size: usize, seed: u64) -> Result<Self> {
        if model_size == 0 || dataset.is_empty() {
            return Err(Error::Invalid(format!(
                "a light sampler needs a model size ≥ 1 and photos, got {model_size} and {}",
                dataset.len()
            )));
        }
        let scale = 2.0 * model_size as f64 / dataset.size() as f64;
        Ok(Self {
            model_size,
            highlights_px: (0..dataset.len())
                .map(|i| {
                    let (row, col) = dataset.highlight_px(i);
                    (row * scale, col * scale)
                })
                .collect(),
            rng: StdRng::seed_from_u64(seed),
        })
    }

    /// `batch` highlights in crop-plane coordinates.
    pub fn sample(&mut self, batch: usize) -> Vec<Highlight> {
        (0..batch)
            .map(|_| {
                let d = draw(&mut self.rng, self.highlights_px.len(), self.model_size);
                d.window.highlight(self.highlights_px[d.photo])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetries_are_the_eight_distinct_maps_of_the_square() {
        let size = 5;
        let images: Vec<Vec<(usize, usize)>> = Symmetry::ALL
            .iter()
            .map(|s| {
                (0..size * size)
                    .map(|t| s.pixel((t / size, t % size), size))
                    .collect()
            })
            .collect();
        for (a, ia) in images.iter().enumerate() {
            for ib in &images[a + 1..] {
                assert_ne!(ia, ib);
            }
        }
        // Pixel centres move like continuous points.
        for s in Symmetry::ALL {
            for (i, j) in [(0, 0), (1, 3), (4, 2)] {
                let (a, b) = s.pixel((i, j), size);
                let (r, c) = s.point((i as f64 + 0.5, j as f64 + 0.5), size);
                assert_eq!((a as f64 + 0.5, b as f64 + 0.5), (r, c), "{s:?}");
            }
        }
    }

    #[test]
    fn symmetry_vectors_follow_the_plane_axes() {
        // A point's plane position (x, y) = (col/H − ½, ½ − row/H) moves like a vector.
        let size = 8;
        for s in Symmetry::ALL {
            let (row, col) = (1.25, 6.5);
            let before = Highlight::from_pixel(row, col, size);
            let (r, c) = s.point((row, col), size);
            let after = Highlight::from_pixel(r, c, size);
            let v = s.vector([before.x, before.y, 1.0]);
            assert!((v[0] - after.x).abs() < 1e-12 && (v[1] - after.y).abs() < 1e-12);
        }
    }
}
