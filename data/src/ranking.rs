//! `photomat rank-snapshots` as a library driver: a GAN run's snapshots scored
//! ([`crate::snapshots::score_models`]) against the data set it trained on (or another),
//! ranked, the ranking written to `RUN/snapshots/ranking.json`, and on request the best
//! snapshot copied as a GAN model folder under the output-folder rule
//! ([`photomat_core::output_folder`]; docs/robustness.md, "Output folders").

use std::path::{Path, PathBuf};

use anyhow::Context;
use photomat_core::image_io::write_atomic;
use photomat_core::output_folder::{OutputFolder, ResultKind};
use photomat_generator::model_files::{GAN_MANIFEST_FILE, GAN_WEIGHTS_FILE, copy_gan_model};
use photomat_generator::train::SNAPSHOTS_DIR;
use photomat_generator::train::state::{CONFIG_FILE, read_config};

use crate::snapshots::{
    ScoreSettings, SnapshotScore, UnscoredFolder, ranked, run_snapshots, score_models,
};

/// The ranking's file in the run's snapshot folder.
pub const RANKING_FILE: &str = "ranking.json";

/// What `--best-to` writes: a GAN model folder.
pub const BEST_MODEL: ResultKind = ResultKind {
    what: "a GAN model",
    command: "photomat rank-snapshots --best-to",
    entries: &[GAN_MANIFEST_FILE, GAN_WEIGHTS_FILE],
    kept: &[],
};

/// What to rank and where the best goes.
#[derive(Debug, Clone, PartialEq)]
pub struct RankSettings {
    /// The `photomat train-gan` run folder.
    pub run: PathBuf,
    /// The data set whose patches are the reference (`None`: the run's, from its train.json).
    pub data: Option<PathBuf>,
    /// Fakes and real patches per seed.
    pub count: usize,
    /// Seeds 0 … N−1, one SWD each.
    pub seeds: u64,
    /// Copy the best snapshot here as a GAN model folder.
    pub best_to: Option<PathBuf>,
    /// Replace the GAN model already in `best_to`.
    pub overwrite: bool,
}

/// What [`rank_run`] measured and wrote.
#[derive(Debug, Clone)]
pub struct RunRanking {
    /// What the snapshots were scored with.
    pub settings: ScoreSettings,
    /// Best first ([`ranked`]); never empty.
    pub ranking: Vec<SnapshotScore>,
    /// Snapshots that could not be scored.
    pub unscored: Vec<UnscoredFolder>,
    /// Where the ranking was written.
    pub ranking_path: PathBuf,
    /// The ranking file's JSON.
    pub report: serde_json::Value,
}

/// Ranks the snapshots of `settings.run` (module docs); `progress` hears (SWD measurements
/// done, of how many) after each seed.
pub fn rank_run(
    settings: &RankSettings,
    progress: &mut dyn FnMut(u64, u64),
) -> anyhow::Result<RunRanking> {
    let run = &settings.run;
    let folders = run_snapshots(run)?;
    let data = match &settings.data {
        Some(data) => data.clone(),
        None if !run.join(CONFIG_FILE).exists() => anyhow::bail!(
            "{} has no {CONFIG_FILE} to say what it was trained on: give the data set with \
             --data DATASET",
            run.display()
        ),
        // A damaged train.json is reported as it is.
        None => read_config(run)?.data,
    };
    // The destination is claimed before the snapshots are scored: a folder it must not
    // replace is refused at once.
    let best_to = match &settings.best_to {
        Some(dir) => Some(OutputFolder::claim(dir, BEST_MODEL, settings.overwrite)?),
        None => None,
    };
    let score_settings = ScoreSettings {
        data,
        count: settings.count,
        seeds: (0..settings.seeds).collect(),
    };
    let total = folders.len() as u64 * settings.seeds;
    let per_model = settings.seeds;
    let scores = score_models(&folders, &score_settings, &mut |model, seeds_done| {
        progress(model as u64 * per_model + seeds_done as u64, total)
    })
    .with_context(|| {
        format!(
            "cannot score the snapshots of '{}' against '{}'",
            run.display(),
            score_settings.data.display()
        )
    })?;
    if scores.scored.is_empty() {
        let reasons: Vec<String> = scores
            .unscored
            .iter()
            .map(|u| format!("{}: {}", u.folder.display(), u.error))
            .collect();
        anyhow::bail!(
            "none of the {} snapshots of '{}' could be scored:\n  {}",
            folders.len(),
            run.display(),
            reasons.join("\n  ")
        );
    }
    let ranking = ranked(scores.scored);
    let report = serde_json::json!({
        "data": score_settings.data,
        "count": score_settings.count,
        "seeds": score_settings.seeds,
        "ranking": ranking,
        "unscored": scores.unscored,
    });
    let ranking_path = run.join(SNAPSHOTS_DIR).join(RANKING_FILE);
    write_atomic(
        &ranking_path,
        serde_json::to_string_pretty(&report)?.as_bytes(),
    )
    .with_context(|| format!("cannot write {}", ranking_path.display()))?;
    if let Some(folder) = best_to {
        copy_best(&ranking[0].folder, folder)?;
    }
    Ok(RunRanking {
        settings: score_settings,
        ranking,
        unscored: scores.unscored,
        ranking_path,
        report,
    })
}

/// Copies the model of `best` into the claimed folder and commits it.
fn copy_best(best: &Path, folder: OutputFolder) -> anyhow::Result<()> {
    copy_gan_model(best, folder.path()).with_context(|| {
        format!(
            "cannot copy the best snapshot {} to {}",
            best.display(),
            folder.output().display()
        )
    })?;
    folder.commit()?;
    Ok(())
}
