//! The collocated-flash renderer (`docs/conventions.md`, "Radiance"): exact values under the flash,
//! the 1/d³ falloff of a Lambertian plane, highlight placement, batching, periodicity of the height
//! adapter, decoding of raw network output, and clear errors for bad maps.

use candle_core::{DType, Device, Tensor};
use photomat_brdfs::height::HeightToNormal;
use photomat_core::flash::texel_center;
use photomat_core::{Highlight, MaterialMaps, render, render_radiance};
use photomat_tests::{model, random_maps, rng, values};

fn white_lambert(size: usize) -> MaterialMaps {
    let brdf = model("lambert");
    MaterialMaps::defaults(brdf.params(), 1, size, DType::F32, &Device::Cpu)
        .unwrap()
        .with(
            "diffuse",
            Tensor::ones((1, 3, size, size), DType::F32, &Device::Cpu).unwrap(),
        )
}

#[test]
fn renderer_flat_white_lambert_under_the_flash_is_one() {
    // Odd sizes put a texel centre exactly under a centred flash.
    for size in [1, 5, 33] {
        let img = render(
            model("lambert").as_ref(),
            &white_lambert(size),
            &[Highlight::CENTER],
        )
        .unwrap();
        let c = size / 2;
        for ch in 0..3 {
            let v = img
                .get(0)
                .unwrap()
                .get(ch)
                .unwrap()
                .get(c)
                .unwrap()
                .get(c)
                .unwrap();
            let v = v.to_scalar::<f32>().unwrap();
            assert!((v - 1.0).abs() <= 2.0 * f32::EPSILON, "size {size}: {v}");
        }
    }
}

#[test]
fn renderer_lambert_falloff_matches_the_closed_form() {
    // White Lambert, flash at (0, 0, 1): radiance = π·(1/π)·cos θ/d² = 1/d³ with d the distance
    // to the flash; the ratio corner/centre is therefore d_corner⁻³.
    let size = 65;
    let radiance = values(
        &render_radiance(
            model("lambert").as_ref(),
            &white_lambert(size),
            &[Highlight::CENTER],
        )
        .unwrap(),
    );
    let plane = size * size;
    for (row, col) in [(0, 0), (0, size - 1), (size - 1, size / 2), (17, 40)] {
        let d = (Highlight::CENTER.flash_position() - texel_center(row, col, size)).length();
        let expected = d.powi(-3);
        for ch in 0..3 {
            let v = radiance[ch * plane + row * size + col];
            assert!(
                (v - expected).abs() <= 1e-6 * expected,
                "texel ({row},{col}): {v} vs {expected}"
            );
        }
    }
}

#[test]
fn renderer_highlight_lands_under_the_flash() {
    // A near-mirror GGX material peaks where ω is the normal, i.e. straight under the flash.
    let size = 64;
    let brdf = model("ggx");
    let maps = MaterialMaps::defaults(brdf.params(), 1, size, DType::F32, &Device::Cpu)
        .unwrap()
        .with(
            "roughness",
            Tensor::full(0.15f32, (1, 1, size, size), &Device::Cpu).unwrap(),
        );
    for (row, col) in [(10.5, 50.5), (32.5, 32.5), (60.5, 3.5)] {
        let light = Highlight::from_pixel(row, col, size);
        let img = values(
            &render_radiance(brdf.as_ref(), &maps, &[light])
                .unwrap()
                .narrow(1, 0, 1)
                .unwrap(),
        );
        let argmax = img
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap()
            .0;
        assert_eq!((argmax / size, argmax % size), (row as usize, col as usize));
        let (r, c) = light.to_pixel(size);
        assert!(
            (r - row).abs() < 1e-12 && (c - col).abs() < 1e-12,
            "pixel round trip"
        );
    }
}

#[test]
fn renderer_one_material_under_many_lights_equals_separate_renders() {
    let brdf = model("height(ggx)");
    let maps = random_maps(&brdf, &mut rng(20), 16, 0.1, DType::F32);
    let lights = [
        Highlight::new(0.2, 0.1),
        Highlight::new(-0.3, 0.4),
        Highlight::CENTER,
    ];
    let together = values(&render(brdf.as_ref(), &maps, &lights).unwrap());
    let separate: Vec<f64> = lights
        .iter()
        .flat_map(|l| values(&render(brdf.as_ref(), &maps, &[*l]).unwrap()))
        .collect();
    assert_eq!(together, separate);
}

