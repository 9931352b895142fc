//! `photomat sample`: the product's main job (issue 7, "Sampling"; the reference tool's
//! sampler, DESIGN §4 last paragraph). For each seed, G turns z(seed) into a neural material F
//! (truncation ψ), E decodes F into the maps of its BRDF model, and the command writes, under
//! `OUT/seed-XXXX/`:
//! - `material/`: the map folder (engine format: PNG + float EXR + material.json);
//! - `neural.png` / `analytic.png`: M's relighting of F and the flash render of the maps under
//!   the reference's 5 lights, side by side: the centre, then highlights at
//!   [`REFERENCE_LIGHT_RADIUS`]·(cos θ, sin θ) for θ = 45°, 135°, 225°, 315°;
//! - with `--tileable` (tileable models only) `tiled_2x2.png`: the maps repeated 2×2 under the
//!   centred flash; with `--hextile`, `hextile_2x2.png` and `material_hextile_2x2/`: the maps
//!   hex-tiled (Mikkelsen 2022, `photomat_export::hextile`) to 2×2 periods with one lattice
//!   per material (seeded by the material's seed), rendered the same way. The 2×2 renders show
//!   the shading maps of the innermost model (an adapter's derived normal, so the relief keeps
//!   its slope) on the unit square, i.e. the material at half size;
//! - with `--gltf` / `--mtlx`: `export/material.gltf` (+ `.bin`) / `export/material.mtlx` and
//!   their textures (`photomat_export`; what a model's mapping drops is printed).
//!
//! Plus, for the run, `OUT/contact_sheet.png` (a row per material — the first
//! [`SHEET_MAX_ROWS`] — of map previews, the 5 analytic renders and the 5 neural renders, tiles
//! at most [`SHEET_MAX_TILE`] pixels) and `OUT/summary.json`: seeds, per material and light the L1
//! distance between analytic and neural render in display-encoded [0, 1] space, their means,
//! and the wall time of each stage.
//!
//! Seeds are S, S+1, …, S+N−1; a seed names the same material on every run (z and the noise
//! images are drawn from the seed, `GanModel::features_for_seeds`): same seed, same files.
//!
//! `--model` defaults to `$PHOTOMAT_MODEL`, else the bundled `models/demo/` of this source tree.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use indicatif::{ProgressBar, ProgressStyle};
use photomat_core::image_io::{CONTACT_SHEET_GAP, PlanarImage, PngBits, write_atomic, write_png};
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::{Brdf, ColorSpace, FlashGeometry, Highlight, MaterialMaps, render};
use photomat_estimator::EstimatorModel;
use photomat_export::hextile::{Content, HexTiling, hextile};
use photomat_generator::GanModel;

use super::previews::map_previews;

/// Radius of the reference's four diagonal lights: `0.5·(cos θ, sin θ)` in the reference's
/// plane coordinates, which span [−1, 1]; our plane spans [−½, ½] (DESIGN §2), so ¼.
pub const REFERENCE_LIGHT_RADIUS: f64 = 0.25;

/// Materials shown in the contact sheet (the first ones of the run): 64 rows of 128-pixel
/// tiles are already an 8,400-pixel-tall image; the per-material PNGs hold every material.
pub const SHEET_MAX_ROWS: usize = 64;

/// Largest tile side in the contact sheet, in pixels (tiles are shrunk to it).
pub const SHEET_MAX_TILE: usize = 128;

/// Texels relit and rendered per call: all 5 lights at up to 512² (≈ 1.3 M texels, a few
/// hundred MB of intermediates), one light at a time above.
pub const LIGHT_BATCH_TEXELS: usize = 5 * 512 * 512;

/// Environment variable naming the default model folder.
pub const MODEL_ENV: &str = "PHOTOMAT_MODEL";

