//! `photomat trade --gan MODEL --brdfs "lambert,ggx,height(ggx),coated" --out T [--steps N]
//! [--finetune-steps M] [--width W] [--seed S] [--materials K] [--size N] [--cache DIR]`: the
//! speed/accuracy trade of BRDF models on one GAN. The study is the library's
//! [`photomat_estimator::trade::TradeStudy`] (what it trains, measures and writes is described
//! there and in `docs/trade.md`); this command parses the flags and shows progress.

use std::io::Write;
use std::path::PathBuf;

use photomat_core::plugin_spec::split_list;
use photomat_estimator::trade::{
    self, DEFAULT_FINETUNE_STEPS, DEFAULT_MATERIALS, DEFAULT_STEPS, DEFAULT_WIDTH, TradeEvent,
    TradeSettings, TradeStudy,
};

use crate::common::{interruption, progress_bar, stop_flag};

#[derive(Debug, clap::Args)]
#[command(after_help = crate::common::STOP_HELP)]
pub struct Args {
    /// GAN model folder (gan.json + gan.safetensors), e.g. models/demo.
    #[arg(long, value_name = "MODEL")]
    pub gan: PathBuf,

    /// BRDF models to compare, comma-separated (commas inside parentheses belong to a model):
    /// e.g. "lambert,ggx(shadowing=implicit),ggx,height(ggx),coated".
    #[arg(long, value_name = "SPECS")]
    pub brdfs: String,

    /// Output folder (created): trade.md, trade.json, trade.png, maps/<model>/.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Stage-1 steps of every estimator (the same budget for all).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_STEPS,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: u64,

    /// Fine-tune steps of every estimator.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_FINETUNE_STEPS)]
    pub finetune_steps: u64,

    /// Width multiplier of every estimator's channels.
    #[arg(long, value_name = "W", default_value_t = DEFAULT_WIDTH)]
    pub width: f64,

    /// Seed of every estimator's training and of the evaluation materials and lights.
    #[arg(long, value_name = "S", default_value_t = 1)]
    pub seed: u64,

    /// Evaluation materials.
    #[arg(long, value_name = "K", default_value_t = DEFAULT_MATERIALS as u32,
          value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub materials: u32,

    /// Evaluation side in texels [default: 128 for an any-size (spatial) GAN, the GAN's
    /// resolution otherwise].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(16..=2048))]
    pub size: Option<u32>,

    /// Folder of the trained estimators, reused by later runs with the same GAN and settings
    /// [default: OUT/estimators, carried over when OUT is overwritten].
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,

    /// Replace an earlier study in OUT, whole (its cached estimators are kept and reused).
    #[arg(long)]
    pub overwrite: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let brdfs = split_list(&args.brdfs)?;
    let settings = TradeSettings {
        steps: args.steps,
        finetune_steps: args.finetune_steps,
        width: args.width,
        seed: args.seed,
        materials: args.materials as usize,
        size: args.size.map(|s| s as usize),
        ..TradeSettings::new(
            args.gan.clone(),
            brdfs,
            args.cache
                .clone()
                .unwrap_or_else(|| args.out.join("estimators")),
        )
    };
    let models = settings.brdfs.len() as u64;
    let stop = stop_flag()?;
    let bar = progress_bar(
        models,
        "{elapsed_precise} [{bar:30}] {pos}/{len} models {msg}",
    );
    let mut current = String::new();
    let result = TradeStudy::new(settings).run(&args.out, args.overwrite, &stop, &mut |event| {
        match event {
            TradeEvent::Model {
                index,
                spec,
                reused,
                ..
            } => {
                bar.set_position(index as u64);
                current = spec;
                bar.set_message(format!(
                    "{current}: {}",
                    if reused {
                        "cached estimator"
                    } else {
                        "training E"
                    }
                ));
            }
            TradeEvent::Step { step, total, l1 } => {
                bar.set_message(format!("{current}: E step {step}/{total}, L1 {l1:.4}"));
            }
            TradeEvent::Note(line) => bar.suspend(|| eprintln!("{line}")),
        }
        Ok(())
    });
    bar.finish_and_clear();
    let report = match result {
        Ok(report) => report,
        Err(e) if stop.load(std::sync::atomic::Ordering::SeqCst) => {
            eprintln!(
                "interrupted ({e:#}): {} is as it was; the estimators trained so far are kept \
                 and the same command continues them",
                args.out.display()
            );
            return Err(interruption().into());
        }
        Err(e) => return Err(e),
    };
    for entry in &report.entries {
        writeln!(
            out,
            "{:<32} L1 {:.4} (held-out lights {:.4})  SSIM {:.3}  render {:>7.1} ms/Mtexel{}",
            entry.spec,
            entry.accuracy.l1_mean,
            entry.accuracy.l1_held_out,
            entry.accuracy.ssim_mean,
            entry.cost.render.eval_ms_per_megatexel,
            if entry.pareto { "  ★ Pareto" } else { "" }
        )?;
    }
    writeln!(
        out,
        "wrote {}, {} and {}",
        args.out.join(trade::TABLE_FILE).display(),
        args.out.join(trade::JSON_FILE).display(),
        args.out.join(trade::PLOT_FILE).display()
    )?;
    Ok(())
}
