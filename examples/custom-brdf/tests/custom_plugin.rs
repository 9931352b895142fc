//! The custom-plugin proof: a model registered from a user's crate is listed next to the
//! built-ins, composes with the built-in height adapter, passes photomat's conformance kit
//! (finite at extremes, non-negative, 0 below the horizon, reciprocal, gradients equal to
//! finite differences, map-file round trip), matches its documented formula, is
//! energy-bounded, renders its highlight under the flash, and the user's own binary built on
//! `photomat_cli::run()` lists and renders it.

// Linking pitfall (see `photomat_core::registry`): name both plugin crates, or the registry
// misses their models.
use photomat_brdfs as _;
use photomat_custom_brdf_example as _;

use std::path::Path;
use std::process::{Command, Output};

use candle_core::{DType, Device, Tensor};
use photomat_core::flash::texel_center;
use photomat_core::image_io::{PlanarImage, read_png};
use photomat_core::map_files::{SaveOptions, load_maps, save_maps};
use photomat_core::testing::check_model;
use photomat_core::{Brdf, Highlight, MaterialMaps, lookup, registered_names, render};

/// Every model a binary linking the built-ins and this crate sees, sorted: the built-ins
/// and this crate's models, each read from the registry by the crate that registered it.
fn expected_names() -> Vec<&'static str> {
    let mut names = photomat_brdfs::builtin_names().unwrap();
    names.extend(photomat_custom_brdf_example::registered_names().unwrap());
    names.sort();
    names
}

fn model(spec: &str) -> Brdf {
    lookup(spec).unwrap_or_else(|e| panic!("{e}"))
}

/// SplitMix64: a tiny seeded generator, so the cases are reproducible without extra crates.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Unit vector with z ≥ `min_z`, uniform in solid angle over that cap.
    fn direction(&mut self, min_z: f64) -> [f64; 3] {
        let z = self.uniform(min_z, 1.0);
        let phi = self.uniform(0.0, std::f64::consts::TAU);
        let s = (1.0 - z * z).max(0.0).sqrt();
        [s * phi.cos(), s * phi.sin(), z]
    }
}

/// (1, C, R, R) f64 tensor from per-texel C-vectors, row-major over the R×R grid.
fn grid(texels: &[Vec<f64>], size: usize) -> Tensor {
    grid_hw(texels, size, size)
}

/// (1, C, H, W) f64 tensor from per-texel C-vectors, row-major over the H×W grid.
fn grid_hw(texels: &[Vec<f64>], h: usize, w: usize) -> Tensor {
    assert_eq!(texels.len(), h * w);
    let c = texels[0].len();
    let mut data = vec![0.0; c * h * w];
    for (t, v) in texels.iter().enumerate() {
        for (k, x) in v.iter().enumerate() {
            data[k * h * w + t] = *x;
        }
    }
    Tensor::from_vec(data, (1, c, h, w), &Device::Cpu).unwrap()
}

/// Per-texel C-vectors of a (1, C, R, R) tensor.
fn texels(t: &Tensor) -> Vec<Vec<f64>> {
    let (_, c, h, w) = t.dims4().unwrap();
    let flat = values(t);
    (0..h * w)
        .map(|p| (0..c).map(|k| flat[k * h * w + p]).collect())
        .collect()
}

fn values(t: &Tensor) -> Vec<f64> {
    t.to_dtype(DType::F64)
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f64>()
        .unwrap()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn normalized(v: &[f64]) -> Vec<f64> {
    let len = dot(v, v).sqrt();
    v.iter().map(|x| x / len).collect()
}

/// Random blinn_phong_gloss maps for an R×R grid, f64: albedos and glossiness in the given ranges,
/// normals tilted by at most ≈ 27° (x, y ∈ [−½, ½], z = 1; normalised by the model).
fn random_maps(rng: &mut Rng, size: usize, albedo: (f64, f64), gloss: (f64, f64)) -> MaterialMaps {
    let n = size * size;
    let mut rgb = |r: (f64, f64)| -> Vec<Vec<f64>> {
        (0..n)
            .map(|_| (0..3).map(|_| rng.uniform(r.0, r.1)).collect())
            .collect()
    };
    let diffuse = rgb(albedo);
    let specular = rgb(albedo);
    let glossiness: Vec<Vec<f64>> = (0..n)
        .map(|_| vec![rng.uniform(gloss.0, gloss.1)])
        .collect();
    let normal: Vec<Vec<f64>> = (0..n)
        .map(|_| vec![rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), 1.0])
        .collect();
    MaterialMaps::new()
        .with("diffuse", grid(&diffuse, size))
        .with("specular", grid(&specular, size))
        .with("glossiness", grid(&glossiness, size))
        .with("normal", grid(&normal, size))
}

