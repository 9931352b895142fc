//! # photomat-cli
//!
//! The `photomat` command line as a library, so that users can build their own binary with
//! extra BRDF plugins linked in: depend on `photomat-cli`, register plugins in the binary's
//! crate with `photomat_core::register_brdf!`, and call [`run`] from `main`:
//!
//! ```ignore
//! // my-photomat/src/main.rs
//! mod my_brdf; // calls photomat_core::register_brdf!(…)
//! fn main() -> std::process::ExitCode {
//!     // SAFETY: the first statement of `main`, before any thread starts
//!     // (`photomat_kernels::threads`: candle's element-wise ops on the calling thread).
//!     unsafe {
//!         photomat_kernels::threads::run_candle_elementwise_inline();
//!         photomat_kernels::threads::fix_rayon_thread_count();
//!     }
//!     photomat_cli::run()
//! }
//! ```
//!
//! Commands (one file each under `commands/`):
//! - `photomat demo [--out DIR]`: a procedural material's maps, render, orbit and map sheets;
//! - `photomat brdfs [--json]`: the registered models with their parameter tables and `n`;
//! - `photomat render --maps DIR (--light X,Y | --orbit N) [--brdf SPEC] --out FILE.png`;
//! - `photomat brdf-eval --brdf SPEC --cases FILE.json [--grad] [--f64]`: values (and
//!   Jacobians) of a model at given directions and parameters, as JSON on stdout;
//! - `photomat simulate --count N --size S --out DIR [--seed K] [--format jpg|png]`: phone-flash
//!   photos of procedural materials with ground-truth maps and highlights;
//! - `photomat library import SRC… --out LIB`: artist-made texture sets of game-data packages
//!   → a material library (maps, provenance, licences, splits);
//! - `photomat prepare --photos DIR --out DATASET [--size 512] [--detector robust|paper]`: flash
//!   photos → square images, highlights, index.json and report.txt;
//! - `photomat eval-detector --dataset DIR [--detector NAME]`: highlight error per family;
//! - `photomat train-gan --data DATASET --out RUN (--steps N | --kimg K) [--size 64] [--tileable]
//!   [--resume]`: G, M and D on flash photos; RUN is a GAN model folder;
//! - `photomat eval-gan --gan RUN --data DATASET`: sliced Wasserstein distance to real crops;
//! - `photomat rank-snapshots RUN`: a run's snapshots ranked by their SWD over several seeds;
//! - `photomat relight --gan RUN --seed S --orbit N --out FILE.png [--gif F]`: one neural
//!   material under moving flashes;
//! - `photomat train-estimator --gan RUN --brdf SPEC --out MODEL`: E for any registered model;
//!   MODEL is a complete model folder (GAN + estimator);
//! - `photomat train-prior --library LIB --brdf SPEC --out RUN --steps N`: the relief prior,
//!   one flash photo → SPEC's maps, trained on photos of the library;
//! - `photomat sample [--model MODEL] --count N --out OUT [--gltf] [--mtlx] [--hextile]`: maps,
//!   renders, contact sheet and renderer exports of sampled materials;
//! - `photomat bench`: whole training and sampling steps timed (JSON), the Rust side of
//!   `bench/compare.py`.

use std::ffi::OsString;
use std::io::Write;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

// Link the built-in plugins: a crate that only lists them in Cargo.toml sees none
// (`docs/conventions.md`).
use photomat_brdfs as _;

mod commands;
mod common;

/// Learn material generators from flash photos and decode them into analytic SVBRDF maps.
#[derive(Debug, Parser)]
#[command(name = "photomat", version, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Generate a procedural material and show it: maps, a render and an orbit sheet.
    Demo(commands::demo::Args),
    /// List the registered BRDF models: parameter tables and channel counts n.
    Brdfs(commands::brdfs::Args),
    /// Render a material folder under the collocated flash (one image or an orbit sheet).
    Render(commands::render::Args),
    /// The spread of material maps (normal angles, per-map std) of material folders.
    MapStats(commands::map_stats::Args),
    /// Evaluate a model at given directions and parameters; JSON values and gradients.
    BrdfEval(commands::brdf_eval::Args),
    /// Simulate phone-flash photos of procedural materials, with their ground truth.
    Simulate(commands::simulate::Args),
    /// Material libraries of artist-made SVBRDF maps: `photomat library import SRC… --out LIB`.
    Library(commands::library::Args),
    /// Prepare a folder of flash photos as a dataset: square images, highlights, report.
    Prepare(commands::prepare::Args),
    /// Measure the highlight detectors against a simulated dataset's true highlights.
    EvalDetector(commands::eval_detector::Args),
    /// Train the relightable generator G, relighting MLP M and discriminator D on a dataset.
    TrainGan(commands::train_gan::Args),
    /// Sliced Wasserstein distance between a GAN's relit samples and a dataset's real crops.
    EvalGan(commands::eval_gan::Args),
    /// Rank a GAN run's snapshots by their SWD to the data set over several seeds.
    RankSnapshots(commands::rank_snapshots::Args),
    /// Relight one neural material of a trained GAN under an orbit of flash positions.
    Relight(commands::relight::Args),
    /// Train the map estimator E for a named BRDF model against a frozen GAN.
    TrainEstimator(commands::train_estimator::Args),
    /// Train the relief prior, one flash photo → a model's maps, on photos of a library.
    TrainPrior(commands::train_prior::Args),
    /// Fit the maps of a named BRDF model to one phone flash photo.
    Capture(commands::capture::Args),
    /// Sample materials from a trained model: maps, renders, contact sheet, glTF/MaterialX.
    Sample(commands::sample::Args),
    /// Speed against accuracy of BRDF models: one estimator each, same budget; table and plot.
    Trade(commands::trade::Args),
    /// Time whole training and sampling steps (JSON), for comparison with PyTorch.
    Bench(commands::bench::Args),
}