/// The bundled model folder of this source tree.
pub fn bundled_model_dir() -> PathBuf {
    let cli = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The workspace root is the CLI crate's parent folder.
    cli.parent().unwrap_or(cli).join("models").join("demo")
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model folder (`photomat train-estimator` output: gan.json, gan.safetensors,
    /// estimator.json, estimator.safetensors) [default: $PHOTOMAT_MODEL, else the bundled
    /// models/demo].
    #[arg(long, value_name = "DIR")]
    pub model: Option<PathBuf>,

    /// Number of materials.
    #[arg(long, value_name = "N", default_value_t = 4,
          value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub count: u32,

    /// First seed; material k uses seed S + k.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,

    /// Output folder (created): seed-XXXX/ folders, contact_sheet.png, summary.json.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Truncation ψ: 1 samples the full distribution, smaller values stay nearer the average
    /// material (more typical, less varied).
    #[arg(
        long,
        value_name = "PSI",
        default_value_t = 1.0,
        allow_hyphen_values = true
    )]
    pub psi: f64,

    /// Also write tiled_2x2.png (needs a model trained with `photomat train-gan --tileable`).
    #[arg(long)]
    pub tileable: bool,

    /// Also hex-tile the maps to 2×2 periods: hextile_2x2.png and material_hextile_2x2/.
    #[arg(long)]
    pub hextile: bool,

    /// Also write export/material.gltf (glTF 2.0 with KHR_materials_specular) and its textures.
    #[arg(long)]
    pub gltf: bool,

    /// Also write export/material.mtlx (MaterialX 1.38, UsdPreviewSurface) and its textures.
    #[arg(long)]
    pub mtlx: bool,

    /// Side in pixels of each render and preview in the PNG sheets [default: the model's
    /// resolution]; the maps themselves keep the model's resolution.
    #[arg(long = "size-render", value_name = "PX",
          value_parser = clap::value_parser!(u32).range(8..=4096))]
    pub size_render: Option<u32>,
}

/// The reference's 5 lights: the centre, then the diagonals counter-clockwise from +x.
pub fn reference_lights() -> Vec<Highlight> {
    let mut lights = vec![Highlight::CENTER];
    for k in 0..4 {
        let theta = (45.0 + 90.0 * k as f64).to_radians();
        lights.push(Highlight::new(
            REFERENCE_LIGHT_RADIUS * theta.cos(),
            REFERENCE_LIGHT_RADIUS * theta.sin(),
        ));
    }
    lights
}

/// The model folder to use: `--model`, else `$PHOTOMAT_MODEL`, else the bundled one; an error
/// naming the path tried and how to train a model if it holds none.
fn model_dir(arg: Option<&Path>) -> anyhow::Result<PathBuf> {
    let (dir, source) = match (arg, std::env::var_os(MODEL_ENV)) {
        (Some(dir), _) => (dir.to_path_buf(), "--model"),
        (None, Some(env)) => (PathBuf::from(env), "$PHOTOMAT_MODEL"),
        (None, None) => (bundled_model_dir(), "the bundled model folder"),
    };
    let manifests = [
        photomat_generator::model_files::GAN_MANIFEST_FILE,
        photomat_estimator::model_files::ESTIMATOR_MANIFEST_FILE,
    ];
    if let Some(missing) = manifests.iter().find(|m| !dir.join(m).is_file()) {
        bail!(
            "no trained model in '{}' ({source}): {missing} is missing. Train one with \
             `photomat train-gan --data DATASET --out RUN`, then `photomat train-estimator \
             --gan RUN --brdf 'height(ggx)' --out MODEL`, and pass --model MODEL (or set \
             ${MODEL_ENV})",
            dir.display()
        );
    }
    Ok(dir)
}

/// Per-stage wall time, seconds.
#[derive(Debug, Default, Clone, serde::Serialize)]
struct Timings {
    load: f64,
    generate: f64,
    estimate: f64,
    relight: f64,
    render: f64,
    extras: f64,
    write: f64,
    total: f64,
}

#[derive(Debug, serde::Serialize)]
struct MaterialSummary {
    seed: u64,
    folder: String,
    /// L1 analytic vs neural per light, display-encoded [0, 1].
    l1_per_light: Vec<f64>,
    l1_mean: f64,
}

