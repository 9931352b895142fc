//! `photomat eval-detector --dataset DIR [--detector NAME]`: the highlight error of the
//! detectors on a dataset prepared from `photomat simulate` output (`docs/datasets.md`, "Highlight
//! detectors").
//!
//! Re-runs each detector (default: all of them) on the dataset's images and compares with the
//! true highlight that `prepare` copied from `simulation.json` (`truth_highlight_px`, moved
//! through the same crop and resize). Prints mean and largest error in pixels and in % of the
//! image width, per material family (from the simulation record beside the source photos) and
//! overall, and how often each detector fell back to the centre. `--json` prints the same as
//! JSON. The library side is `photomat_data::dataset::evaluate`.

use std::io::Write;
use std::path::PathBuf;

use photomat_data::dataset::{FlashDataset, evaluate};
use photomat_data::highlight::DetectorKind;

use crate::common::parse_detector;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Dataset folder written by `photomat prepare` from simulated photos.
    #[arg(long, value_name = "DIR")]
    pub dataset: PathBuf,

    /// Detector to measure (repeatable); default: every detector.
    #[arg(long, value_name = "NAME", value_parser = parse_detector)]
    pub detector: Vec<DetectorKind>,

    /// Print the results as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let dataset = FlashDataset::open(&args.dataset)?;
    let mut detectors = if args.detector.is_empty() {
        DetectorKind::ALL.to_vec()
    } else {
        args.detector.clone()
    };
    detectors.dedup();
    let evaluation = evaluate(&dataset, &detectors, !args.json)?;
    if args.json {
        serde_json::to_writer_pretty(&mut *out, &evaluation)?;
        writeln!(out)?;
        return Ok(());
    }
    writeln!(
        out,
        "{}: {} of {} photos have a true highlight; images {}², errors against the truth",
        args.dataset.display(),
        evaluation.with_truth,
        evaluation.photos,
        evaluation.size
    )?;
    write!(out, "{}", evaluation.table())?;
    Ok(())
}
