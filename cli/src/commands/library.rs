//! `photomat library import SRC… --out LIB [--seed S] [--min-side 256] [--max-side 1024]
//! [--overwrite]`: artist-made texture sets of game-data packages (extracted with
//! `data/sources/debian.sh PACKAGE DIR`, or any folder or zip/pk3 archive of texture sets) →
//! a material library: per material a `ggx` folder (the artist's normals) and a
//! `height(ggx, scale=S)` folder (their integral), `library.json` (splits, packages,
//! licences, what was left out) and `contact_sheet.png`. The importer is
//! `photomat_library::import`; this command parses the flags, shows progress and prints the
//! counts (docs/data.md).

use std::io::Write;
use std::path::PathBuf;
use std::sync::Mutex;

use photomat_library::convert::ConvertOptions;
use photomat_library::import::{ImportEvent, ImportOptions, ImportReport, import};
use photomat_library::split::Split;

use crate::common::{interruption, progress_bar, stop_flag};

#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(subcommand)]
    pub command: LibraryCommand,
}

#[derive(Debug, clap::Subcommand)]
pub enum LibraryCommand {
    /// Import texture sets from package folders or archives into a material library.
    Import(ImportArgs),
}

#[derive(Debug, clap::Args)]
pub struct ImportArgs {
    /// Sources: extracted package folders (`data/sources/debian.sh`), folders or zip/pk3
    /// archives of texture sets.
    #[arg(required = true, value_name = "SRC")]
    pub sources: Vec<PathBuf>,

    /// The library folder to write.
    #[arg(long, value_name = "LIB")]
    pub out: PathBuf,

    /// Seed of the training / validation / test splits [default: 0].
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,

    /// Smallest side of a base colour [default: 256].
    #[arg(long, value_name = "PIXELS", default_value_t = 256,
          value_parser = clap::value_parser!(u32).range(16..=4096))]
    pub min_side: u32,

    /// Largest side of the maps written; larger textures are halved [default: 1024].
    #[arg(long, value_name = "PIXELS", default_value_t = 1024,
          value_parser = clap::value_parser!(u32).range(16..=4096))]
    pub max_side: u32,

    /// Replace the library in LIB, whole.
    #[arg(long)]
    pub overwrite: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    match &args.command {
        LibraryCommand::Import(args) => run_import(args, out),
    }
}

fn run_import(args: &ImportArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let options = ImportOptions {
        convert: ConvertOptions {
            min_side: args.min_side as usize,
            max_side: args.max_side as usize,
        },
        seed: args.seed,
        overwrite: args.overwrite,
        ..ImportOptions::default()
    };
    let stop = stop_flag()?;
    let bar = Mutex::new(None);
    let report = import(&args.sources, &args.out, &options, &stop, &|event| {
        let Ok(mut bar) = bar.lock() else { return };
        match event {
            ImportEvent::Source { package, sets } => {
                if let Some(old) = bar.take() {
                    indicatif::ProgressBar::finish_and_clear(&old);
                }
                let b = progress_bar(
                    sets as u64,
                    "{elapsed_precise} [{bar:30}] {pos}/{len} texture sets {msg}",
                );
                b.set_message(package);
                *bar = Some(b);
            }
            ImportEvent::Set => {
                if let Some(b) = bar.as_ref() {
                    b.inc(1);
                }
            }
            ImportEvent::Unreadable(message) => match bar.as_ref() {
                Some(b) => b.suspend(|| eprintln!("warning: {message}")),
                None => eprintln!("warning: {message}"),
            },
        }
    })?;
    if let Ok(Some(b)) = bar.lock().map(|mut b| b.take()) {
        b.finish_and_clear();
    }
    if report.interrupted {
        eprintln!(
            "interrupted: {} is as it was; run the same command again to import",
            args.out.display()
        );
        return Err(interruption().into());
    }
    print_report(&report, out)
}

/// The counts per package and split, what was left out, and where the outputs are.
fn print_report(report: &ImportReport, out: &mut dyn Write) -> anyhow::Result<()> {
    let index = &report.index;
    writeln!(
        out,
        "{} materials in {} ({} train, {} validation, {} test)",
        index.materials.len(),
        report.library.display(),
        index.split(Split::Train).len(),
        index.split(Split::Validation).len(),
        index.split(Split::Test).len(),
    )?;
    for package in &index.packages {
        let count = |s: Split| package.materials.get(&s).copied().unwrap_or(0);
        writeln!(
            out,
            "  {} {}: {} texture sets → {} materials ({} / {} / {}); licences: {}",
            package.package.name,
            package.package.version,
            package.sets,
            count(Split::Train) + count(Split::Validation) + count(Split::Test),
            count(Split::Train),
            count(Split::Validation),
            count(Split::Test),
            package
                .licences
                .iter()
                .map(|(l, n)| format!("{l} ({n})"))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        for (reason, n) in &package.rejected {
            writeln!(out, "      left out {n}: {}", reason.describe())?;
        }
    }
    if !report.unreadable.is_empty() {
        writeln!(
            out,
            "  {} files could not be read (warnings above)",
            report.unreadable.len()
        )?;
    }
    writeln!(
        out,
        "  {}/library.json  index (splits, packages, licences)",
        report.library.display()
    )?;
    writeln!(
        out,
        "  {}/contact_sheet.png  diffuse | normal | roughness | height | flash render",
        report.library.display()
    )?;
    Ok(())
}
