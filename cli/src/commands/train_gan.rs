//! `photomat train-gan --data DATASET --out RUN (--steps N | --kimg K) [--size 64]
//! [--multiplier 0.25] [--batch 4] [--seed S] [--tileable | --spatial] [--lr 0.0025] [--pl-weight W]
//! [--checkpoint-every N] [--sample-every N] [--swd-every N] [--swd-count N] [--resume]`: trains the
//! relightable generator G, the relighting MLP M and the light-conditioned discriminator D on
//! a prepared flash-photo data set (PhotoMat §3–4). The run is the library's
//! `photomat_generator::train::GanTraining` driver; this command parses the flags, opens the
//! data set, installs the signal handler and shows progress.
//!
//! The run folder RUN holds:
//! - `train.json` (the full configuration) and `train_state.safetensors` (G, G_ema, M, D,
//!   Adam moments, counters): written atomically every `--checkpoint-every` steps, at the
//!   end, and on SIGINT (Ctrl-C), SIGTERM or SIGHUP (the current step finishes first; the
//!   command then exits with 128 + the signal number: 130, 143, 129);
//! - `gan.json` + `gan.safetensors`: the inference model (G_ema + M) with its provenance,
//!   written with every checkpoint, so RUN is a GAN model folder for `photomat relight --gan
//!   RUN` and `photomat train-estimator --gan RUN`;
//! - `log.csv`: one row per step (losses, logits, R1, seconds, and every `--swd-every` steps
//!   the sliced Wasserstein distance ×10³ of `--swd-count` relit G_ema samples against as
//!   many real crops, a fixed seeded set: `photomat_generator::swd::model_swd`, the value
//!   `photomat eval-gan` prints);
//! - `samples/step-NNNNNN.png`: five fixed materials of G_ema under four lights each, a real
//!   crop at the end of each row.
//!
//! `--resume` continues RUN from its last checkpoint with the same optimiser state, draws and
//! cadence of outputs (saved in `train.json`), until `--steps`/`--kimg` in total: the result
//! is identical to an uninterrupted run. Architecture and training flags given with
//! `--resume` must agree with `train.json` (a contradiction is an error naming the field),
//! except `--lr` (lower it to continue a diverged run; log.csv records it) and the cadence
//! flags. RUN is locked while the command runs: a second one on it fails naming this one's
//! process id. A step whose update a non-finite value skipped is reported on stderr and in
//! log.csv, and no checkpoint is written until a step updates again (docs/robustness.md).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use candle_core::Device;
use indicatif::ProgressBar;
use photomat_data::source::DatasetSource;
use photomat_generator::train::state::Restored;
use photomat_generator::train::{GanEvent, GanOutcome, GanSettings, GanTraining, RunLength};

use crate::common::{interruption, steps_bar, stop_flag};

#[derive(Debug, clap::Args)]
#[command(group(clap::ArgGroup::new("length").args(["steps", "kimg"]).required(true)))]
#[command(after_help = crate::common::STOP_HELP)]
pub struct Args {
    /// Run folder: checkpoints, samples, log and the trained GAN model.
    #[arg(long, value_name = "RUN")]
    pub out: PathBuf,

    /// Total training steps (a resumed run continues up to this count).
    #[arg(long, value_name = "N")]
    pub steps: Option<u64>,

    /// Total training length in thousands of real images (steps = ⌈1000·K / batch⌉).
    #[arg(long, value_name = "K")]
    pub kimg: Option<f64>,

    /// Continue the run in RUN from its last checkpoint.
    #[arg(long)]
    pub resume: bool,

    #[command(flatten)]
    pub settings: GanSettings,
}

