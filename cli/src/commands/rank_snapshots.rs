//! `photomat rank-snapshots RUN [--data DATASET] [--seeds 4] [--count 64] [--best-to DIR]
//! [--json]`: the snapshots a `train-gan --snapshot-every N` run kept, ranked by their SWD to
//! the data set averaged over several seeds (`photomat_data::snapshots`), so that the model to
//! keep is the best measured one rather than the last one. Writes
//! `RUN/snapshots/ranking.json`; `--best-to DIR` copies the best snapshot there as a model
//! folder (what `train-estimator --gan` and `sample --model` take). Each measurement is kept in
//! its snapshot (`swd_scores.json`), so ranking again while the run adds snapshots, with more
//! seeds, or after Ctrl-C measures only what is new. It runs beside a training run that is
//! writing RUN (it takes no lock: it writes only those two kinds of files, atomically), and a
//! snapshot that cannot be read is reported and left out.

use std::io::Write;
use std::path::PathBuf;

use photomat_data::ranking::{RankSettings, rank_run};
use photomat_data::snapshots::SnapshotScore;

use crate::common::progress_bar;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// A `photomat train-gan` run folder that kept snapshots (RUN/snapshots/step-NNNNNN/).
    #[arg(value_name = "RUN")]
    pub run: PathBuf,

    /// Prepared data set whose patches are the reference [default: the run's, from
    /// RUN/train.json].
    #[arg(long, value_name = "DATASET")]
    pub data: Option<PathBuf>,

    /// Seeds per snapshot (0 … N−1), one SWD each. One seed can misrank: two seeds of one
    /// model differ by up to half at 64 images (docs/benchmarks/gan-training.md, "Picking a
    /// snapshot"). At most 64: beyond that the seeds' mean moves less than the snapshots differ.
    #[arg(long, value_name = "N", default_value_t = 4,
          value_parser = clap::value_parser!(u64).range(1..=64))]
    pub seeds: u64,

    /// Relit samples and real patches per seed (as `eval-gan --count`; both sets are held in
    /// memory). About 4 s per seed and snapshot for the bundled recipe on two threads at 64.
    #[arg(long, value_name = "N", default_value_t = 64,
          value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub count: u64,

    /// Copy the best snapshot's gan.json + gan.safetensors into this folder, a new GAN model
    /// folder (one holding other files, e.g. a model folder with estimators, is refused).
    #[arg(long, value_name = "DIR")]
    pub best_to: Option<PathBuf>,

    /// Replace the GAN model in the --best-to folder.
    #[arg(long, requires = "best_to")]
    pub overwrite: bool,

    /// Print the ranking as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let settings = RankSettings {
        run: args.run.clone(),
        data: args.data.clone(),
        count: args.count as usize,
        seeds: args.seeds,
        best_to: args.best_to.clone(),
        overwrite: args.overwrite,
    };
    let bar = progress_bar(
        0,
        "{elapsed_precise} [{bar:40}] {pos}/{len} SWD measurements ({eta} left)",
    );
    let ranking = rank_run(&settings, &mut |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    });
    bar.finish_and_clear();
    let ranking = ranking?;
    for unscored in &ranking.unscored {
        eprintln!(
            "warning: {} not ranked: {}",
            unscored.folder.display(),
            unscored.error
        );
    }
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&ranking.report)?)?;
        return Ok(());
    }
    print_table(&ranking.ranking, &ranking.settings.seeds, out)?;
    writeln!(out, "ranking written to {}", ranking.ranking_path.display())?;
    if let Some(dir) = &args.best_to {
        let best = &ranking.ranking[0];
        writeln!(
            out,
            "best: {} copied to {}",
            best.folder.display(),
            dir.display()
        )?;
    }
    Ok(())
}

/// The ranking as a table, best first.
fn print_table(scores: &[SnapshotScore], seeds: &[u64], out: &mut dyn Write) -> anyhow::Result<()> {
    let seed_heads: String = seeds
        .iter()
        .map(|s| format!(" {:>8}", format!("seed {s}")))
        .collect();
    writeln!(
        out,
        "SWD ×10³ of each snapshot against the data set's patches (lower is closer)\n{:>4} {:>8} {:>7}{} {:>8}  folder",
        "rank", "step", "kimg", seed_heads, "mean"
    )?;
    for (rank, score) in scores.iter().enumerate() {
        let cells: String = score
            .swd_per_seed
            .iter()
            .map(|v| format!(" {v:>8.1}"))
            .collect();
        let step = score.step.map_or("–".to_string(), |s| s.to_string());
        let kimg = score.kimg.map_or("–".to_string(), |k| format!("{k:.1}"));
        writeln!(
            out,
            "{:>4} {step:>8} {kimg:>7}{cells} {:>8.1}  {}",
            rank + 1,
            score.mean,
            score.folder.display()
        )?;
    }
    Ok(())
}
