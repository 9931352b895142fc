//! `photomat relight --gan RUN --seed S --orbit N --out FILE.png [--frames DIR]
//! [--gif FILE.gif] [--psi 1.0] [--radius 0.35] [--frame-ms 100]`: one neural material of a
//! trained GAN under N flash positions (PhotoMat §3: M relights the features
//! F of G under any light).
//!
//! The material is `GanModel::features_for_seeds([S], ψ)` — z and noise drawn from S, so a
//! seed names the same material on every machine. The flash positions are the orbit of
//! `photomat render --orbit` (N highlights evenly spaced on a circle of radius `--radius`
//! around the centre, θ_k = 2π(k + ½)/N, [`photomat_core::LightSet::orbit`]); for each, M maps F ‖ ω
//! (per-texel direction to the collocated flash) to an image in the encoded space [−1, 1],
//! shown as (x + 1)/2 clamped to [0, 1]. Outputs: a contact sheet PNG (row by row, ⌈√N⌉
//! columns, black gaps), optionally one PNG per position (`DIR/frame-000.png`, …) and an
//! animated, looping GIF (colours quantised to a 256-colour palette per frame, NeuQuant).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, RgbaImage};
use photomat_core::image_io::{PlanarImage, PngBits, write_atomic, write_png};
use photomat_core::lights::DEFAULT_ORBIT_RADIUS;
use photomat_core::sheet::contact_sheet;
use photomat_core::{FlashGeometry, Highlight};
use photomat_generator::GanModel;
use photomat_generator::train::samples::display_tiles;

use crate::common::{orbit_lights, progress_bar};

/// Most orbit positions accepted (as `photomat render --orbit`).
const MAX_ORBIT: u32 = 1024;
/// Lights relit per forward pass of M: bounds memory (N copies of F at 1024² would not fit)
/// without giving up the batched matrix products.
const RELIGHT_BATCH: usize = 8;

/// Largest `--size`: a 4096² material's 32 feature channels alone take 2 GiB in f32.
const MAX_SIDE: u32 = 4096;
/// NeuQuant sampling factor of the GIF palettes (1 best … 30 fastest): 1 lets every pixel
/// train the palette, which halves the colour error on small frames (32²: 3/255 against
/// 7/255 at the crate's suggested 10) for a cost that stays small next to G.
const GIF_QUANTISER_SPEED: i32 = 1;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// GAN model folder (gan.json + gan.safetensors), e.g. a `photomat train-gan` run.
    #[arg(long, value_name = "RUN")]
    pub gan: PathBuf,

    /// Seed of the material (its latent z and noise images).
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,

    /// Number of flash positions on the circle.
    #[arg(long, value_name = "N", default_value_t = 8,
          value_parser = clap::value_parser!(u32).range(1..=MAX_ORBIT as i64))]
    pub orbit: u32,

    /// Radius of the circle in plane coordinates (the material spans [-0.5, 0.5]²).
    #[arg(
        long,
        value_name = "R",
        default_value_t = DEFAULT_ORBIT_RADIUS,
        allow_hyphen_values = true
    )]
    pub radius: f64,

    /// Truncation ψ: 1 samples the full distribution, smaller values move w towards the
    /// average w (more typical, less varied materials).
    #[arg(
        long,
        value_name = "PSI",
        default_value_t = 1.0,
        allow_hyphen_values = true
    )]
    pub psi: f64,

    /// Side of the material in texels [default: the model's native output: R for a
    /// fixed-size model, 512 for a spatial one]. A spatial model
    /// makes any multiple of R/4 (a larger side shows more of the material at the same
    /// texel scale); a fixed-size model only R.
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=MAX_SIDE as i64))]
    pub size: Option<u32>,

    /// Contact sheet of all positions (PNG).
    #[arg(long, value_name = "FILE.png")]
    pub out: PathBuf,

    /// Also write one PNG per position into this folder (created if missing).
    #[arg(long, value_name = "DIR")]
    pub frames: Option<PathBuf>,

    /// Also write the positions as an animated, looping GIF.
    #[arg(long, value_name = "FILE.gif")]
    pub gif: Option<PathBuf>,

    /// Display time of each GIF frame in milliseconds.
    #[arg(long, value_name = "MS", default_value_t = 100,
          value_parser = clap::value_parser!(u32).range(10..=60_000))]
    pub frame_ms: u32,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    check_extension(&args.out, "png", "--out")?;
    if let Some(gif) = &args.gif {
        check_extension(gif, "gif", "--gif")?;
    }
    if !args.psi.is_finite() {
        bail!("--psi must be a finite number, got {}", args.psi);
    }
    let lights = orbit_lights(args.orbit, args.radius)?;
    let device = Device::Cpu;
    let model = GanModel::load(&args.gan, &device)
        .with_context(|| format!("cannot load the GAN model in '{}'", args.gan.display()))?;
    let config = model.config();
    let side = config.sample_side(args.size.map(|s| s as usize))?;
    let world_side = config.world_side(side)?;
    // The orbit is given on the unit material square; scale it to the material's extent.
    let lights = lights.scaled(world_side);
    let highlights = lights.highlights();

    let bar = progress_bar(
        highlights.len() as u64,
        "{elapsed_precise} [{bar:40}] {pos}/{len} lights ({eta} left)",
    );
    let features = model
        .features_for_seeds_at(&[args.seed], args.psi, side)
        .context("cannot generate the material")?;
    let mut tiles = Vec::with_capacity(highlights.len());
    // M's intermediates grow with lights × texels: RELIGHT_BATCH lights up to 512², fewer above.
    let per_call = (RELIGHT_BATCH * 512 * 512 / (side * side)).clamp(1, RELIGHT_BATCH);
    for lights in highlights.chunks(per_call) {
        tiles.extend(relight(&model, &features, lights, side, world_side)?);
        bar.inc(lights.len() as u64);
    }
    bar.finish_and_clear();

    let sheet = contact_sheet(&tiles, 0.0)?;
    write_png(&args.out, &sheet, PngBits::Eight)
        .with_context(|| format!("cannot write '{}'", args.out.display()))?;
    writeln!(
        out,
        "wrote {} ({}×{}): material seed {} (ψ = {}) of '{}' under {} flash positions, {side}×{side} each",
        args.out.display(),
        sheet.width,
        sheet.height,
        args.seed,
        args.psi,
        args.gan.display(),
        tiles.len()
    )?;
    write_extras(args, &tiles, out)
}