impl Args {
    /// `--steps N` or `--kimg K` (clap requires one).
    fn length(&self) -> anyhow::Result<RunLength> {
        match (self.steps, self.kimg) {
            (Some(s), _) => Ok(RunLength::Steps(s)),
            (None, Some(k)) => Ok(RunLength::Kimg(k)),
            (None, None) => anyhow::bail!("give the run's length with --steps N or --kimg K"),
        }
    }
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut plan = GanTraining::plan(&args.out, &args.settings, args.resume)?;
    for note in &plan.notes {
        eprintln!("{note}");
    }
    let total = args.length()?.steps(plan.config.batch)?;
    let data =
        DatasetSource::for_training(&plan.config).context("cannot open the training data")?;
    plan.bind_data(&data)?;
    let mut training = GanTraining::open(&args.out, plan, total, &Device::Cpu)?;
    if training.restored() == Some(Restored::WithFreshOptimisers) {
        eprintln!(
            "note: {} holds no optimiser state (a portable checkpoint): the networks continue \
             from step {}, Adam restarts from zero moments",
            args.out.display(),
            training.trainer().steps_done()
        );
    }
    let stop = stop_flag()?;
    let start_step = training.trainer().steps_done();
    let c = training.trainer().config();
    writeln!(
        out,
        "training {}² (multiplier {}, batch {}, seed {}{}) on {} ({} photos): steps {} → {total}",
        c.generator.resolution,
        c.generator.channel_multiplier,
        c.batch,
        c.seed,
        match (&c.generator.spatial, c.generator.tileable) {
            (Some(_), _) => ", spatial: any-size, on patches at the photos' resolution",
            (None, true) => ", tileable",
            (None, false) => "",
        },
        c.data.display(),
        data.dataset().len(),
        start_step
    )?;
    let bar = steps_bar(total, start_step);
    let outcome = training.run(&data, &stop, &mut |event| show(&bar, event))?;
    bar.finish_and_clear();
    report(&args.out, total, &outcome, out)?;
    if outcome.interrupted {
        return Err(interruption().into());
    }
    Ok(())
}

/// One event of the run on the progress bar.
fn show(bar: &ProgressBar, event: GanEvent<'_>) {
    match event {
        // On stderr whether or not it is a terminal (the bar's own lines are hidden when it
        // is not), and in log.csv's `skipped` column.
        GanEvent::Skipped { step, reason } => {
            bar.suspend(|| eprintln!("warning: step {step}: skipped the update: {reason}"))
        }
        GanEvent::CheckpointHeld { step, reason } => bar.suspend(|| {
            eprintln!(
                "warning: no checkpoint after step {step}: {reason}; the previous one is kept"
            )
        }),
        GanEvent::SnapshotHeld { step, reason } => {
            bar.suspend(|| eprintln!("warning: no snapshot after step {step}: {reason}"))
        }
        GanEvent::SwdStarted { count } => {
            bar.set_message(format!("measuring SWD on {count} images"))
        }
        GanEvent::SwdProgress => bar.tick(),
        GanEvent::Swd { step, report } => bar.println(format!(
            "step {step}: SWD×10³ {:.2} (per level {:?})",
            report.mean, report.per_level
        )),
        GanEvent::Step {
            stats,
            seconds,
            done,
            kimg,
        } => {
            bar.set_position(done);
            bar.set_message(format!(
                "kimg {kimg:.3} | D {:.3} G {:.3} | gap {:+.3} | {seconds:.2} s/step",
                stats.loss_d,
                stats.loss_g,
                stats.real_logit - stats.fake_logit
            ));
        }
    }
}

/// The lines after a run: how it ended and where its outputs are.
fn report(run: &Path, total: u64, o: &GanOutcome, out: &mut dyn Write) -> anyhow::Result<()> {
    if o.interrupted {
        writeln!(
            out,
            "interrupted at step {} of {total}: state saved in {}; continue with\n  photomat train-gan --out {} --resume --steps {total}",
            o.steps_done,
            run.display(),
            run.display()
        )?;
    } else {
        let timing = if o.steps_run > 0 {
            let (n, p) = (o.steps_run as f64, o.phases);
            format!(
                ", {:.2} s/step (G {:.2}, D {:.2}, crops {:.2}, R1 {:.2}, EMA {:.2})",
                o.seconds / n,
                p.g / n,
                p.d / n,
                p.data / n,
                p.r1 / n,
                p.ema / n
            )
        } else {
            String::new()
        };
        writeln!(
            out,
            "trained {} steps ({} in total, {:.3} kimg){timing}",
            o.steps_run, o.steps_done, o.kimg
        )?;
    }
    writeln!(
        out,
        "  {}/gan.json, gan.safetensors  G_ema + M (photomat relight --gan {})",
        run.display(),
        run.display()
    )?;
    writeln!(out, "  {}/log.csv  losses per step", run.display())?;
    writeln!(out, "  {}  latest samples", o.samples.display())?;
    Ok(())
}