#[derive(Debug, serde::Serialize)]
struct Summary {
    model: String,
    brdf: String,
    resolution: usize,
    psi: f64,
    tileable_model: bool,
    /// Highlight positions (x, y) of the lights, in the order of the renders.
    lights: Vec<[f64; 2]>,
    seeds: Vec<u64>,
    materials: Vec<MaterialSummary>,
    /// Mean over materials of the L1 per light.
    l1_per_light: Vec<f64>,
    l1_mean: f64,
    timings_s: Timings,
    materials_per_minute: f64,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    if !(args.psi.is_finite()) {
        bail!("--psi must be a finite number, got {}", args.psi);
    }
    let total_start = Instant::now();
    let mut timings = Timings::default();
    let dir = model_dir(args.model.as_deref())?;
    let device = Device::Cpu;
    let gan = GanModel::load(&dir, &device)
        .with_context(|| format!("cannot load the GAN model in '{}'", dir.display()))?;
    let estimator = EstimatorModel::load(&dir, &device)
        .with_context(|| format!("cannot load the estimator in '{}'", dir.display()))?;
    let config = gan.config();
    if args.tileable && !config.tileable {
        bail!(
            "--tileable: the model in '{}' is not tileable (gan.json: architecture.tileable = \
             false), its materials have seams when repeated; train one with `photomat train-gan \
             --tileable`, or use --hextile, which hides the repetition of any material",
            dir.display()
        );
    }
    let in_channels = estimator.estimator().config().in_channels;
    if in_channels != config.feature_channels {
        bail!(
            "the estimator in '{}' reads {in_channels} feature channels but the GAN produces {} \
             (estimator.json and gan.json come from different runs)",
            dir.display(),
            config.feature_channels
        );
    }
    let brdf = estimator.brdf().clone();
    let inner = brdf.innermost();
    let resolution = config.resolution;
    let tile = args.size_render.map_or(resolution, |s| s as usize);
    let lights = reference_lights();
    let geometry = FlashGeometry::new(&lights, resolution, DType::F32, &device)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create '{}'", args.out.display()))?;
    if args.hextile && !config.tileable {
        writeln!(
            out,
            "note: the model is not tileable; the maps' own border seam can show inside the \
             hexagons of hextile_2x2.png"
        )?;
    }
    timings.load = total_start.elapsed().as_secs_f64();

