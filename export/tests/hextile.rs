//! HexTiling properties: no seam at the input's period, one lattice for every map (linear
//! maps commute with it), determinism per seed, partition of unity, and rotated normal maps
//! consistent with the normals of the rotated height.

use candle_core::{Device, Tensor};
use photomat_brdfs as _;
use photomat_core::MaterialMaps;
use photomat_core::image_io::PlanarImage;
use photomat_export::hextile::{Content, HexTiling, hextile};

const R: usize = 32;

/// A smooth periodic image: sums of integer-frequency sinusoids, values in [0, 1].
fn periodic(channels: usize, seed: u64) -> PlanarImage {
    let mut rng = photomat_core::rng::SplitMix64(seed);
    let mut data = Vec::new();
    for _ in 0..channels {
        let waves: Vec<[f64; 4]> = (0..4)
            .map(|_| {
                [
                    (rng.next_unit() * 4.0).floor() + 1.0,
                    (rng.next_unit() * 4.0).floor(),
                    rng.next_unit() * std::f64::consts::TAU,
                    0.1 + 0.1 * rng.next_unit(),
                ]
            })
            .collect();
        for row in 0..R {
            for col in 0..R {
                let (x, y) = (col as f64 / R as f64, row as f64 / R as f64);
                let v: f64 = waves
                    .iter()
                    .map(|[fx, fy, p, a]| a * (std::f64::consts::TAU * (fx * x + fy * y) + p).sin())
                    .sum();
                data.push((0.5 + v) as f32);
            }
        }
    }
    PlanarImage::new(channels, R, R, data).unwrap()
}

/// Absolute differences between horizontal and vertical neighbours, split into those across
/// the input's period boundaries (column/row multiples of R) and the rest.
fn neighbour_differences(image: &PlanarImage) -> (Vec<f32>, Vec<f32>) {
    let (mut seam, mut interior) = (Vec::new(), Vec::new());
    for c in 0..image.channels {
        for row in 0..image.height {
            for col in 0..image.width {
                let v = image.get(c, row, col);
                if col + 1 < image.width {
                    let d = (image.get(c, row, col + 1) - v).abs();
                    if (col + 1) % R == 0 {
                        &mut seam
                    } else {
                        &mut interior
                    }
                    .push(d);
                }
                if row + 1 < image.height {
                    let d = (image.get(c, row + 1, col) - v).abs();
                    if (row + 1) % R == 0 {
                        &mut seam
                    } else {
                        &mut interior
                    }
                    .push(d);
                }
            }
        }
    }
    (seam, interior)
}

fn max(v: &[f32]) -> f32 {
    v.iter().copied().fold(0.0, f32::max)
}

#[test]
fn hextile_has_no_seam_at_the_period() {
    let input = periodic(3, 1);
    for tiling in [
        HexTiling::default(),
        HexTiling {
            seed: 9,
            rotation: 1.0,
            gain: 0.7,
            ..HexTiling::default()
        },
    ] {
        let out = hextile(
            &tiling,
            &[(&input, Content::Scalar)],
            Some(&input),
            2 * R,
            2 * R,
        )
        .unwrap()
        .remove(0);
        let (seam, interior) = neighbour_differences(&out);
        assert!(!seam.is_empty());
        assert!(
            max(&seam) <= max(&interior),
            "seam step {} above every interior step (max {})",
            max(&seam),
            max(&interior)
        );
    }
    // The measure sees a seam when there is one: a non-periodic ramp tiled 2×2.
    let ramp = PlanarImage::new(
        1,
        R,
        R,
        (0..R * R).map(|i| (i % R) as f32 / R as f32).collect(),
    )
    .unwrap();
    let tiled = PlanarImage::new(
        1,
        R,
        2 * R,
        (0..R * 2 * R)
            .map(|i| ramp.data[(i / (2 * R)) * R + i % R])
            .collect(),
    )
    .unwrap();
    let (seam, interior) = neighbour_differences(&tiled);
    assert!(max(&seam) > 10.0 * max(&interior));
}