/// The documented formula, evaluated independently in plain f64: `f·cosθ_o`.
fn reference_f_cos(wi: &[f64], wo: &[f64], n: &[f64], rd: f64, ks: f64, g: f64) -> f64 {
    let n = normalized(n);
    let (ci, co) = (dot(&n, wi), dot(&n, wo));
    if ci <= 0.0 || co <= 0.0 {
        return 0.0;
    }
    let h = normalized(&[wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]);
    let e = 2f64.powf(1.0 + 12.0 * g);
    let f = rd / std::f64::consts::PI
        + ks * (e + 2.0) / (8.0 * std::f64::consts::PI) * dot(&n, &h).powf(e);
    f * co
}

#[test]
fn registry_lists_the_builtins_and_the_user_plugin_sorted() {
    assert_eq!(
        photomat_custom_brdf_example::registered_names().unwrap(),
        ["blinn_phong_gloss"]
    );
    let expected = expected_names();
    assert!(
        expected.contains(&"ggx"),
        "built-ins not linked: {expected:?}"
    );
    assert_eq!(registered_names().unwrap(), expected);
    // The user's model is reachable by name and named in lookup errors like any built-in.
    let err = lookup("blinn")
        .err()
        .expect("unknown name must fail")
        .to_string();
    assert!(err.contains(&expected.join(", ")), "{err}");
}

#[test]
fn blinn_phong_gloss_file_stem_equals_registered_name() {
    photomat_core::testing::check_file_stems("photomat_custom_brdf_example").unwrap();
}

#[test]
fn blinn_phong_gloss_passes_the_conformance_kit() {
    check_model("blinn_phong_gloss").unwrap();
}

#[test]
fn height_blinn_phong_gloss_passes_the_conformance_kit() {
    // The built-in adapter differentiates through the user's model down to the height map;
    // a visible relief makes the normals depend strongly on the heights.
    check_model("height(blinn_phong_gloss, scale=0.1)").unwrap();
}

#[test]
fn blinn_phong_gloss_channel_counts_and_height_adapter() {
    let plain = model("blinn_phong_gloss");
    assert_eq!(plain.name(), "blinn_phong_gloss");
    assert_eq!(plain.channels(), 10);
    let names: Vec<_> = plain.params().iter().map(|p| p.name).collect();
    assert_eq!(names, ["diffuse", "specular", "glossiness", "normal"]);

    // The built-in adapter wraps the user's model by name: normal (3) → height (1).
    let bumped = model("height(blinn_phong_gloss)");
    assert_eq!(bumped.channels(), 8);
    let names: Vec<_> = bumped.params().iter().map(|p| p.name).collect();
    assert_eq!(names, ["diffuse", "specular", "glossiness", "height"]);
    assert_eq!(bumped.name(), "height(blinn_phong_gloss, scale=0.02)");
    assert_eq!(model(&bumped.name()).name(), bumped.name());

    // Decoding raw network output goes through the specs: 10 channels in, four maps out.
    let raw = Tensor::zeros((2, 10, 4, 4), DType::F32, &Device::Cpu).unwrap();
    let maps = plain.decode(&raw).unwrap();
    maps.validate("blinn_phong_gloss", plain.params()).unwrap();
    // tanh(0) = 0 decodes to the middle of the linear range: g = ½, e = 2^7.
    let g = values(maps.get("glossiness").unwrap());
    assert!(g.iter().all(|&v| (v - 0.5).abs() < 1e-6), "{g:?}");
}

#[test]
fn blinn_phong_gloss_matches_the_documented_formula() {
    let brdf = model("blinn_phong_gloss");
    let size = 16;
    let mut rng = Rng(7);
    let wi: Vec<Vec<f64>> = (0..size * size)
        .map(|_| rng.direction(-0.3).to_vec())
        .collect();
    let wo: Vec<Vec<f64>> = (0..size * size)
        .map(|_| rng.direction(-0.3).to_vec())
        .collect();
    let maps = random_maps(&mut rng, size, (0.0, 1.0), (0.0, 1.0));
    let out = texels(
        &brdf
            .eval(&grid(&wi, size), &grid(&wo, size), &maps)
            .unwrap(),
    );
    let [rd, ks, g, n] =
        ["diffuse", "specular", "glossiness", "normal"].map(|name| texels(maps.get(name).unwrap()));
    let mut lit = 0;
    for t in 0..size * size {
        for c in 0..3 {
            let expected = reference_f_cos(&wi[t], &wo[t], &n[t], rd[t][c], ks[t][c], g[t][0]);
            let got = out[t][c];
            assert!(
                (got - expected).abs() <= 1e-9 * expected.abs().max(1.0),
                "texel {t} channel {c}: {got} vs {expected}"
            );
            lit += usize::from(expected > 0.0);
        }
    }
    assert!(
        lit > 3 * size * size / 4,
        "too few cases above the horizon: {lit}"
    );
}

