//! `photomat sample [--model MODEL] --count N --out OUT [--seed S] [--psi ψ] [--tileable]
//! [--hextile] [--gltf] [--mtlx] [--size-render PX] [--brdf SPEC|auto] [--simplify]
//! [--tolerance T]`: the
//! product's main job, the reference
//! tool's sampler. The pipeline is the library's [`photomat_estimator::sample::Sampler`]
//! (what it writes under `OUT/seed-XXXX/`, the contact sheet and `summary.json` are described
//! there); this command parses the flags, finds the model folder and shows progress.
//!
//! `--model` defaults to `$PHOTOMAT_MODEL`, else the bundled `models/demo/` of this source tree.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;

use anyhow::bail;
use candle_core::Device;
use photomat_estimator::sample::{
    BrdfChoice, CONTACT_SHEET_FILE, DEFAULT_TOLERANCE, SHEET_MAX_ROWS, SUMMARY_FILE, SampleEvent,
    SampleOptions, SampleSummary, Sampler,
};

use crate::common::{interruption, model_dir, progress_bar, stop_flag};

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

    /// Side of each material in texels [default: the model's native side: 512 for a spatial
    /// model such as the bundled one, R for a fixed-size model (which makes R only)]. A
    /// spatial model makes any multiple of its generator's cell and its estimator's stride
    /// (32 for the bundled model) up to 4096; its texel keeps its size, so a larger side
    /// shows more of the material, and memory grows with the side² (about 4.7 GB at 2048²).
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub size: Option<u32>,

    /// Side in pixels of each render and preview in the PNG sheets [default: the material's
    /// side]; the maps themselves keep the material's side.
    #[arg(long = "size-render", value_name = "PX",
          value_parser = clap::value_parser!(u32).range(8..=4096))]
    pub size_render: Option<u32>,

    /// Replace the samples already in --out, whole; without it a folder holding samples is
    /// refused (and one holding files a sample run does not write is refused always).
    #[arg(long)]
    pub overwrite: bool,

    /// BRDF model of the maps: one the model folder has an estimator for (its root one by
    /// default, others under estimators/<name>/), or `auto`: per material, the cheapest model
    /// (fewest map channels) whose L1 of linear radiance against M's relighting is within
    /// --tolerance of the best one's. material.json records the choice and every candidate's
    /// error.
    #[arg(long, value_name = "SPEC|auto")]
    pub brdf: Option<String>,

    /// Store only the maps a material requires: a map whose constant (its mean) keeps the
    /// material's L1 against M's relighting within --tolerance, of linear radiance and of
    /// display-encoded images alike, becomes a value in material.json (a factor in the --gltf / --mtlx exports), a colour map whose grey
    /// (luminance) does becomes one channel. material.json and summary.json record what was
    /// simplified, the error added and the bytes saved.
    #[arg(long)]
    pub simplify: bool,

    /// With --brdf auto: accepted L1 above the best model's; with --simplify: accepted L1
    /// above the material's own before simplifying. Relative (0.1 = 10 %).
    #[arg(long, value_name = "T", default_value_t = DEFAULT_TOLERANCE)]
    pub tolerance: f64,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    if !(args.psi.is_finite()) {
        bail!("--psi must be a finite number, got {}", args.psi);
    }
    // The model is checked by name before any model folder loads.
    let brdf = match &args.brdf {
        Some(text) => BrdfChoice::parse(text, args.tolerance)?,
        None => BrdfChoice::Default,
    };
    let dir = model_dir(args.model.as_deref())?;
    let sampler = Sampler::open(&dir, &Device::Cpu)?;
    let options = SampleOptions {
        count: args.count as usize,
        seed: args.seed,
        psi: args.psi,
        tileable: args.tileable,
        hextile: args.hextile,
        gltf: args.gltf,
        mtlx: args.mtlx,
        size: args.size.map(|s| s as usize),
        render_size: args.size_render.map(|s| s as usize),
        overwrite: args.overwrite,
        brdf,
        simplify: args.simplify.then_some(args.tolerance),
    };
    let bar = progress_bar(
        args.count as u64,
        "{elapsed_precise} [{bar:40}] {pos}/{len} materials ({per_sec}, {eta} left)",
    );
    let stop = stop_flag()?;
    let result = sampler.run(&options, &args.out, &mut |event| {
        if stop.load(Ordering::SeqCst) {
            anyhow::bail!("stopped");
        }
        match event {
            SampleEvent::Note(line) => bar.suspend(|| writeln!(out, "{line}"))?,
            SampleEvent::Material { .. } => bar.inc(1),
        }
        Ok(())
    });
    bar.finish_and_clear();
    if stop.load(Ordering::SeqCst) {
        eprintln!(
            "interrupted: nothing was written; {} is as it was. Run the same command again to \
             sample",
            args.out.display()
        );
        return Err(interruption().into());
    }
    let summary = result?;
    report(args, &dir, &summary, out)
}

/// The lines after a run: what was written where, and the run's L1 and speed.
fn report(
    args: &Args,
    dir: &Path,
    summary: &SampleSummary,
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    let resolution = summary.resolution;
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
        args.out.join(CONTACT_SHEET_FILE).display(),
        if summary.seeds.len() > SHEET_MAX_ROWS {
            format!(" (the first {SHEET_MAX_ROWS})")
        } else {
            String::new()
        }
    )?;
    // Larger than a photo, a material has texels M never saw lit that obliquely.
    // Relative 1e-6: above the f32 rounding of the two sums, which agree when every texel is
    // within reach.
    let gap = (summary.l1_within_photo_reach - summary.l1_mean).abs();
    let in_reach = if gap > 1e-6 * summary.l1_mean.abs().max(f64::MIN_POSITIVE) {
        format!(
            " ({:.4} within a photo's reach of the flash)",
            summary.l1_within_photo_reach
        )
    } else {
        String::new()
    };
    writeln!(
        out,
        "  {}  L1 analytic vs neural (encoded): {:.4} mean{in_reach}; {:.1} materials/min",
        args.out.join(SUMMARY_FILE).display(),
        summary.l1_mean,
        summary.materials_per_minute
    )?;
    if summary.brdf == "auto" {
        let counts: Vec<String> = summary
            .brdf_counts
            .iter()
            .map(|(brdf, n)| format!("{n} × {brdf}"))
            .collect();
        writeln!(
            out,
            "  --brdf auto (tolerance {}): {}",
            args.tolerance,
            counts.join(", ")
        )?;
    }
    if let Some(totals) = &summary.simplification {
        let counts: Vec<String> = totals
            .counts
            .iter()
            .map(|(what, n)| format!("{n} × {what}"))
            .collect();
        let saved = totals.bytes_before.saturating_sub(totals.bytes_after);
        writeln!(
            out,
            "  --simplify (tolerance {}): {}; {:.1} MB of {:.1} MB saved ({:.0} %); {}",
            args.tolerance,
            if counts.is_empty() {
                "no map could be simplified".to_string()
            } else {
                counts.join(", ")
            },
            saved as f64 / 1e6,
            totals.bytes_before as f64 / 1e6,
            100.0 * saved as f64 / totals.bytes_before.max(1) as f64,
            (0..totals.metrics.len())
                .map(|i| format!(
                    "{} {:.4} → {:.4}",
                    totals.metrics[i], totals.error_before[i], totals.error_after[i]
                ))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
    }
    Ok(())
}