/// `--frames DIR` and `--gif FILE`, when given.
fn write_extras(args: &Args, tiles: &[PlanarImage], out: &mut dyn Write) -> anyhow::Result<()> {
    if let Some(dir) = &args.frames {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the frames folder '{}'", dir.display()))?;
        for (k, tile) in tiles.iter().enumerate() {
            let path = dir.join(frame_name(k));
            write_png(&path, tile, PngBits::Eight)
                .with_context(|| format!("cannot write '{}'", path.display()))?;
        }
        writeln!(out, "wrote {} frames into {}", tiles.len(), dir.display())?;
    }
    if let Some(path) = &args.gif {
        let bytes = encode_gif(tiles, args.frame_ms)
            .with_context(|| format!("cannot encode '{}'", path.display()))?;
        write_atomic(path, &bytes).with_context(|| format!("cannot write '{}'", path.display()))?;
        writeln!(
            out,
            "wrote {} ({} frames, {} ms each)",
            path.display(),
            tiles.len(),
            args.frame_ms
        )?;
    }
    Ok(())
}

/// The material `features` (1, C, N, N) relit under each of `lights` (world coordinates of
/// the highlight relative to the material's centre) on a square of side `world_side`, as
/// display tiles.
fn relight(
    model: &GanModel,
    features: &Tensor,
    lights: &[Highlight],
    side: usize,
    world_side: f64,
) -> anyhow::Result<Vec<PlanarImage>> {
    let (_, c, h, w) = features.dims4()?;
    let batch = features
        .broadcast_as((lights.len(), c, h, w))?
        .contiguous()?;
    let omega =
        FlashGeometry::with_side(lights, side, world_side, DType::F32, model.device())?.omega;
    let images = model
        .relight()
        .forward(&batch, &omega)
        .context("cannot relight the material")?;
    Ok(display_tiles(&images)?)
}

/// File name of frame `k` in `--frames DIR`.
pub fn frame_name(k: usize) -> String {
    format!("frame-{k:03}.png")
}

/// An animated GIF of display tiles (values in [0, 1]), looping forever.
fn encode_gif(tiles: &[PlanarImage], frame_ms: u32) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    {
        let mut encoder = GifEncoder::new_with_speed(&mut bytes, GIF_QUANTISER_SPEED);
        encoder.set_repeat(Repeat::Infinite)?;
        let delay = Delay::from_numer_denom_ms(frame_ms, 1);
        encoder.encode_frames(
            tiles
                .iter()
                .map(|t| Frame::from_parts(rgba8(t), 0, 0, delay)),
        )?;
    }
    Ok(bytes)
}

/// A 3-channel display image (values in [0, 1]) as opaque 8-bit RGBA.
fn rgba8(image: &PlanarImage) -> RgbaImage {
    let (w, h) = (image.width, image.height);
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    RgbaImage::from_fn(w as u32, h as u32, |x, y| {
        let (row, col) = (y as usize, x as usize);
        image::Rgba([
            to_u8(image.get(0, row, col)),
            to_u8(image.get(1, row, col)),
            to_u8(image.get(2, row, col)),
            255,
        ])
    })
}

/// Refuse output names that promise another format.
fn check_extension(path: &Path, ext: &str, flag: &str) -> anyhow::Result<()> {
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case(ext))
    {
        bail!("{flag} must name a .{ext} file, got '{}'", path.display());
    }
    Ok(())
}
