//! The phone-flash simulator end to end: determinism, the ideal camera against the analytic
//! renderer, the recorded highlight against the rendered peak (overhead and hand-held poses),
//! the posed renderer against the collocated one, and the ground truth on disk.

use std::collections::BTreeMap;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use photomat_brdfs as _;
use photomat_core::image_io::{PlanarImage, read_png};
use photomat_core::map_files::load_maps;
use photomat_core::{
    FlashGeometry, Highlight, MaterialMaps, Result, encode_display, lookup, render_radiance_with,
};
use photomat_data::procedural::{Family, families, family};
use photomat_data::simulator::random::photo_rng;
use photomat_data::simulator::{
    CameraModel, CameraSource, HighlightJitter, PHOTO_SIDE, PhoneCamera, PhonePose, PhotoFormat,
    PoseJitter, Scene, SimulationConfig, SimulationManifest, simulate, write_photo,
};

/// Every file under `dir` (relative path → bytes).
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let rel = path
                    .strip_prefix(root)
                    .unwrap()
                    .to_string_lossy()
                    .into_owned();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

fn config<'a>(all: &'a [Box<dyn Family>], seed: u64) -> SimulationConfig<'a> {
    SimulationConfig {
        count: all.len() + 2,
        size: 32,
        seed,
        format: PhotoFormat::Jpeg,
        families: all.iter().map(|f| f.as_ref()).collect(),
        camera: CameraSource::Phone(PhoneCamera::default()),
        jitter: HighlightJitter::default(),
        pose: Default::default(),
    }
}

/// Run `config` into a fresh folder on a pool of `threads` threads.
fn run(config: &SimulationConfig<'_>, threads: usize) -> (tempfile::TempDir, SimulationManifest) {
    let dir = tempfile::tempdir().unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let manifest = pool
        .install(|| simulate(dir.path(), config, false, &|| {}))
        .unwrap();
    (dir, manifest)
}

#[test]
fn simulator_same_seed_gives_identical_bytes_whatever_the_threads() {
    let all = families();
    let (a, manifest) = run(&config(&all, 7), 1);
    let (b, _) = run(&config(&all, 7), 3);
    let (c, _) = run(&config(&all, 8), 2);
    let (ta, tb, tc) = (tree(a.path()), tree(b.path()), tree(c.path()));
    assert_eq!(ta.keys().collect::<Vec<_>>(), tb.keys().collect::<Vec<_>>());
    for (name, bytes) in &ta {
        assert!(bytes == &tb[name], "{name} differs between equal seeds");
    }
    // Another seed: every photo and the record change.
    assert_eq!(ta.keys().collect::<Vec<_>>(), tc.keys().collect::<Vec<_>>());
    for (name, bytes) in &ta {
        if name.starts_with("photos/") || name == "simulation.json" {
            assert!(bytes != &tc[name], "{name} equal under different seeds");
        }
    }
    // Families cycle in order; the record points at files that exist.
    assert_eq!(manifest.photos.len(), all.len() + 2);
    for (i, photo) in manifest.photos.iter().enumerate() {
        assert_eq!(photo.family, all[i % all.len()].name());
        assert_eq!(photo.photo, format!("photos/{i:06}.jpg"));
        assert!(ta.contains_key(&photo.photo));
        assert!(ta.contains_key(&format!("{}/material.json", photo.truth)));
    }
    assert_eq!(SimulationManifest::read(a.path()).unwrap(), manifest);
}

#[test]
fn simulator_truth_loads_back_and_regenerates_from_the_record() {
    let all = families();
    let (dir, manifest) = run(&config(&all, 3), 2);
    for photo in &manifest.photos {
        let loaded = load_maps(&dir.path().join(&photo.truth), None).unwrap();
        let (batch, h, w) = loaded.maps.batch_and_size().unwrap();
        assert_eq!((batch, h, w), (1, 32, 32), "{}", photo.truth);
        // Truth is in the shading model: no adapter left.
        assert!(
            ["ggx", "coated", "lambert"].contains(&loaded.brdf.name().as_str()),
            "{}: {}",
            photo.truth,
            loaded.brdf.name()
        );
        // The recorded family and seed give the same maps (EXR is exact).
        let scene = Scene::from_family(
            family(&photo.family).unwrap().as_ref(),
            32,
            photo.family_seed,
            &Device::Cpu,
        )
        .unwrap();
        for (name, map) in scene.maps().iter() {
            let stored = loaded.maps.get(name).unwrap();
            let diff = max_abs(&(map - stored).unwrap());
            assert_eq!(diff, 0.0, "{} map {name}", photo.truth);
        }
        // The recorded plane highlight is the recorded pixel highlight on the side-2 photo.
        let h = Highlight::from_pixel_on(photo.highlight_px[0], photo.highlight_px[1], 32, 2.0);
        assert_eq!([h.x, h.y], photo.highlight);
        photo.camera.validate().unwrap();
    }
}

