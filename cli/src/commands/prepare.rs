//! `photomat prepare --photos DIR --out DATASET [--size 512] [--detector robust|paper]
//! [--reject-non-square]`: a folder of phone flash photos → a training dataset (format
//! in docs/datasets.md; paper §"Dataset collection").
//!
//! Reads JPEG and PNG (8/16-bit, grey/RGB/RGBA, EXIF orientation applied), centre-crops each
//! photo to a square, resizes it to the working size in linear light (Lanczos3), detects the
//! flash highlight (in parallel, progress bar on stderr) and writes `DATASET/images/`,
//! `DATASET/index.json` and `DATASET/report.txt`. Bad files are listed with their reason and
//! skipped; re-running only processes new or changed files. The library side is
//! `photomat_data::dataset::prepare`.

use std::io::Write;
use std::path::PathBuf;

use photomat_data::dataset::{PrepareOptions, REPORT_FILE, prepare};
use photomat_data::highlight::DetectorKind;

use crate::common::parse_detector;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folder of flash photos (JPEG or PNG; files directly inside it).
    #[arg(long, value_name = "DIR")]
    pub photos: PathBuf,

    /// Dataset folder to create or extend: images/, index.json and report.txt.
    #[arg(long, value_name = "DATASET")]
    pub out: PathBuf,

    /// Side of the prepared square images, in pixels; photos whose shorter side is below a
    /// quarter of it are rejected.
    #[arg(long, value_name = "PIXELS", default_value_t = 512,
          value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub size: u32,

    /// Highlight detector: `robust` (fits the flash falloff, vignetting and ambient light) or
    /// `paper` (the paper's above-mean centroid). Default: the dataset's, else robust.
    #[arg(long, value_name = "NAME", value_parser = parse_detector)]
    pub detector: Option<DetectorKind>,

    /// Reject non-square photos instead of centre-cropping them.
    #[arg(long)]
    pub reject_non_square: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let options = PrepareOptions {
        size: args.size as usize,
        detector: args.detector,
        reject_non_square: args.reject_non_square,
        progress: true,
    };
    let summary = prepare(&args.photos, &args.out, &options)?;
    let new = summary.added + summary.rejected;
    writeln!(
        out,
        "{} files in {}: {} new or changed, {} unchanged",
        summary.files,
        args.photos.display(),
        new,
        summary.unchanged
    )?;
    if new > 0 {
        writeln!(
            out,
            "  added {} photos ({} with the highlight at the fallback centre), rejected {}, \
             {:.1} s ({:.1} files/s)",
            summary.added,
            summary.added_fallbacks,
            summary.rejected,
            summary.seconds,
            new as f64 / summary.seconds.max(1e-9)
        )?;
    }
    writeln!(
        out,
        "dataset {}: {} photos of {}², detector '{}', {} rejected files",
        args.out.display(),
        summary.total_photos,
        args.size,
        summary.detector,
        summary.total_rejected
    )?;
    writeln!(
        out,
        "  {}  every rejected file and fallback, with the reason",
        args.out.join(REPORT_FILE).display()
    )?;
    Ok(())
}
