//! The training crop and patch samplers: crop and patch geometry against the whole photo's,
//! highlights moving with the image under flips and rotations, determinism, resizing, the
//! highlight-inside option of patches, and the dataset index reader.

use std::path::Path;

use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _;
use photomat_core::image_io::{PlanarImage, PngBits, write_png};
use photomat_core::{FlashGeometry, Highlight};
use photomat_data::dataset::{DatasetIndex, FlashDataset, PhotoEntry};
use photomat_data::highlight::{DetectionStatus, DetectorKind};
use photomat_data::patch::{
    PatchLightSampler, PatchOptions, PatchSampler, PatchWindow, patch_side,
    uniform_highlight_inside,
};
use photomat_data::sampler::{CropSampler, CropWindow, LightSampler, Symmetry, load_resized};
use proptest::prelude::*;

/// (C, H, W) f64 values of item 0 of an NCHW tensor.
fn item(t: &Tensor, b: usize) -> PlanarImage {
    PlanarImage::from_tensor(&t.narrow(0, b, 1).unwrap()).unwrap()
}

/// Checks that `cut`, the flash geometry of a `window` of a `photo`² image, is the geometry
/// `whole` of the image cut at the window and transformed by its symmetry: per texel, ω
/// rotated or flipped with the pixels and 1/d² moved with them, to 1e-12 (f64 rounding of
/// the two ways of writing the same texel position).
fn assert_cut_of(
    cut: &FlashGeometry,
    whole: &FlashGeometry,
    photo: usize,
    window: &CropWindow,
) -> Result<(), TestCaseError> {
    let values = |t: &Tensor| -> Vec<f64> { t.flatten_all().unwrap().to_vec1().unwrap() };
    let (whole_omega, whole_d2) = (values(&whole.omega), values(&whole.inv_dist2));
    let (cut_omega, cut_d2) = (values(&cut.omega), values(&cut.inv_dist2));
    let h = window.size;
    let (pp, hh) = (photo * photo, h * h);
    for i in 0..h {
        for j in 0..h {
            let src = (window.top + i) * photo + window.left + j;
            let (a, b) = window.symmetry.pixel((i, j), h);
            let dst = a * h + b;
            let v = window.symmetry.vector([
                whole_omega[src],
                whole_omega[pp + src],
                whole_omega[2 * pp + src],
            ]);
            for c in 0..3 {
                prop_assert!(
                    (cut_omega[c * hh + dst] - v[c]).abs() < 1e-12,
                    "ω[{c}] at cut pixel ({a}, {b}): {} vs {}",
                    cut_omega[c * hh + dst],
                    v[c]
                );
            }
            prop_assert!((cut_d2[dst] - whole_d2[src]).abs() < 1e-12);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn sampler_crop_omega_is_the_photo_omega_restricted(
        h in 2usize..20,
        // Highlights inside the photo and up to half a crop beyond it.
        hr in -0.25f64..1.25,
        hc in -0.25f64..1.25,
        top_frac in 0.0f64..=1.0,
        left_frac in 0.0f64..=1.0,
        symmetry in 0usize..8,
    ) {
        let photo = 2 * h;
        let highlight_px = (hr * photo as f64, hc * photo as f64);
        let window = CropWindow {
            size: h,
            top: (top_frac * h as f64).round() as usize,
            left: (left_frac * h as f64).round() as usize,
            symmetry: Symmetry::ALL[symmetry],
        };
        let whole = FlashGeometry::with_side(
            &[Highlight::from_pixel_on(highlight_px.0, highlight_px.1, photo, 2.0)],
            photo,
            2.0,
            DType::F64,
            &Device::Cpu,
        )
        .unwrap();
        let crop = FlashGeometry::new(
            &[window.highlight(highlight_px)],
            h,
            DType::F64,
            &Device::Cpu,
        )
        .unwrap();
        assert_cut_of(&crop, &whole, photo, &window)?;
    }
}

/// A `photomat prepare` folder in `dir` holding `photos` (image, highlight (row, col)), all
/// `size`², opened.
fn write_dataset(dir: &Path, size: usize, photos: &[(PlanarImage, (f64, f64))]) -> FlashDataset {
    std::fs::create_dir_all(dir.join("images")).unwrap();
    let mut index = DatasetIndex::new(size, DetectorKind::Paper);
    for (k, (image, (row, col))) in photos.iter().enumerate() {
        let name = format!("images/{k:03}.png");
        write_png(&dir.join(&name), image, PngBits::Eight).unwrap();
        let h = Highlight::from_pixel_on(*row, *col, size, 2.0);
        index.photos.push(PhotoEntry {
            image: name,
            // Sorted by source when written: keep the photos in order.
            source: format!("/photos/{k:03}.jpg"),
            source_bytes: 1,
            source_modified: 0,
            source_size: [size, size],
            highlight_px: [*row, *col],
            highlight: [h.x, h.y],
            status: DetectionStatus::Detected,
            reason: None,
            truth_highlight_px: None,
        });
    }
    index.write(dir).unwrap();
    FlashDataset::open(dir).unwrap()
}

/// A dataset of dark `size`² photos, each with one white pixel: the one that contains its
/// highlight (at the pixel's centre), plus a dim gradient so that crops differ.
fn bright_pixel_dataset(dir: &Path, size: usize, highlights: &[(usize, usize)]) -> FlashDataset {
    let plane = size * size;
    let photos: Vec<_> = highlights
        .iter()
        .map(|&(r, c)| {
            let mut data: Vec<f32> = (0..3 * plane)
                .map(|i| 0.05 + 0.3 * ((i % plane) as f32 / plane as f32))
                .collect();
            for ch in 0..3 {
                data[ch * plane + r * size + c] = 1.0;
            }
            (
                PlanarImage::new(3, size, size, data).unwrap(),
                (r as f64 + 0.5, c as f64 + 0.5),
            )
        })
        .collect();
    write_dataset(dir, size, &photos)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn sampler_highlight_moves_with_the_image(
        seed in any::<u64>(),
        h in 4usize..12,
        highlights in proptest::collection::vec((0.2f64..0.8, 0.2f64..0.8), 1..4),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let size = 2 * h;
        let pixels: Vec<(usize, usize)> = highlights
            .iter()
            .map(|(r, c)| ((r * size as f64) as usize, (c * size as f64) as usize))
            .collect();
        let dataset = bright_pixel_dataset(dir.path(), size, &pixels);
        let mut sampler = CropSampler::new(h, seed).unwrap();
        let batch = sampler.sample(&dataset, 8, &Device::Cpu).unwrap();
        prop_assert_eq!(batch.images.dims(), &[8, 3, h, h]);
        prop_assert_eq!(batch.omega.dims(), &[8, 3, h, h]);
        for (b, highlight) in batch.highlights.iter().enumerate() {
            let crop = item(&batch.images, b);
            // Network range: the white pixel is 1, the background below 0.
            let bright: Vec<(usize, usize)> = (0..h * h)
                .filter(|t| crop.data[h * h + t] > 0.9)
                .map(|t| (t / h, t % h))
                .collect();
            let (row, col) = highlight.to_pixel(h);
            if (0.0..h as f64).contains(&row) && (0.0..h as f64).contains(&col) {
                prop_assert_eq!(
                    bright,
                    vec![(row.floor() as usize, col.floor() as usize)],
                    "item {}: highlight ({}, {})", b, row, col
                );
            } else {
                prop_assert!(bright.is_empty(), "item {}: highlight ({}, {}) outside", b, row, col);
            }
            // ω belongs to the returned highlight.
            let expected = FlashGeometry::new(&[*highlight], h, DType::F32, &Device::Cpu)
                .unwrap()
                .omega;
            let diff = (batch.omega.narrow(0, b, 1).unwrap() - expected)
                .unwrap()
                .abs()
                .unwrap()
                .flatten_all()
                .unwrap()
                .max(0)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap();
            prop_assert_eq!(diff, 0.0);
        }
    }
}

fn to_vec(t: &Tensor) -> Vec<f32> {
    t.flatten_all().unwrap().to_vec1().unwrap()
}

#[test]
fn sampler_is_deterministic_under_a_seed() {
    let dir = tempfile::tempdir().unwrap();
    let dataset = bright_pixel_dataset(dir.path(), 16, &[(5, 9), (8, 8), (10, 3)]);
    let draw = |seed| {
        CropSampler::new(8, seed)
            .unwrap()
            .sample(&dataset, 6, &Device::Cpu)
            .unwrap()
    };
    let (a, b, c) = (draw(4), draw(4), draw(5));
    assert_eq!(to_vec(&a.images), to_vec(&b.images));
    assert_eq!(a.highlights, b.highlights);
    assert_ne!(a.highlights, c.highlights);
    // The light sampler draws the crop sampler's highlights under the same seed.
    let lights = LightSampler::new(&dataset, 8, 4).unwrap().sample(6);
    assert_eq!(lights, a.highlights);
    // Successive batches differ.
    let mut sampler = CropSampler::new(8, 4).unwrap();
    let first = sampler.sample(&dataset, 6, &Device::Cpu).unwrap();
    let second = sampler.sample(&dataset, 6, &Device::Cpu).unwrap();
    assert_eq!(first.highlights, a.highlights);
    assert_ne!(first.highlights, second.highlights);
}

#[test]
fn sampler_highlights_may_fall_outside_the_crop() {
    let dir = tempfile::tempdir().unwrap();
    // Highlights near a corner of the photo: most crops do not contain them.
    let dataset = bright_pixel_dataset(dir.path(), 16, &[(1, 2), (14, 13)]);
    let mut sampler = CropSampler::new(8, 9).unwrap();
    let batch = sampler.sample(&dataset, 32, &Device::Cpu).unwrap();
    let outside = batch
        .highlights
        .iter()
        .filter(|h| h.x.abs() > 0.5 || h.y.abs() > 0.5)
        .count();
    assert!(outside > 8, "{outside} of 32 outside");
    // ω stays a field of unit vectors pointing up.
    let omega = item(&batch.omega, 0);
    for t in 0..64 {
        let v = [omega.data[t], omega.data[64 + t], omega.data[128 + t]];
        let len = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((len - 1.0).abs() < 1e-5 && v[2] > 0.0);
    }
}

#[test]
fn sampler_resizes_photos_to_twice_the_model_size() {
    let dir = tempfile::tempdir().unwrap();
    // 48² photos with a white 3×3 block around the highlight, model size 8 (photos → 16²).
    let size = 48;
    let plane = size * size;
    let mut data = vec![0.1f32; 3 * plane];
    for ch in 0..3 {
        for r in 21..24 {
            for c in 30..33 {
                data[ch * plane + r * size + c] = 1.0;
            }
        }
    }
    let dataset = write_dataset(
        dir.path(),
        size,
        &[(PlanarImage::new(3, size, size, data).unwrap(), (22.5, 31.5))],
    );
    let (photo, highlight) = load_resized(&dataset, 0, 16).unwrap();
    assert_eq!((photo.height, photo.width), (16, 16));
    assert_eq!(highlight, (7.5, 10.5));
    // The block (source pixels 21..24 × 30..33) shrinks to pixel (7, 10), around the moved
    // highlight.
    let brightest = (0..256).max_by(|&a, &b| photo.data[a].total_cmp(&photo.data[b]));
    assert_eq!(brightest, Some(7 * 16 + 10));
    // Resampled in linear light: Lanczos3 widened 3× puts 77 % of its weight on the block,
    // which gives 0.89 in linear light and 0.79 when averaging display values.
    assert!(photo.get(0, 7, 10) > 0.85, "{}", photo.get(0, 7, 10));
    assert!(photo.data.iter().all(|v| (0.0..=1.0).contains(v)));
    let batch = CropSampler::new(8, 0)
        .unwrap()
        .sample(&dataset, 4, &Device::Cpu)
        .unwrap();
    assert_eq!(batch.images.dims(), &[4, 3, 8, 8]);
    let values = to_vec(&batch.images);
    assert!(values.iter().all(|v| (-1.0..=1.0).contains(v)));
}

#[test]
fn sampler_errors_name_the_missing_photo() {
    let dir = tempfile::tempdir().unwrap();
    let dataset = bright_pixel_dataset(dir.path(), 16, &[(8, 8)]);
    std::fs::remove_file(dir.path().join("images/000.png")).unwrap();
    let err = CropSampler::new(8, 0)
        .unwrap()
        .sample(&dataset, 2, &Device::Cpu)
        .unwrap_err()
        .to_string();
    assert!(err.contains("000.png"), "{err}");
    assert!(CropSampler::new(0, 0).is_err());
    assert!(
        CropSampler::new(8, 0)
            .unwrap()
            .sample(&dataset, 0, &Device::Cpu)
            .is_err()
    );
}

#[test]
fn sampler_crops_a_prepared_simulation() {
    use photomat_data::dataset::{PrepareOptions, prepare};
    use photomat_data::procedural::families;
    use photomat_data::simulator::{
        CameraSource, HighlightJitter, PhoneCamera, PhotoFormat, SimulationConfig, simulate,
    };
    // simulate → prepare (resize 64 → 32, truth carried over) → crops of a model of size 8
    // (photos resized again, 32 → 16).
    let dir = tempfile::tempdir().unwrap();
    let (sim, data) = (dir.path().join("sim"), dir.path().join("data"));
    let all = families();
    let config = SimulationConfig {
        count: 4,
        size: 64,
        seed: 2,
        format: PhotoFormat::Jpeg,
        families: all.iter().take(4).map(|f| f.as_ref()).collect(),
        camera: CameraSource::Phone(PhoneCamera::default()),
        jitter: HighlightJitter::default(),
        pose: Default::default(),
    };
    let record = simulate(&sim, &config, false, &|| {}).unwrap();
    let options = PrepareOptions {
        size: 32,
        progress: false,
        ..PrepareOptions::default()
    };
    prepare(&sim.join("photos"), &data, &options).unwrap();
    let dataset = FlashDataset::open(&data).unwrap();
    assert_eq!((dataset.len(), dataset.size()), (4, 32));
    // The index carries the simulator's truth, scaled to the prepared size.
    for (entry, truth) in dataset.photos().iter().zip(&record.photos) {
        let t = entry
            .truth_highlight_px
            .expect("prepare found simulation.json");
        assert!((t[0] - truth.highlight_px[0] / 2.0).abs() < 1e-9, "{t:?}");
        assert!((t[1] - truth.highlight_px[1] / 2.0).abs() < 1e-9, "{t:?}");
    }
    let batch = CropSampler::new(8, 1)
        .unwrap()
        .sample(&dataset, 6, &Device::Cpu)
        .unwrap();
    assert_eq!(batch.images.dims(), &[6, 3, 8, 8]);
    assert!(
        to_vec(&batch.images)
            .iter()
            .all(|v| (-1.0..=1.0).contains(v))
    );
    // Highlights near the photo centre land within the crop or just beyond its edge: the
    // crop's centre is at most ½ from the photo's, the highlight a few % of the width from it.
    for h in LightSampler::new(&dataset, 8, 1).unwrap().sample(64) {
        assert!(h.x.abs() < 0.8 && h.y.abs() < 0.8, "{h:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn patch_omega_is_the_photo_omega_cut_at_the_patch(
        photo in 2usize..40,
        patch_frac in 0.0f64..=1.0,
        // Highlights inside the photo and up to a quarter of it beyond.
        hr in -0.25f64..1.25,
        hc in -0.25f64..1.25,
        top_frac in 0.0f64..=1.0,
        left_frac in 0.0f64..=1.0,
        symmetry in 0usize..8,
    ) {
        let p = 1 + (patch_frac * (photo - 1) as f64).round() as usize;
        let highlight_px = (hr * photo as f64, hc * photo as f64);
        let patch = PatchWindow {
            window: CropWindow {
                size: p,
                top: (top_frac * (photo - p) as f64).round() as usize,
                left: (left_frac * (photo - p) as f64).round() as usize,
                symmetry: Symmetry::ALL[symmetry],
            },
            photo_size: photo,
        };
        prop_assert_eq!(patch.side(), 2.0 * p as f64 / photo as f64);
        // The photo: the side-2 square, flash at height 1 above its highlight.
        let whole = FlashGeometry::with_side(
            &[Highlight::from_pixel_on(highlight_px.0, highlight_px.1, photo, 2.0)],
            photo,
            2.0,
            DType::F64,
            &Device::Cpu,
        )
        .unwrap();
        let cut = FlashGeometry::with_side(
            &[patch.highlight(highlight_px)],
            p,
            patch.side(),
            DType::F64,
            &Device::Cpu,
        )
        .unwrap();
        assert_cut_of(&cut, &whole, photo, &patch.window)?;
    }
}

#[test]
fn patch_sampler_cuts_native_pixels_and_moves_the_highlight() {
    let dir = tempfile::tempdir().unwrap();
    let (size, p) = (32, 8);
    let dataset = bright_pixel_dataset(dir.path(), size, &[(5, 9), (16, 16), (27, 3)]);
    let options = PatchOptions {
        size: p,
        highlight_prob: 0.5,
    };
    let batch = PatchSampler::new(options, 3)
        .sample(&dataset, 24, &Device::Cpu)
        .unwrap();
    assert_eq!(batch.images.dims(), &[24, 3, p, p]);
    assert_eq!(batch.side, patch_side(p, size));
    assert_eq!(batch.side, 0.5);
    let mut inside = 0;
    for (b, highlight) in batch.highlights.iter().enumerate() {
        let patch = item(&batch.images, b);
        let bright: Vec<(usize, usize)> = (0..p * p)
            .filter(|t| patch.data[p * p + t] > 0.9)
            .map(|t| (t / p, t % p))
            .collect();
        let (row, col) = highlight.to_pixel_on(p, batch.side);
        if (0.0..p as f64).contains(&row) && (0.0..p as f64).contains(&col) {
            inside += 1;
            assert_eq!(
                bright,
                vec![(row.floor() as usize, col.floor() as usize)],
                "item {b}: highlight ({row}, {col})"
            );
        } else {
            assert!(
                bright.is_empty(),
                "item {b}: highlight ({row}, {col}) outside"
            );
        }
        // ω belongs to the returned placement.
        let expected =
            FlashGeometry::with_side(&[*highlight], p, batch.side, DType::F32, &Device::Cpu)
                .unwrap()
                .omega;
        let diff = (batch.omega.narrow(0, b, 1).unwrap() - expected)
            .unwrap()
            .abs()
            .unwrap()
            .max_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap();
        assert_eq!(diff, 0.0);
    }
    // Half the patches are placed over the highlight; uniform ones rarely hold it.
    assert!(
        (8..=20).contains(&inside),
        "{inside} of 24 hold the highlight"
    );
    // Same seed, same draws; the light sampler draws the same placements without pixels.
    let again = PatchSampler::new(options, 3)
        .sample(&dataset, 24, &Device::Cpu)
        .unwrap();
    assert_eq!(to_vec(&again.images), to_vec(&batch.images));
    let mut lights = PatchLightSampler::new(&dataset, options, 3).unwrap();
    assert_eq!(lights.side(), batch.side);
    assert_eq!(lights.sample(24), batch.highlights);
    // Patches larger than the photos are refused.
    let err = PatchLightSampler::new(
        &dataset,
        PatchOptions {
            size: 33,
            highlight_prob: 0.5,
        },
        0,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("33"), "{err}");
}

/// The fraction of `n` placements of `options` whose highlight lies inside the patch.
fn inside_fraction(dataset: &FlashDataset, options: PatchOptions, n: usize) -> f64 {
    let mut lights = PatchLightSampler::new(dataset, options, 17).unwrap();
    let half = lights.side() / 2.0;
    let inside = lights
        .sample(n)
        .iter()
        .filter(|h| h.x.abs() < half && h.y.abs() < half)
        .count();
    inside as f64 / n as f64
}

#[test]
fn patch_highlight_option_sets_how_often_the_highlight_is_inside() {
    let dir = tempfile::tempdir().unwrap();
    let (size, p) = (64, 8);
    let dataset = bright_pixel_dataset(dir.path(), size, &[(32, 32), (30, 36), (25, 40)]);
    // Exact under uniform positions: for a highlight at pixel centre 32.5 each axis has
    // P of the S − P + 1 offsets holding it.
    let centred = bright_pixel_dataset(&dir.path().join("c"), size, &[(32, 32)]);
    let exact = uniform_highlight_inside(&centred, p).unwrap();
    let expected = (8.0f64 / 57.0).powi(2);
    assert!((exact - expected).abs() < 1e-15, "{exact} vs {expected}");
    // Sampled placements follow it (20 000 draws: standard error 0.001).
    let uniform = uniform_highlight_inside(&dataset, p).unwrap();
    let n = 20_000;
    let at = |highlight_prob| {
        inside_fraction(
            &dataset,
            PatchOptions {
                size: p,
                highlight_prob,
            },
            n,
        )
    };
    let sampled = at(0.0);
    assert!((sampled - uniform).abs() < 0.005, "{sampled} vs {uniform}");
    assert_eq!(at(1.0), 1.0);
    let half = at(0.5);
    let target = 0.5 + 0.5 * uniform;
    assert!((half - target).abs() < 0.02, "{half} vs {target}");
}

#[test]
fn patch_uniform_positions_rarely_hold_the_highlight_of_simulated_photos() {
    use photomat_data::dataset::{PrepareOptions, prepare};
    use photomat_data::procedural::families;
    use photomat_data::simulator::{
        CameraSource, HighlightJitter, PhoneCamera, PhotoFormat, SimulationConfig, simulate,
    };
    // Photos prepared at 128 with 16² patches: the S/P = 8 of 64² patches of 512² photos.
    let dir = tempfile::tempdir().unwrap();
    let (sim, data) = (dir.path().join("sim"), dir.path().join("data"));
    let all = families();
    let config = SimulationConfig {
        count: 8,
        size: 128,
        seed: 4,
        format: PhotoFormat::Png,
        families: all.iter().map(|f| f.as_ref()).collect(),
        camera: CameraSource::Phone(PhoneCamera::default()),
        jitter: HighlightJitter::default(),
        pose: Default::default(),
    };
    simulate(&sim, &config, false, &|| {}).unwrap();
    let options = PrepareOptions {
        size: 128,
        progress: false,
        ..PrepareOptions::default()
    };
    prepare(&sim.join("photos"), &data, &options).unwrap();
    let dataset = FlashDataset::open(&data).unwrap();
    let uniform = uniform_highlight_inside(&dataset, 16).unwrap();
    // (16/113)² = 2.0 % for exactly centred highlights; the simulator's jitter moves some
    // highlights towards the border, where fewer windows hold them.
    println!("uniform 16² patches of 128² simulated photos hold the highlight: {uniform:.4}");
    assert!(uniform > 0.0 && uniform < 0.03, "{uniform}");
}