fn max_abs(t: &Tensor) -> f32 {
    t.abs()
        .unwrap()
        .flatten_all()
        .unwrap()
        .max(0)
        .unwrap()
        .to_scalar::<f32>()
        .unwrap()
}

fn constant(values: &[f32], size: usize) -> Tensor {
    Tensor::from_slice(values, (1, values.len(), 1, 1), &Device::Cpu)
        .unwrap()
        .broadcast_as((1, values.len(), size, size))
        .unwrap()
        .contiguous()
        .unwrap()
}

#[test]
fn simulator_ideal_white_lambert_photo_is_the_analytic_render() {
    let size = 64;
    let brdf = lookup("lambert").unwrap();
    let maps = MaterialMaps::new()
        .with("diffuse", constant(&[1.0, 1.0, 1.0], size))
        .with("normal", constant(&[0.0, 0.0, 1.0], size));
    let scene = Scene::new(brdf.clone(), maps.clone()).unwrap();
    let highlight = Highlight::from_pixel_on(29.3, 35.8, size, PHOTO_SIDE);
    let photo = scene
        .photograph(highlight, &CameraModel::ideal(), &mut photo_rng(0, 0))
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("white.png");
    write_photo(&path, &photo, PhotoFormat::Png).unwrap();
    let (stored, _) = read_png(&path).unwrap();

    let geometry =
        FlashGeometry::with_side(&[highlight], size, 2.0, DType::F32, &Device::Cpu).unwrap();
    let render =
        encode_display(&render_radiance_with(brdf.as_ref(), &maps, &geometry).unwrap()).unwrap();
    let expected = PlanarImage::from_tensor(&render).unwrap();
    assert_eq!(
        (stored.channels, stored.height, stored.width),
        (3, size, size)
    );
    // 8-bit rounding errs by at most half a step (+ f32 rounding).
    let worst = stored
        .data
        .iter()
        .zip(&expected.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(worst <= 0.5 / 255.0 + 1e-6, "worst difference {worst}");
    // A white Lambertian texel next to the highlight is nearly white; the corners are dark.
    assert!(stored.get(1, 29, 35) > 0.99);
    assert!(stored.get(1, 63, 0) < 0.6);
}

/// A flat, black, near-mirror GGX material: the flash's reflection is one sharp peak
/// straight under the flash.
struct Mirror;

impl Family for Mirror {
    fn name(&self) -> &'static str {
        "mirror"
    }

    fn brdf(&self) -> String {
        "ggx".into()
    }

    fn generate(&self, size: usize, _seed: u64, _device: &Device) -> Result<MaterialMaps> {
        Ok(MaterialMaps::new()
            .with("diffuse", constant(&[0.0, 0.0, 0.0], size))
            .with("specular", constant(&[0.04, 0.04, 0.04], size))
            .with("roughness", constant(&[0.2], size))
            .with("normal", constant(&[0.0, 0.0, 1.0], size)))
    }
}

/// Twelve PNG photos of [`Mirror`] by a fixed camera exposed for its peak.
fn mirror_photos(
    size: usize,
    seed: u64,
    jitter: HighlightJitter,
    pose: PoseJitter,
) -> SimulationConfig<'static> {
    SimulationConfig {
        count: 12,
        size,
        seed,
        format: PhotoFormat::Png,
        families: vec![&Mirror as &dyn Family],
        // Peak radiance of the lobe (α = 0.2² = 0.04): F0·D(0)·π/4 = 0.04/(π·0.04²)·π/4 =
        // 6.25; expose it to 0.75 so the peak is not clipped (a texel centre half a pixel
        // away from the highlight still gets 3/4 of it).
        camera: CameraSource::Fixed(CameraModel {
            exposure: 0.12,
            ..CameraModel::ideal()
        }),
        jitter,
        pose,
    }
}

