//! `photomat simulate --count N --size S --out DIR [--seed K] [--format jpg|png]`: phone-flash
//! photos of procedural materials with their ground truth (format in
//! docs/datasets.md): `DIR/photos/`, `DIR/truth/` (material folders of each photo's shading
//! model over the photographed area) and `DIR/simulation.json` (family, seed, true highlight
//! and camera per photo). The same `--seed` gives byte-identical output on any machine with
//! the same build, whatever `--threads`.
//!
//! Photo i uses family number i mod F of the (sorted) `--families`, so each is equally
//! represented. The camera model (`photomat_data::simulator::camera`): auto-exposure with
//! jitter, white-balance error, flash beam profile, vignetting, weak ambient light, sensor
//! noise, an sRGB or gamma-2.2 tone curve with a mild S-curve, 8-bit JPEG (quality 92) or PNG,
//! with EXIF recording the 90° lens (so that `photomat capture` needs no `--fov` for them).
//! `--camera ideal` switches all of it off (exact renderer output, gamma 2.2).
//! `--max-tilt` and `--flash-offset` hold the phone as a hand does
//! (`photomat_data::simulator::pose`): a tilted camera and a flash beside the lens; the true
//! highlight is then the flash's mirror point as the lens sees it.
//!
//! `--library LIB --split train|validation|test` photographs the materials of a material
//! library's split (`photomat library import`) instead of procedural families: per photo one
//! material (or a mix of two), seen at a random zoom, offset and orientation
//! (`photomat_library::photos`, docs/data.md); `simulation.json` names each photo's
//! material(s) and how they were seen, `truth/` holds their `ggx` maps as photographed.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use photomat_data::procedural::{Family, families, family, family_names};
use photomat_data::simulator::{
    CameraModel, CameraSource, HighlightJitter, PhoneCamera, PhotoFormat, PoseJitter,
    SimulationConfig, SimulationManifest, simulate,
};

use photomat_library::photos::{Augmentation, LibraryFamily};

use crate::common::{parse_pair, progress_bar};

/// `LO,HI` of `--flash-offset` (ranges are checked by the simulator).
fn parse_offset_range(text: &str) -> Result<(f64, f64), String> {
    parse_pair(text, "LO,HI")
}

/// Photo file format on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// JPEG, quality 92 (what phones write).
    Jpg,
    /// Lossless 8-bit PNG.
    Png,
}

/// Camera model on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Camera {
    /// A random phone camera per photo.
    Phone,
    /// No camera effects: exposure 1, gamma 2.2, no noise, vignetting or ambient light.
    Ideal,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Number of photos.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    pub count: u32,

    /// Photo side in pixels (photos are square; the truth maps have the same size).
    #[arg(long, value_name = "S", default_value_t = 512,
          value_parser = clap::value_parser!(u32).range(8..=8192))]
    pub size: u32,

    /// Output folder: photos/, truth/ and simulation.json are written inside.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Seed of the run: the same seed gives the same photos, byte for byte.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub seed: u64,

    /// Photo file format.
    #[arg(long, value_enum, default_value_t = Format::Jpg)]
    pub format: Format,

    /// Material families to cycle through, comma-separated (default: all).
    #[arg(
        long,
        value_name = "NAMES",
        value_delimiter = ',',
        conflicts_with = "library"
    )]
    pub families: Vec<String>,

    /// A material library (`photomat library import` output): photograph its materials
    /// instead of procedural families.
    #[arg(long, value_name = "LIB", requires = "split")]
    pub library: Option<PathBuf>,

    /// The library's split to photograph: train, validation or test.
    #[arg(long, value_name = "SPLIT", requires = "library")]
    pub split: Option<photomat_library::split::Split>,

    /// Leave out library materials with this licence (repeatable), e.g. `GPL-3+` for photos
    /// a model under CC-BY-SA is trained on (docs/data.md, "Licences").
    #[arg(long, value_name = "LICENCE", requires = "library")]
    pub exclude_licence: Vec<String>,

    /// Range of library materials across one photo, LO,HI (log-uniform; materials are
    /// periodic).
    #[arg(long, value_name = "LO,HI", default_value = "0.5,1.5", value_parser = parse_offset_range,
          requires = "library")]
    pub zoom: (f64, f64),

    /// Probability that a photo of the library shows a mix of two materials.
    #[arg(long, value_name = "P", default_value_t = 0.2, requires = "library")]
    pub mix_prob: f64,

    /// Camera model.
    #[arg(long, value_enum, default_value_t = Camera::Phone)]
    pub camera: Camera,

    /// Standard deviation of the highlight's offset from the centre, as a fraction of the
    /// photo width (Gaussian per axis, truncated at 3σ).
    #[arg(long, value_name = "FRACTION", default_value_t = 0.04)]
    pub jitter: f64,

    /// Largest tilt of the phone away from the plane's normal, degrees (uniform in [0, MAX]
    /// about a random axis; at most 30). 0, the default, is the training convention: the
    /// camera looks straight down.
    #[arg(long, value_name = "DEGREES", default_value_t = 0.0)]
    pub max_tilt: f64,

    /// Distance of the flash from the lens as a range LO,HI, a fraction of the camera's height
    /// (uniform, in a random direction; at most 0.25). `0,0`, the default, puts the flash in
    /// the lens. Hand-held phones: `--max-tilt 12 --flash-offset 0.03,0.07`.
    #[arg(long, value_name = "LO,HI", default_value = "0,0", value_parser = parse_offset_range)]
    pub flash_offset: (f64, f64),

    /// Replace a previous simulation in DIR (removes DIR/photos, DIR/truth and
    /// DIR/simulation.json, nothing else).
    #[arg(long)]
    pub overwrite: bool,

    /// Worker threads (0: one per core). The output does not depend on it.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub threads: usize,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    if !(args.jitter.is_finite() && (0.0..=0.15).contains(&args.jitter)) {
        bail!(
            "--jitter must lie in [0, 0.15] (3σ must keep the highlight inside the photo), got {}",
            args.jitter
        );
    }
    let chosen: Vec<Box<dyn Family>> =
        if let (Some(library), Some(split)) = (&args.library, args.split) {
            if !(0.0..=1.0).contains(&args.mix_prob) {
                bail!("--mix-prob must lie in [0, 1], got {}", args.mix_prob);
            }
            let augmentation = Augmentation {
                zoom: args.zoom,
                mix_probability: args.mix_prob,
                ..Augmentation::default()
            };
            vec![Box::new(
                LibraryFamily::open(library, split, &args.exclude_licence, augmentation)
                    .context("invalid --library")?,
            )]
        } else if args.families.is_empty() {
            families()
        } else {
            let mut names: Vec<&str> = args.families.iter().map(|n| n.trim()).collect();
            names.sort();
            names.dedup();
            names
                .iter()
                .map(|name| family(name))
                .collect::<Result<_, _>>()
                .context("invalid --families")?
        };
    let config = SimulationConfig {
        count: args.count as usize,
        size: args.size as usize,
        seed: args.seed,
        format: match args.format {
            Format::Jpg => PhotoFormat::Jpeg,
            Format::Png => PhotoFormat::Png,
        },
        families: chosen.iter().map(|f| f.as_ref()).collect(),
        camera: match args.camera {
            Camera::Phone => CameraSource::Phone(PhoneCamera::default()),
            Camera::Ideal => CameraSource::Fixed(CameraModel::ideal()),
        },
        jitter: HighlightJitter {
            sigma: args.jitter,
            ..HighlightJitter::default()
        },
        pose: PoseJitter {
            max_tilt_degrees: args.max_tilt,
            flash_offset: args.flash_offset,
        },
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads)
        .build()
        .context("cannot start the worker threads")?;

    let bar = progress_bar(
        args.count as u64,
        "{elapsed_precise} [{bar:40}] {pos}/{len} photos ({per_sec}, {eta} left)",
    );
    let start = Instant::now();
    let result = pool.install(|| simulate(&args.out, &config, args.overwrite, &|| bar.inc(1)));
    bar.finish_and_clear();
    let manifest =
        result.with_context(|| format!("cannot simulate photos into '{}'", args.out.display()))?;
    let seconds = start.elapsed().as_secs_f64();
    let used: Vec<&str> = config.families.iter().map(|f| f.name()).collect();
    report(
        args,
        &manifest,
        &used,
        seconds,
        pool.current_num_threads(),
        out,
    )
}