#[test]
fn height_adapter_normals_of_a_periodic_field_are_periodic() {
    // h(x, y) = ½ + ¼ sin(2πx)·cos(2πy) on the unit square is periodic; its normals from
    // wrap-around central differences must (a) roll with the height map and (b) match the
    // analytic slope at the borders as well as inside (no seam).
    let size = 64;
    let adapter = HeightToNormal { scale: 0.05 };
    let mut h = vec![0f64; size * size];
    for row in 0..size {
        for col in 0..size {
            let p = texel_center(row, col, size);
            h[row * size + col] = 0.5
                + 0.25
                    * (2.0 * std::f64::consts::PI * p.x).sin()
                    * (2.0 * std::f64::consts::PI * p.y).cos();
        }
    }
    let height = Tensor::from_vec(h, (1, 1, size, size), &Device::Cpu).unwrap();
    let normals = adapter.normals(&height).unwrap();
    let rolled = adapter
        .normals(&height.roll(7, 3).unwrap().roll(-5, 2).unwrap())
        .unwrap();
    assert_eq!(
        values(&rolled),
        values(&normals.roll(7, 3).unwrap().roll(-5, 2).unwrap())
    );

    let n = values(&normals);
    let plane = size * size;
    let two_pi = 2.0 * std::f64::consts::PI;
    // Central differences of sin over ±1/R shrink the slope by sinc: sin(2π/R)/(2π/R).
    let shrink = (two_pi / size as f64).sin() / (two_pi / size as f64);
    for (row, col) in [(0, 0), (0, 31), (63, 63), (31, 0), (20, 45)] {
        let p = texel_center(row, col, size);
        let dhdx = 0.25 * two_pi * (two_pi * p.x).cos() * (two_pi * p.y).cos() * shrink;
        let dhdy = -0.25 * two_pi * (two_pi * p.x).sin() * (two_pi * p.y).sin() * shrink;
        let v = glam::DVec3::new(-0.05 * dhdx, -0.05 * dhdy, 1.0).normalize();
        let t = row * size + col;
        for (c, e) in [v.x, v.y, v.z].iter().enumerate() {
            assert!(
                (n[c * plane + t] - e).abs() < 1e-12,
                "texel ({row},{col}) channel {c}: {} vs {e}",
                n[c * plane + t]
            );
        }
    }
}

#[test]
fn decode_gives_maps_that_validate_for_every_model() {
    for spec in &photomat_tests::models_under_test() {
        let brdf = model(spec);
        let raw =
            (Tensor::randn(0f32, 3.0, (2, brdf.channels(), 8, 8), &Device::Cpu).unwrap()).clone();
        let maps = brdf.decode(&raw).unwrap();
        maps.validate(&brdf.name(), brdf.params()).unwrap();
        for p in brdf.params() {
            for v in values(maps.get(p.name).unwrap()) {
                assert!(
                    v >= p.range.0 as f64 && v <= p.range.1 as f64,
                    "{spec}.{}: {v}",
                    p.name
                );
            }
        }
        let err = brdf
            .decode(&raw.narrow(1, 1, brdf.channels() - 1).unwrap())
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains(&format!("decodes {} channels", brdf.channels())),
            "{err}"
        );
    }
}

#[test]
fn raw_for_inverts_decode_for_every_map_of_every_model() {
    // Each spec's defaults, and values near both ends of its range (a normal tilted 60°),
    // decode back from `raw_for` to within 1e-3.
    for spec in &photomat_tests::models_under_test() {
        let brdf = model(spec);
        for p in brdf.params() {
            let (lo, hi) = p.range;
            let tilted = [0.75f32.sqrt() * 0.6, -(0.75f32.sqrt()) * 0.8, 0.5];
            let cases: Vec<Vec<f32>> = if p.encoding == photomat_core::Encoding::UnitNormal {
                vec![p.default.to_vec(), tilted.to_vec()]
            } else {
                vec![
                    p.default.to_vec(),
                    vec![lo + 0.01 * (hi - lo); p.channels],
                    vec![lo + 0.97 * (hi - lo); p.channels],
                ]
            };
            for want in cases {
                let raw = p.raw_for(&want);
                let raw = Tensor::from_vec(raw, (1, p.channels, 1, 1), &Device::Cpu).unwrap();
                let got = values(&p.decode(&raw).unwrap());
                for (g, w) in got.iter().zip(&want) {
                    let tol = 1e-3 * (hi - lo) as f64;
                    assert!((g - *w as f64).abs() < tol, "{spec}.{}: {g} vs {w}", p.name);
                }
            }
        }
    }
}