#[test]
fn blinn_phong_gloss_white_furnace_le_one_and_normalised() {
    // Directional albedo ∫ f·cosθ_o dω_o by the midpoint rule over (cosθ_o, φ_o), for a white
    // specular lobe (diffuse 0) and a white diffuse one (specular 0). The (e + 2)/(8π) factor
    // keeps the lobe ≤ 1 at every angle and ≈ 1 at normal incidence for narrow lobes.
    let brdf = model("blinn_phong_gloss");
    let (n_mu, n_phi) = (400, 200);
    let mut wo = Vec::with_capacity(n_mu * n_phi);
    for i in 0..n_mu {
        let mu = (i as f64 + 0.5) / n_mu as f64;
        for j in 0..n_phi {
            let phi = (j as f64 + 0.5) / n_phi as f64 * std::f64::consts::TAU;
            let s = (1.0 - mu * mu).sqrt();
            wo.push(vec![s * phi.cos(), s * phi.sin(), mu]);
        }
    }
    let wo = grid_hw(&wo, n_mu, n_phi);
    let cell = (1.0 / n_mu as f64) * (std::f64::consts::TAU / n_phi as f64);
    let albedo = |theta_deg: f64, rd: f64, ks: f64, g: f64| -> f64 {
        let t = theta_deg.to_radians();
        let wi = Tensor::new(&[t.sin(), 0.0, t.cos()], &Device::Cpu)
            .unwrap()
            .reshape((1, 3, 1, 1))
            .unwrap()
            .broadcast_as((1, 3, n_mu, n_phi))
            .unwrap()
            .contiguous()
            .unwrap();
        let constant = |v: &[f64]| {
            Tensor::new(v, &Device::Cpu)
                .unwrap()
                .reshape((1, v.len(), 1, 1))
                .unwrap()
        };
        let maps = MaterialMaps::new()
            .with("diffuse", constant(&[rd; 3]))
            .with("specular", constant(&[ks; 3]))
            .with("glossiness", constant(&[g]))
            .with("normal", constant(&[0.0, 0.0, 1.0]));
        let f_cos = brdf.eval(&wi, &wo, &maps).unwrap();
        let sums = values(&f_cos.sum((2, 3)).unwrap());
        sums[0] * cell
    };
    for theta in [0.0, 30.0, 60.0, 85.0, 89.9] {
        let lambert = albedo(theta, 1.0, 0.0, 0.5);
        assert!(
            (lambert - 1.0).abs() < 1e-4,
            "Lambert albedo at {theta}°: {lambert}"
        );
        for g in [0.0, 0.25, 0.5] {
            let a = albedo(theta, 0.0, 1.0, g);
            assert!(
                a > 0.0 && a <= 1.0 + 1e-3,
                "specular albedo at {theta}°, g = {g}: {a}"
            );
        }
    }
    // Normalisation, not just boundedness: a narrow lobe at normal incidence keeps ≈ all energy.
    let head_on = albedo(0.0, 0.0, 1.0, 0.5);
    assert!(
        head_on > 0.95,
        "specular albedo at normal incidence, e = 128: {head_on}"
    );
}

#[test]
fn blinn_phong_gloss_render_puts_the_highlight_under_the_flash() {
    let brdf = model("blinn_phong_gloss");
    let size = 64;
    let constant = |v: &[f32]| {
        Tensor::new(v, &Device::Cpu)
            .unwrap()
            .reshape((1, v.len(), 1, 1))
            .unwrap()
            .broadcast_as((1, v.len(), size, size))
            .unwrap()
            .contiguous()
            .unwrap()
    };
    // A dark glossy plane: the peak (≈ 0.1 + 0.04·130/8 = 0.75) stays below display white.
    let maps = MaterialMaps::new()
        .with("diffuse", constant(&[0.1, 0.1, 0.1]))
        .with("specular", constant(&[0.04, 0.04, 0.04]))
        .with("glossiness", constant(&[0.5]))
        .with("normal", constant(&[0.0, 0.0, 1.0]));
    // Flashes straight above two texel centres, rendered as one batch of the same material.
    let targets = [(40, 12), (9, 50)];
    let highlights: Vec<Highlight> = targets
        .iter()
        .map(|&(r, c)| {
            let p = texel_center(r, c, size);
            Highlight::new(p.x, p.y)
        })
        .collect();
    let image = render(brdf.as_ref(), &maps, &highlights).unwrap();
    assert_eq!(image.dims(), [2, 3, size, size]);
    for (b, &(row, col)) in targets.iter().enumerate() {
        let lum = values(&image.get(b).unwrap().mean(0).unwrap());
        let (argmax, peak) = lum
            .iter()
            .copied()
            .enumerate()
            .fold(
                (0, f64::MIN),
                |best, (i, v)| if v > best.1 { (i, v) } else { best },
            );
        assert_eq!((argmax / size, argmax % size), (row, col), "flash {b}");
        assert!(peak < 1.0, "the highlight must not saturate: {peak}");
        // The specular lobe makes the highlight: the darkest texel is far dimmer.
        let darkest = lum.iter().copied().fold(f64::MAX, f64::min);
        assert!(
            peak > 2.0 * darkest,
            "flash {b}: peak {peak}, darkest {darkest}"
        );
    }
}