/// The lines after a run: speed, families and what was written where.
fn report(
    args: &Args,
    manifest: &SimulationManifest,
    used: &[&str],
    seconds: f64,
    threads: usize,
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    writeln!(
        out,
        "simulated {} photos of {}×{} (seed {}) in {seconds:.1} s: {:.2} photos/s on {} threads",
        manifest.photos.len(),
        manifest.size,
        manifest.size,
        manifest.seed,
        // A zero elapsed time cannot happen for a run that wrote files; the floor only keeps
        // the division finite.
        manifest.photos.len() as f64 / seconds.max(1e-9),
        threads
    )?;
    writeln!(
        out,
        "  families: {} (all: {})",
        used.join(", "),
        family_names().join(", ")
    )?;
    let dir = args.out.display();
    writeln!(out, "  {dir}/photos/  8-bit photos")?;
    writeln!(
        out,
        "  {dir}/truth/   ground-truth maps of each photo's shading model"
    )?;
    writeln!(
        out,
        "  {dir}/simulation.json  true highlight, family, seed and camera per photo"
    )?;
    writeln!(
        out,
        "next: photomat prepare --photos {dir}/photos --out {dir}-dataset"
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn simulate_command_writes_photos_truth_and_record() {
        let dir = tempfile::tempdir().unwrap();
        let out_dir = dir.path().join("sim");
        let out_arg = out_dir.to_str().unwrap();
        let args = [
            "photomat",
            "simulate",
            "--count",
            "3",
            "--size",
            "16",
            "--out",
            out_arg,
            "--families",
            "wood, tiles",
            "--format",
            "png",
            "--seed",
            "5",
        ];
        let mut out = Vec::new();
        crate::run_with_output(args, &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.contains("simulated 3 photos of 16×16 (seed 5)"),
            "{text}"
        );
        assert!(text.contains("families: tiles, wood"), "{text}");
        let record = photomat_data::simulator::SimulationManifest::read(&out_dir).unwrap();
        let families: Vec<&str> = record.photos.iter().map(|p| p.family.as_str()).collect();
        assert_eq!(families, ["tiles", "wood", "tiles"]);
        for photo in &record.photos {
            assert!(out_dir.join(&photo.photo).is_file());
            assert!(out_dir.join(&photo.truth).join("material.json").is_file());
        }
        // A second run into the same folder needs --overwrite.
        let err = crate::run_with_output(args, &mut Vec::new()).unwrap_err();
        assert!(format!("{err:#}").contains("--overwrite"), "{err:#}");
        let bad = crate::run_with_output(
            [
                "photomat",
                "simulate",
                "--count",
                "1",
                "--out",
                out_arg,
                "--families",
                "marble",
            ],
            &mut Vec::new(),
        )
        .unwrap_err();
        assert!(format!("{bad:#}").contains("wood"), "{bad:#}");
    }
}