#[test]
fn simulator_recorded_highlight_is_the_rendered_peak() {
    let size = 64;
    let jitter = HighlightJitter {
        sigma: 0.08,
        ..HighlightJitter::default()
    };
    let config = mirror_photos(size, 11, jitter, PoseJitter::default());
    let (dir, manifest) = run(&config, 2);
    let mut off_centre = 0;
    for photo in &manifest.photos {
        let (image, _) = read_png(&dir.path().join(&photo.photo)).unwrap();
        let [row, col] = photo.highlight_px;
        let (i, j) = (row.floor() as usize, col.floor() as usize);
        let peak = image.data.iter().copied().fold(0f32, f32::max);
        assert!(peak > 0.5, "{}: peak {peak}", photo.photo);
        for c in 0..3 {
            assert_eq!(
                image.get(c, i, j),
                peak,
                "{}: highlight ({row}, {col}) is not on the brightest pixel",
                photo.photo
            );
        }
        if (row - 32.0).abs() > 2.0 || (col - 32.0).abs() > 2.0 {
            off_centre += 1;
        }
    }
    // The jitter did move the highlight: the check is not only about the centre.
    assert!(off_centre >= 6, "{off_centre} of 12 off-centre");
}

#[test]
fn simulator_hand_held_highlight_is_the_rendered_peak() {
    // The mirror material of the overhead test, photographed by a tilted phone with the
    // flash beside the lens: the recorded highlight (the flash's mirror point seen through
    // the lens) must still be where the photo is brightest.
    let size = 64;
    let config = mirror_photos(size, 5, HighlightJitter::default(), PoseJitter::HAND_HELD);
    let (dir, manifest) = run(&config, 2);
    let mut moved = 0;
    for photo in &manifest.photos {
        let pose = photo.pose.expect("a hand-held photo records its pose");
        assert!(pose.tilt_degrees <= 12.0);
        let (image, _) = read_png(&dir.path().join(&photo.photo)).unwrap();
        let brightest = (0..image.texels())
            .max_by(|&a, &b| {
                image
                    .get(1, a / size, a % size)
                    .total_cmp(&image.get(1, b / size, b % size))
            })
            .unwrap();
        let peak = (
            (brightest / size) as f64 + 0.5,
            (brightest % size) as f64 + 0.5,
        );
        let [row, col] = photo.highlight_px;
        // The lobe's peak sits on the mirror point up to the pixel grid and the slight pull
        // of cos θ and 1/d² (under a pixel at this roughness).
        assert!(
            (peak.0 - row).abs() <= 1.0 && (peak.1 - col).abs() <= 1.0,
            "{}: brightest pixel centre {peak:?}, recorded highlight ({row}, {col}), {pose:?}",
            photo.photo
        );
        if (row - 32.0).abs().max((col - 32.0).abs()) > 3.0 {
            moved += 1;
        }
    }
    // Tilts up to 12° move the mirror point by up to tan(24°)/2 ≈ 22 % of the width: most
    // photos' highlights are well off the jittered centre.
    assert!(moved >= 6, "{moved} of 12 highlights moved by the tilt");
}

#[test]
fn simulator_posed_renderer_with_an_untilted_lens_flash_equals_the_collocated_one() {
    // A pose that differs from the overhead one only in the axis of a zero tilt takes the
    // posed path (separate light and view directions, resampled maps) through the same
    // geometry: it must give the collocated renderer's light and the same maps.
    let size = 48;
    let all = families();
    let highlight = Highlight::from_pixel_on(21.7, 26.2, size, PHOTO_SIDE);
    let pose = PhonePose {
        tilt_azimuth_degrees: 90.0,
        ..PhonePose::OVERHEAD
    };
    for family in &all {
        let scene = Scene::from_family(family.as_ref(), size, 3, &Device::Cpu).unwrap();
        let expected = scene.light(highlight).unwrap();
        let (seen, light) = scene.seen_from(highlight, &pose).unwrap();
        for (name, map) in scene.maps().iter() {
            let diff = (map - seen.maps().get(name).unwrap()).unwrap();
            assert!(max_abs(&diff) < 1e-6, "{}: map {name} moved", family.name());
        }
        let worst = light
            .flash
            .data
            .iter()
            .zip(&expected.flash.data)
            .map(|(a, b)| (a - b).abs() / b.abs().max(1e-3))
            .fold(0f32, f32::max);
        assert!(
            worst < 1e-4,
            "{}: relative difference {worst}",
            family.name()
        );
        assert_eq!(light.ambient_reflectance, expected.ambient_reflectance);
    }
}

#[test]
fn simulator_refuses_to_overwrite_unless_asked() {
    let all = families();
    let mut config = config(&all, 1);
    config.count = 2;
    config.families.truncate(1);
    let (dir, _) = run(&config, 1);
    let err = simulate(dir.path(), &config, false, &|| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("already holds a simulation"), "{err}");
    config.count = 1;
    let manifest = simulate(dir.path(), &config, true, &|| {}).unwrap();
    assert_eq!(manifest.photos.len(), 1);
    // The second run left no photo of the first behind.
    assert_eq!(
        std::fs::read_dir(dir.path().join("photos"))
            .unwrap()
            .count(),
        1
    );
}