impl Command {
    fn execute(&self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self {
            Command::Demo(args) => commands::demo::run(args, out),
            Command::Brdfs(args) => commands::brdfs::run(args, out),
            Command::Render(args) => commands::render::run(args, out),
            Command::Capture(args) => commands::capture::run(args, out),
            Command::MapStats(args) => commands::map_stats::run(args, out),
            Command::BrdfEval(args) => commands::brdf_eval::run(args, out),
            Command::Simulate(args) => commands::simulate::run(args, out),
            Command::Library(args) => commands::library::run(args, out),
            Command::Prepare(args) => commands::prepare::run(args, out),
            Command::EvalDetector(args) => commands::eval_detector::run(args, out),
            Command::TrainGan(args) => commands::train_gan::run(args, out),
            Command::EvalGan(args) => commands::eval_gan::run(args, out),
            Command::RankSnapshots(args) => commands::rank_snapshots::run(args, out),
            Command::Relight(args) => commands::relight::run(args, out),
            Command::TrainEstimator(args) => commands::train_estimator::run(args, out),
            Command::TrainPrior(args) => commands::train_prior::run(args, out),
            Command::Sample(args) => commands::sample::run(args, out),
            Command::Trade(args) => commands::trade::run(args, out),
            Command::Bench(args) => commands::bench::run(args, out),
        }
    }
}

/// Run the command line of this process: parse `std::env::args_os()`, execute, print errors
/// as `error: …` followed by their causes to stderr. Exit codes: 0 success, 1 failure,
/// 2 usage error, 128 + the signal number for a training stopped by SIGINT (130), SIGTERM
/// (143) or SIGHUP (129) after its checkpoint.
pub fn run() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // Help and version requests are "errors" that print to stdout and exit 0.
            let _ = e.print();
            return ExitCode::from(e.exit_code().clamp(0, 255) as u8);
        }
    };
    let stdout = std::io::stdout();
    match cli.command.execute(&mut stdout.lock()) {
        Ok(()) => ExitCode::SUCCESS,
        // `photomat brdfs | head`: the reader has gone, nothing is left to report.
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<common::Interrupted>().is_some() => {
            let stop = e.downcast_ref::<common::Interrupted>().copied();
            let stop = stop.expect("checked by the guard");
            eprintln!("{stop}");
            ExitCode::from(stop.exit_code())
        }
        Err(e) => {
            eprintln!("{}", format_error(&e));
            ExitCode::FAILURE
        }
    }
}

fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Parse `args` (the first item is the program name, as in `std::env::args`) and execute,
/// writing the command's output to stdout. For tests and embedding; usage errors, `--help`
/// and a training stopped by a signal (after its checkpoint) come back as errors.
pub fn run_with_args<I, T>(args: I) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let stdout = std::io::stdout();
    run_with_output(args, &mut stdout.lock())
}

/// [`run_with_args`] writing the command's output (tables, JSON, status lines) to `out`.
pub fn run_with_output<I, T>(args: I, out: &mut dyn Write) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    Cli::try_parse_from(args)?.command.execute(out)?;
    out.flush()?;
    Ok(())
}

/// `error: <message>` followed by one `  caused by: <cause>` line per underlying error.
pub fn format_error(error: &anyhow::Error) -> String {
    let mut text = format!("error: {error}");
    for cause in error.chain().skip(1) {
        text.push_str(&format!("\n  caused by: {cause}"));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn format_error_lists_the_cause_chain() {
        let inner = anyhow::anyhow!("disk full");
        let error = inner.context("cannot write out.png");
        assert_eq!(
            format_error(&error),
            "error: cannot write out.png\n  caused by: disk full"
        );
    }

    #[test]
    fn usage_errors_come_back_as_errors() {
        let mut out = Vec::new();
        let err = run_with_output(["photomat", "render", "--maps", "x"], &mut out).unwrap_err();
        assert!(err.to_string().contains("--out"), "{err}");
    }
}