#[test]
fn raw_for_map_inverts_decode_texel_by_texel() {
    // A 1 × 3 map whose texels are the default, a value near the low end and one near the
    // high end (for unit normals: +z, a 60° tilt and its mirror) decodes back from
    // `raw_for_map` texel by texel, in place.
    for spec in &photomat_tests::models_under_test() {
        let brdf = model(spec);
        for p in brdf.params() {
            let (lo, hi) = p.range;
            let texels: Vec<Vec<f32>> = if p.encoding == photomat_core::Encoding::UnitNormal {
                let s = 0.75f32.sqrt();
                vec![
                    p.default.to_vec(),
                    vec![s * 0.6, -s * 0.8, 0.5],
                    vec![-s * 0.6, s * 0.8, 0.5],
                ]
            } else {
                vec![
                    p.default.to_vec(),
                    vec![lo + 0.01 * (hi - lo); p.channels],
                    vec![lo + 0.97 * (hi - lo); p.channels],
                ]
            };
            // (1, C, 1, 3): channel-major, as the maps are stored.
            let planar: Vec<f32> = (0..p.channels)
                .flat_map(|c| texels.iter().map(move |t| t[c]))
                .collect();
            let map =
                Tensor::from_vec(planar.clone(), (1, p.channels, 1, 3), &Device::Cpu).unwrap();
            let got = values(&p.decode(&p.raw_for_map(&map).unwrap()).unwrap());
            for (g, w) in got.iter().zip(&planar) {
                let tol = 1e-3 * (hi - lo) as f64;
                assert!((g - *w as f64).abs() < tol, "{spec}.{}: {g} vs {w}", p.name);
            }
            let wrong = Tensor::zeros((1, p.channels + 1, 1, 3), DType::F32, &Device::Cpu).unwrap();
            let err = p.raw_for_map(&wrong).unwrap_err().to_string();
            assert!(err.contains(p.name) && err.contains("channels"), "{err}");
        }
    }
}

#[test]
fn renderer_rejects_bad_maps_with_clear_errors() {
    let brdf = model("ggx");
    let good = MaterialMaps::defaults(brdf.params(), 1, 8, DType::F32, &Device::Cpu).unwrap();
    let light = [Highlight::CENTER];
    let expect = |maps: &MaterialMaps, lights: &[Highlight], needle: &str| {
        let err = render(brdf.as_ref(), maps, lights)
            .expect_err("must fail")
            .to_string();
        assert!(err.contains(needle), "expected '{needle}' in: {err}");
    };
    let zeros = |c, h, w| Tensor::zeros((1, c, h, w), DType::F32, &Device::Cpu).unwrap();
    expect(
        &good.clone().with("roughness", zeros(3, 8, 8)),
        &light,
        "map 'roughness' must have shape (B, 1, H, W)",
    );
    expect(
        &good.clone().with("diffuse", zeros(3, 4, 4)),
        &light,
        "map sizes differ",
    );
    expect(
        &good.clone().with("sheen", zeros(1, 8, 8)),
        &light,
        "unexpected map 'sheen'",
    );
    let mut missing = good.clone();
    missing.remove("normal");
    expect(&missing, &light, "missing map 'normal'");
    let rect = MaterialMaps::defaults(brdf.params(), 1, 1, DType::F32, &Device::Cpu)
        .unwrap()
        .map_tensors(|t| Ok(t.broadcast_as((1, t.dim(1)?, 4, 6))?.contiguous()?))
        .unwrap();
    expect(&rect, &light, "square maps");
    let two = good.map_tensors(|t| Ok(Tensor::cat(&[t, t], 0)?)).unwrap();
    expect(
        &two,
        &[Highlight::CENTER; 3],
        "3 highlight(s) for a batch of 2",
    );
    expect(&good, &[Highlight::new(f64::NAN, 0.0)], "not finite");

    // NaN is caught by the full validation used at trust boundaries.
    let mut nan = values(good.get("diffuse").unwrap());
    nan[5] = f64::NAN;
    let nan_maps = good.clone().with(
        "diffuse",
        Tensor::from_vec(nan, (1, 3, 8, 8), &Device::Cpu)
            .unwrap()
            .to_dtype(DType::F32)
            .unwrap(),
    );
    let err = nan_maps
        .validate("ggx", brdf.params())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("map 'diffuse' contains NaN"), "{err}");
}