    let bar = ProgressBar::new(args.count as u64).with_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} materials ({per_sec}, {eta} left)",
        )
        .expect("the template is valid")
        .progress_chars("=> "),
    );
    let mut rows = Vec::new();
    let mut materials = Vec::new();
    let mut notes_shown = false;
    let seeds: Vec<u64> = (0..args.count as u64)
        .map(|k| args.seed.wrapping_add(k))
        .collect();
    for &seed in &seeds {
        let folder = args.out.join(format!("seed-{seed:04}"));
        let stage = Instant::now();
        let features = gan.features_for_seeds(&[seed], args.psi)?;
        timings.generate += stage.elapsed().as_secs_f64();
        let stage = Instant::now();
        let maps = estimator.estimate(&features)?;
        timings.estimate += stage.elapsed().as_secs_f64();
        // Lights in groups of at most LIGHT_BATCH_TEXELS texels: M's and the renderer's
        // intermediates scale with the batch (5 lights of a 1024² material would hold
        // gigabytes at once); materials up to 512² keep one call for all lights.
        let per_call = (LIGHT_BATCH_TEXELS / (resolution * resolution)).clamp(1, lights.len());
        let mut neural = Vec::new();
        let mut analytic = Vec::new();
        for first in (0..lights.len()).step_by(per_call) {
            let n = per_call.min(lights.len() - first);
            let omega = geometry.omega.narrow(0, first, n)?;
            let repeated = features.repeat((n, 1, 1, 1))?;
            let relight = Instant::now();
            neural.push(gan.relight().forward(&repeated, &omega)?);
            timings.relight += relight.elapsed().as_secs_f64();
            let shade = Instant::now();
            analytic.push(render(brdf.as_ref(), &maps, &lights[first..first + n])?);
            timings.render += shade.elapsed().as_secs_f64();
        }
        let neural = Tensor::cat(&neural, 0)?.affine(0.5, 0.5)?.clamp(0.0, 1.0)?;
        let analytic = Tensor::cat(&analytic, 0)?;
        let l1: Vec<f64> = (analytic.clone() - &neural)?
            .abs()?
            .flatten_from(1)?
            .mean(1)?
            .to_dtype(DType::F64)?
            .to_vec1()?;

        let stage = Instant::now();
        let analytic_tiles = images(&analytic, tile)?;
        let neural_tiles = images(&neural, tile)?;
        let extras = (args.tileable || args.hextile)
            .then(|| brdf.shading_maps(&maps))
            .transpose()?;
        let mut tiled = None;
        let mut hex = None;
        if let Some(shading) = &extras {
            if args.tileable {
                let repeated = shading.map_tensors(|t| Ok(t.repeat((1, 1, 2, 2))?))?;
                tiled = Some(centre_render(&inner, &repeated, 2 * tile)?);
            }
            if args.hextile {
                let maps2 = hextile_maps(&inner, shading, seed)?;
                hex = Some((centre_render(&inner, &maps2, 2 * tile)?, maps2));
            }
        }
        timings.extras += stage.elapsed().as_secs_f64();

        let stage = Instant::now();
        save_maps(
            &folder.join("material"),
            brdf.as_ref(),
            &maps,
            &SaveOptions::default(),
        )
        .with_context(|| format!("cannot write the maps of seed {seed}"))?;
        write_png(
            &folder.join("neural.png"),
            &grid(std::slice::from_ref(&neural_tiles))?,
            PngBits::Eight,
        )?;
        write_png(
            &folder.join("analytic.png"),
            &grid(std::slice::from_ref(&analytic_tiles))?,
            PngBits::Eight,
        )?;
        if let Some(image) = &tiled {
            write_png(&folder.join("tiled_2x2.png"), image, PngBits::Eight)?;
        }
        if let Some((image, maps2)) = &hex {
            write_png(&folder.join("hextile_2x2.png"), image, PngBits::Eight)?;
            save_maps(
                &folder.join("material_hextile_2x2"),
                inner.as_ref(),
                maps2,
                &SaveOptions::default(),
            )?;
        }
        if args.gltf || args.mtlx {
            let export = folder.join("export");
            let set = photomat_export::write_textures(&export, brdf.as_ref(), &maps)?;
            if args.gltf {
                photomat_export::write_gltf(&export, "material", &set)?;
            }
            if args.mtlx {
                photomat_export::write_materialx(&export, "material", &set)?;
            }
            if !notes_shown {
                notes_shown = true;
                for note in &set.dropped {
                    bar.suspend(|| writeln!(out, "export: dropped {note}"))?;
                }
                for note in &set.approximations {
                    bar.suspend(|| writeln!(out, "export: approximation: {note}"))?;
                }
            }
        }
        timings.write += stage.elapsed().as_secs_f64();

        if rows.len() < SHEET_MAX_ROWS {
            let sheet_tile = tile.min(SHEET_MAX_TILE);
            let mut row: Vec<PlanarImage> = map_previews(brdf.as_ref(), &maps)?
                .into_iter()
                .map(|(_, p)| resize(&p, sheet_tile))
                .collect();
            row.extend(analytic_tiles.iter().map(|t| resize(t, sheet_tile)));
            row.extend(neural_tiles.iter().map(|t| resize(t, sheet_tile)));
            rows.push(row);
        }
        materials.push(MaterialSummary {
            seed,
            folder: folder.display().to_string(),
            l1_mean: l1.iter().sum::<f64>() / l1.len() as f64,
            l1_per_light: l1,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    let stage = Instant::now();
    let sheet_path = args.out.join("contact_sheet.png");
    write_png(&sheet_path, &grid(&rows)?, PngBits::Eight)?;
    timings.write += stage.elapsed().as_secs_f64();
    timings.total = total_start.elapsed().as_secs_f64();
    let n = materials.len() as f64;
    let l1_per_light: Vec<f64> = (0..lights.len())
        .map(|i| materials.iter().map(|m| m.l1_per_light[i]).sum::<f64>() / n)
        .collect();
    let l1_mean = l1_per_light.iter().sum::<f64>() / l1_per_light.len() as f64;
    let per_material = timings.generate
        + timings.estimate
        + timings.relight
        + timings.render
        + timings.extras
        + timings.write;
    let summary = Summary {
        model: dir.display().to_string(),
        brdf: brdf.name(),
        resolution,
        psi: args.psi,
        tileable_model: config.tileable,
        lights: lights.iter().map(|h| [h.x, h.y]).collect(),
        seeds,
        materials,
        l1_per_light,
        l1_mean,
        materials_per_minute: 60.0 * n / per_material.max(f64::MIN_POSITIVE),
        timings_s: timings,
    };
    let summary_path = args.out.join("summary.json");
    let mut text = serde_json::to_string_pretty(&summary)?;
    text.push('\n');
    write_atomic(&summary_path, text.as_bytes())?;

    writeln!(
        out,
        "{} material(s) from '{}' ({}×{resolution}, model {}), ψ = {}",
        summary.seeds.len(),
        dir.display(),
        resolution,
        summary.brdf,
        args.psi
    )?;
    writeln!(
        out,
        "  {}/seed-XXXX/  material/, neural.png, analytic.png{}{}{}",
        args.out.display(),
        if args.tileable { ", tiled_2x2.png" } else { "" },
        if args.hextile {
            ", hextile_2x2.png, material_hextile_2x2/"
        } else {
            ""
        },
        match (args.gltf, args.mtlx) {
            (true, true) => ", export/material.{gltf,mtlx}",
            (true, false) => ", export/material.gltf",
            (false, true) => ", export/material.mtlx",
            (false, false) => "",
        }
    )?;
    writeln!(
        out,
        "  {}  a row per material{}: maps, 5 analytic renders, 5 neural renders",
        sheet_path.display(),
        if summary.seeds.len() > SHEET_MAX_ROWS {
            format!(" (the first {SHEET_MAX_ROWS})")
        } else {
            String::new()
        }
    )?;
    writeln!(
        out,
        "  {}  L1 analytic vs neural (encoded): {:.4} mean; {:.1} materials/min",
        summary_path.display(),
        summary.l1_mean,
        summary.materials_per_minute
    )?;
    Ok(())
}

/// Hex-tile the maps of `brdf` to 2×2 periods with one lattice seeded by `seed`; the diffuse
/// albedo (display-encoded) guides the contrast-preserving weights.
fn hextile_maps(brdf: &Brdf, maps: &MaterialMaps, seed: u64) -> anyhow::Result<MaterialMaps> {
    let specs = brdf.params();
    let images = specs
        .iter()
        .map(|s| Ok(PlanarImage::from_tensor(maps.get(s.name)?)?))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let guide = specs
        .iter()
        .zip(&images)
        .find(|(s, i)| s.color_space == ColorSpace::Gamma22 && i.channels == 3)
        .map(|(s, i)| i.map(|v| s.color_space.to_stored(v)));
    let inputs: Vec<(&PlanarImage, Content)> = specs
        .iter()
        .zip(&images)
        .map(|(s, i)| {
            let content = match (s.color_space, i.channels) {
                (ColorSpace::UnitVector, 3) => Content::TangentNormal,
                _ => Content::Scalar,
            };
            (i, content)
        })
        .collect();
    let (h, w) = (images[0].height, images[0].width);
    let tiling = HexTiling {
        seed,
        ..HexTiling::default()
    };
    let outputs = hextile(&tiling, &inputs, guide.as_ref(), 2 * h, 2 * w)?;
    let mut tiled = MaterialMaps::new();
    for (spec, image) in specs.iter().zip(outputs) {
        // Blends stay inside convex ranges; clamp the f32 rounding at the bounds.
        let image = image.map(|v| v.clamp(spec.range.0, spec.range.1));
        tiled.insert(spec.name, image.to_tensor(&Device::Cpu)?);
    }
    Ok(tiled)
}

/// The display-encoded render of `maps` under the centred flash, resized to `side`.
fn centre_render(brdf: &Brdf, maps: &MaterialMaps, side: usize) -> anyhow::Result<PlanarImage> {
    let image = render(brdf.as_ref(), maps, &[Highlight::CENTER])?;
    Ok(resize(&PlanarImage::from_tensor(&image)?, side))
}

/// The items of a (B, 3, R, R) batch as images resized to `side`.
fn images(batch: &Tensor, side: usize) -> anyhow::Result<Vec<PlanarImage>> {
    (0..batch.dim(0)?)
        .map(|i| {
            Ok(resize(
                &PlanarImage::from_tensor(&batch.narrow(0, i, 1)?)?,
                side,
            ))
        })
        .collect()
}

/// Rows of equal-size tiles laid out left to right, top to bottom, [`CONTACT_SHEET_GAP`]
/// black pixels between them (`contact_sheet` picks its own column count; the sheets here
/// need one row per material).
fn grid(rows: &[Vec<PlanarImage>]) -> anyhow::Result<PlanarImage> {
    let Some(first) = rows.first().and_then(|r| r.first()) else {
        bail!("an image grid needs at least one tile");
    };
    let (c, h, w) = (first.channels, first.height, first.width);
    let gap = CONTACT_SHEET_GAP;
    let columns = rows.iter().map(Vec::len).max().unwrap_or(1);
    let (sheet_h, sheet_w) = (rows.len() * (h + gap) - gap, columns * (w + gap) - gap);
    let mut sheet = PlanarImage::filled(c, sheet_h, sheet_w, 0.0);
    for (r, row) in rows.iter().enumerate() {
        for (k, tile) in row.iter().enumerate() {
            if (tile.channels, tile.height, tile.width) != (c, h, w) {
                bail!(
                    "image grid tiles differ in shape: {c}×{h}×{w} and {}×{}×{}",
                    tile.channels,
                    tile.height,
                    tile.width
                );
            }
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

/// `image` resized to `side`×`side` (square in, square out): the mean of the source texels
/// each output pixel covers when shrinking, nearest texel when enlarging (sharp previews).
fn resize(image: &PlanarImage, side: usize) -> PlanarImage {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reference_lights_are_the_centre_and_four_diagonals() {
        let lights = reference_lights();
        assert_eq!(lights.len(), 5);
        assert_eq!(lights[0], Highlight::CENTER);
        let d = REFERENCE_LIGHT_RADIUS / 2f64.sqrt();
        let expected = [(d, d), (-d, d), (-d, -d), (d, -d)];
        for (h, (x, y)) in lights[1..].iter().zip(expected) {
            assert!((h.x - x).abs() < 1e-12 && (h.y - y).abs() < 1e-12, "{h:?}");
        }
    }

    #[test]
    fn resize_averages_when_shrinking_and_repeats_when_enlarging() {
        let image = PlanarImage::new(1, 2, 2, vec![0.0, 1.0, 2.0, 3.0]).unwrap();
        assert_eq!(resize(&image, 1).data, vec![1.5]);
        let big = resize(&image, 4);
        assert_eq!(big.get(0, 0, 1), 0.0);
        assert_eq!(big.get(0, 3, 3), 3.0);
        assert_eq!(big.get(0, 2, 1), 2.0);
    }

    #[test]
    fn grid_lays_out_rows_with_gaps() {
        let tile = |v| PlanarImage::filled(1, 2, 3, v);
        let sheet = grid(&[vec![tile(1.0), tile(2.0)], vec![tile(3.0)]]).unwrap();
        let gap = CONTACT_SHEET_GAP;
        assert_eq!((sheet.height, sheet.width), (4 + gap, 6 + gap));
        assert_eq!(sheet.get(0, 0, 3 + gap), 2.0);
        assert_eq!(sheet.get(0, 2 + gap, 0), 3.0);
        assert_eq!(sheet.get(0, 2 + gap, 3 + gap), 0.0);
    }
}