/// Run the user's binary (built by cargo for this package's tests) with `args`.
fn photomat_custom(args: &[&str]) -> Output {
    let output = Command::new(env!("CARGO_BIN_EXE_photomat-custom"))
        .args(args)
        .output()
        .expect("the photomat-custom binary runs");
    assert!(
        output.status.success(),
        "photomat-custom {args:?} failed: {}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

#[test]
fn photomat_custom_brdfs_lists_blinn_phong_gloss() {
    let text = String::from_utf8(photomat_custom(&["brdfs"]).stdout).unwrap();
    assert!(text.contains("blinn_phong_gloss"), "{text}");
    assert!(text.contains("glossiness"), "{text}");

    // The binary's registry holds exactly the built-ins plus the user's model, with n = 10.
    let json: serde_json::Value =
        serde_json::from_slice(&photomat_custom(&["brdfs", "--json"]).stdout).unwrap();
    let models = json["models"].as_array().expect("a list of models");
    let names: Vec<_> = models.iter().map(|m| m["name"].as_str().unwrap()).collect();
    assert_eq!(names, expected_names());
    let blinn = models
        .iter()
        .find(|m| m["name"] == "blinn_phong_gloss")
        .unwrap();
    assert_eq!(blinn["channels"], 10, "{blinn}");
}

#[test]
fn photomat_custom_renders_saved_blinn_phong_gloss_maps() {
    // Maps saved through the folder API, as a user's estimator would write them.
    let brdf = model("blinn_phong_gloss");
    let size = 32;
    // A flat plane with a faint diffuse texture and a uniform narrow lobe (e = 2^8.2), so
    // the brightest pixel is the one under the flash and the peak (≈ 0.8) is not clipped.
    let mut rng = Rng(53);
    let texture: Vec<Vec<f64>> = (0..size * size)
        .map(|_| (0..3).map(|_| rng.uniform(0.03, 0.05)).collect())
        .collect();
    let uniform = |v: Vec<f64>| grid(&vec![v; size * size], size);
    let maps = MaterialMaps::new()
        .with("diffuse", grid(&texture, size))
        .with("specular", uniform(vec![0.02; 3]))
        .with("glossiness", uniform(vec![0.6]))
        .with("normal", uniform(vec![0.0, 0.0, 1.0]))
        .map_tensors(|t| Ok(t.to_dtype(DType::F32)?))
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("material");
    save_maps(&folder, brdf.as_ref(), &maps, &SaveOptions::default()).unwrap();

    let out = dir.path().join("render.png");
    let args = [
        "render",
        "--maps",
        path_str(&folder),
        "--light",
        "0.1,0.1",
        "--out",
    ];
    let stdout = photomat_custom(&[&args[..], &[path_str(&out)]].concat()).stdout;
    assert!(String::from_utf8_lossy(&stdout).contains("blinn_phong_gloss"));

    // The PNG is the library render of the loaded material, up to 8-bit quantisation.
    let (png, _) = read_png(&out).unwrap();
    assert_eq!((png.channels, png.height, png.width), (3, size, size));
    let loaded = load_maps(&folder, None).unwrap();
    assert_eq!(loaded.brdf.name(), "blinn_phong_gloss");
    let expected = render(
        loaded.brdf.as_ref(),
        &loaded.maps,
        &[Highlight::new(0.1, 0.1)],
    )
    .unwrap();
    let expected = PlanarImage::from_tensor(&expected).unwrap();
    let worst = png
        .data
        .iter()
        .zip(&expected.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst <= 0.5 / 255.0 + 1e-6,
        "PNG differs from the render by {worst}"
    );

    // And the highlight sits under the flash: (0.1, 0.1) is pixel (row 12.8, col 19.2).
    let lum: Vec<f32> = (0..size * size)
        .map(|p| (0..3).map(|c| png.data[c * size * size + p]).sum::<f32>())
        .collect();
    let argmax = (0..lum.len())
        .max_by(|&a, &b| lum[a].total_cmp(&lum[b]))
        .unwrap();
    assert_eq!((argmax / size, argmax % size), (12, 19));
}

fn path_str(path: &Path) -> &str {
    path.to_str().expect("temporary paths are UTF-8")
}