#[test]
fn flash_geometry_of_a_crop_equals_the_photo_geometry_restricted_to_it() {
    // A whole photo of 2R texels spans side 2; its R×R crops are unit squares
    // (`docs/datasets.md`, "Geometry of a photo").
    // Moving the highlight into crop coordinates must give exactly the photo's ω and 1/d².
    use photomat_core::FlashGeometry;
    let r = 16;
    let photo_light = Highlight::new(0.3, -0.45);
    let photo =
        FlashGeometry::with_side(&[photo_light], 2 * r, 2.0, DType::F64, &Device::Cpu).unwrap();
    for (top, left) in [(0, 0), (16, 16), (5, 11)] {
        // Crop centre in photo-plane coordinates, then the highlight relative to it.
        let centre = Highlight::from_pixel_on(
            top as f64 + r as f64 / 2.0,
            left as f64 + r as f64 / 2.0,
            2 * r,
            2.0,
        );
        let crop_light = Highlight::new(photo_light.x - centre.x, photo_light.y - centre.y);
        let crop = FlashGeometry::new(&[crop_light], r, DType::F64, &Device::Cpu).unwrap();
        let window = |t: &Tensor| values(&t.narrow(2, top, r).unwrap().narrow(3, left, r).unwrap());
        let close = |a: Vec<f64>, b: Vec<f64>| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(
            close(window(&photo.omega), values(&crop.omega)),
            "ω differs for crop at ({top},{left})"
        );
        assert!(
            close(window(&photo.inv_dist2), values(&crop.inv_dist2)),
            "1/d² differs at ({top},{left})"
        );
    }
}

#[test]
fn height_adapter_normals_keep_their_slope_at_every_side_when_the_texel_size_is_recorded() {
    // A spatial model's N-texel material records one texel size whatever N: the same heights
    // repeated 2×2 (a 2N-texel material of the same world texel) must give the same normals
    // per texel, and a recorded texel of 1/R must equal the unit square's normals.
    let brdf = model("height(ggx, scale=0.05)");
    let size = 16;
    let maps = random_maps(&brdf, &mut rng(11), size, 0.05, DType::F32);
    let height = maps.get("height").unwrap().clone();
    let adapter = HeightToNormal { scale: 0.05 };
    let texel = 1.0 / 128.0;
    let small = adapter.normals_with_texel(&height, texel).unwrap();
    let large = adapter
        .normals_with_texel(&height.repeat((1, 1, 2, 2)).unwrap(), texel)
        .unwrap();
    assert_eq!(
        values(&large),
        values(&small.repeat((1, 1, 2, 2)).unwrap()),
        "normals of the 2×2-repeated heights are the repeated normals"
    );
    let unit = adapter.normals(&height).unwrap();
    let recorded = adapter
        .normals_with_texel(&height, 1.0 / size as f64)
        .unwrap();
    for (a, b) in values(&unit).iter().zip(values(&recorded)) {
        assert!((a - b).abs() < 1e-6, "{a} vs {b}");
    }
    // Without a recorded texel the unit-square convention scales slopes with N: the 2N
    // material's normals are flatter, which is what the texel size prevents.
    let unrecorded = adapter
        .normals(&height.repeat((1, 1, 2, 2)).unwrap())
        .unwrap();
    assert_ne!(
        values(&unrecorded),
        values(&unit.repeat((1, 1, 2, 2)).unwrap())
    );

    // Through the adapter: maps carrying the texel size get the texel-size normals.
    let shading = brdf
        .shading_maps(&maps.clone().with_texel_size(Some(texel)))
        .unwrap();
    assert_eq!(values(shading.get("normal").unwrap()), values(&small));
}