#[test]
fn hextile_is_deterministic_per_seed() {
    let input = periodic(3, 2);
    let run = |seed| {
        let tiling = HexTiling {
            seed,
            rotation: 0.5,
            ..HexTiling::default()
        };
        hextile(&tiling, &[(&input, Content::Scalar)], Some(&input), 48, 40)
            .unwrap()
            .remove(0)
    };
    let a = run(5);
    assert_eq!(a, run(5));
    assert_eq!((a.channels, a.height, a.width), (3, 48, 40));
    assert_ne!(a, run(6));
}

#[test]
fn hextile_applies_one_lattice_to_every_map() {
    // Blending is linear with weights shared by all maps: an affine function of one map is
    // hex-tiled into the same affine function of its hex-tiling.
    let a = periodic(3, 3);
    let b = a.map(|v| 0.25 * v + 0.1);
    let tiling = HexTiling {
        seed: 4,
        rotation: 1.0,
        ..HexTiling::default()
    };
    let out = hextile(
        &tiling,
        &[(&a, Content::Scalar), (&b, Content::Scalar)],
        Some(&a),
        2 * R,
        2 * R,
    )
    .unwrap();
    for (x, y) in out[0].data.iter().zip(&out[1].data) {
        assert!((0.25 * x + 0.1 - y).abs() < 1e-5, "{x} {y}");
    }
    // Partition of unity: a constant stays constant.
    let flat = PlanarImage::filled(1, R, R, 0.3);
    let out = hextile(&tiling, &[(&flat, Content::Scalar)], Some(&a), 40, 40).unwrap();
    assert!(out[0].data.iter().all(|v| (v - 0.3).abs() < 1e-6));
}

/// The shading normal the height adapter derives from `height` ((1, 1, n, n)) with `scale`.
fn derived_normal(height: &PlanarImage, scale: f64) -> PlanarImage {
    let brdf = photomat_core::lookup(&format!("height(lambert, scale={scale})")).unwrap();
    let n = height.height;
    let maps = MaterialMaps::new()
        .with(
            "diffuse",
            Tensor::full(0.5f32, (1, 3, n, n), &Device::Cpu).unwrap(),
        )
        .with("height", height.to_tensor(&Device::Cpu).unwrap());
    let shading = brdf.shading_maps(&maps).unwrap();
    PlanarImage::from_tensor(shading.get("normal").unwrap()).unwrap()
}

/// Mean cosine between the tilt directions of the hex-tiled normal map and the normals derived
/// from the hex-tiled height, where both are tilted.
fn tilt_agreement(rotation: f64) -> f64 {
    let height = periodic(1, 8);
    let scale = 0.05;
    let normal = derived_normal(&height, scale);
    let tiling = HexTiling {
        seed: 2,
        rotation,
        exponent: 40.0,
        contrast: 0.0,
        ..HexTiling::default()
    };
    let out = hextile(
        &tiling,
        &[
            (&height, Content::Scalar),
            (&normal, Content::TangentNormal),
        ],
        None,
        2 * R,
        2 * R,
    )
    .unwrap();
    // The output spans two periods on the unit square: half the scale keeps the slopes.
    let expected = derived_normal(&out[0], scale / 2.0);
    let plane = 4 * R * R;
    let (mut agree, mut tilted) = (0.0f64, 0usize);
    for t in 0..plane {
        let a = [0, 1].map(|c| out[1].data[c * plane + t] as f64);
        let b = [0, 1].map(|c| expected.data[c * plane + t] as f64);
        let (la, lb) = (a[0].hypot(a[1]), b[0].hypot(b[1]));
        if la > 0.05 && lb > 0.05 {
            agree += (a[0] * b[0] + a[1] * b[1]) / (la * lb);
            tilted += 1;
        }
    }
    assert!(tilted > plane / 4, "{tilted}");
    agree / tilted as f64
}

#[test]
fn hextile_rotates_normal_maps_with_their_copies() {
    // Blending normals is not differentiating the blended height (the weights vary), so even
    // unrotated copies agree only on average (cosine ≈ 0.77 here); rotating the copies must
    // not lose more. Rotating the normals the wrong way round gives a cosine near 0.
    let unrotated = tilt_agreement(0.0);
    let rotated = tilt_agreement(1.0);
    assert!(unrotated > 0.6, "{unrotated}");
    assert!(
        rotated > unrotated - 0.05,
        "rotated copies' normals disagree with their heights: {rotated} vs {unrotated} unrotated"
    );
}
