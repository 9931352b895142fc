//! `photomat train-prior --library LIB --brdf SPEC --out RUN --steps N [--size 256] [--batch 4]
//! [--lr 2e-4] [--width W] [--seed S] [--exclude-licence L] [--checkpoint-every K]
//! [--snapshot-every K] [--validation-count N] [--resume]`: trains the relief prior, a network
//! from one flash photo to SPEC's maps, on photos of the library's train split rendered on the
//! fly, scoring snapshots on its validation split (docs/neural-models.md, "Relief prior"). The
//! run is the library's `photomat_prior::train::PriorTraining` driver; this command parses the
//! flags, installs the signal handler and shows progress.
//!
//! RUN holds `train.json` + `train_state.safetensors` (every `--checkpoint-every` steps, at
//! the end and on SIGINT/SIGTERM/SIGHUP after the current step, exiting 128 + the signal),
//! the prior (`prior.json` + `prior.safetensors`: RUN is a prior folder), `log.csv`,
//! `validation.csv` and `snapshots/step-NNNNNN/` (scored prior folders). `--resume` continues
//! bit-identically; flags that contradict `train.json` are errors naming the field.

use std::io::Write;
use std::path::PathBuf;

use candle_core::Device;
use photomat_prior::train::{PriorEvent, PriorSettings, PriorTraining};

use crate::common::{interruption, steps_bar, stop_flag};

#[derive(Debug, clap::Args)]
#[command(after_help = crate::common::STOP_HELP)]
pub struct Args {
    /// Run folder: the prior, checkpoints, logs, snapshots.
    #[arg(long, value_name = "RUN")]
    pub out: PathBuf,

    /// Total training steps (a resumed run continues up to this count).
    #[arg(long, value_name = "N")]
    pub steps: u64,

    /// Continue the run in RUN from its last checkpoint.
    #[arg(long)]
    pub resume: bool,

    #[command(flatten)]
    pub settings: PriorSettings,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let mut training = PriorTraining::open(&args.out, &args.settings, args.resume, &Device::Cpu)?;
    for note in training.notes() {
        eprintln!("{note}");
    }
    let start = training.trainer().steps_done();
    if start >= args.steps {
        eprintln!(
            "note: {} is at step {start} already, not before --steps {}: nothing to train (give \
             a larger --steps to continue)",
            args.out.display(),
            args.steps
        );
    }
    let c = training.trainer().config();
    writeln!(
        out,
        "training the prior for {} ({} parameters) on {}² photos of {} (batch {}, seed {}): \
         steps {start} → {}",
        c.brdf,
        c.architecture.num_parameters(),
        c.size,
        c.library.display(),
        c.batch,
        c.seed,
        args.steps
    )?;
    let stop = stop_flag()?;
    let bar = steps_bar(args.steps, start);
    let outcome = training.run(args.steps, &stop, &mut |event| match event {
        PriorEvent::Step { report, seconds } => {
            bar.set_position(report.step);
            let t = report.terms;
            bar.set_message(format!(
                "loss {:.4} (maps {:.4}, normals {:.4}, render {:.4}) | {seconds:.2} s/step",
                t.total, t.maps, t.normal, t.render
            ));
        }
        PriorEvent::Validated { step, score } => bar.println(format!(
            "step {step}: validation normals {:.2}° (flat {:.2}°), diffuse RMSE {:.4}, roughness \
             RMSE {:.4}",
            score.normal_degrees,
            score.flat_normal_degrees,
            score.diffuse_rmse,
            score.roughness_rmse
        )),
    })?;
    bar.finish_and_clear();
    let run = args.out.display();
    if outcome.interrupted {
        writeln!(
            out,
            "interrupted at step {} of {}: state saved in {run}; continue with\n  photomat \
             train-prior --out {run} --resume --steps {}",
            outcome.steps_done, args.steps, args.steps
        )?;
        return Err(interruption().into());
    }
    writeln!(
        out,
        "trained {} steps ({} in total){}",
        outcome.steps_run,
        outcome.steps_done,
        if outcome.steps_run > 0 {
            format!(", {:.2} s/step", outcome.seconds / outcome.steps_run as f64)
        } else {
            String::new()
        }
    )?;
    writeln!(out, "  {run}/prior.json, prior.safetensors  the prior")?;
    writeln!(
        out,
        "  {run}/log.csv, validation.csv  losses per step, snapshot scores"
    )?;
    Ok(())
}
