//! `photomat eval-gan --gan RUN --data DATASET [--count 256] [--seed S] [--discriminator]
//! [--json]`: the GAN
//! quality metric (`docs/neural-models.md`, "GAN training") — the sliced Wasserstein distance on
//! Laplacian-pyramid patches (ProGAN, Karras et al. 2018, appendix D; `photomat_generator::swd`)
//! between `count` relit samples of the model in RUN and `count` real crops of DATASET.
//!
//! The fakes are G's materials for seeds drawn from S, relit by M under lights drawn from the
//! data set's highlight distribution (per-texel ω of the collocated flash); the reals are
//! crops drawn as the trainer draws them. Both come from S: one model, data set, count and
//! seed give one value, the same as `train-gan` logs for that model
//! ([`photomat_generator::swd::model_swd`]). Values are ×10³ like ProGAN's `SWDx1e3_<side>`,
//! one per pyramid level (the model's side down to 16) and their mean; lower is closer.
//!
//! For a spatial model the reals are native-scale patches (as in its training), and the
//! command also reports whether M follows the light ([`photomat_data::light_following`]):
//! the highlight detector's distance to the conditioned highlight on M's images and on real
//! patches, in % of the width; and whether M's relighting shows relief
//! ([`photomat_data::relief_signature`]): of the detail in the log-ratio of each material
//! under two opposite lights, the share (window R²) that follows the texture's derivative
//! along the lights' axis (relief), across it (the control) and the texture itself.
//!
//! With `--discriminator` (RUN must be a `photomat train-gan` run folder, which holds D) it also
//! reports what D looks at ([`photomat_data::discriminator_probe`]): D's mean logit on reals,
//! reals under other lights, blurred reals and fakes.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use photomat_core::map_distribution::{MapDistributionTable, StatisticDistance, compare};
use photomat_data::gan_evaluation::{GanEvaluationSettings, evaluate_gan};
use photomat_data::highlight::DetectorKind;
use photomat_estimator::map_distribution::sampled_stats;
use photomat_generator::swd::EvalPhase;
use photomat_library::split::Split;
use photomat_library::stats::split_stats;

use crate::common::{parse_detector, progress_bar};

/// Most materials the map comparison samples: 64 give each statistic's median to a few %, and
/// sampling more only costs time.
const MAX_MAP_MATERIALS: usize = 64;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// GAN model folder (gan.json + gan.safetensors), e.g. a `photomat train-gan` run.
    #[arg(long, value_name = "RUN")]
    pub gan: PathBuf,

    /// Prepared data set (`photomat prepare` output) whose crops are the reference.
    #[arg(long, value_name = "DATASET")]
    pub data: PathBuf,

    /// Relit samples and real crops compared (each). ProGAN used 16 384; fewer give a
    /// noisier value with a higher floor (compare values measured with the same count). Both
    /// sets are held in memory: 2 × N × 3 × R² × 4 bytes (N = 256 at 256²: 0.4 GB).
    #[arg(long, value_name = "N", default_value_t = 256,
          value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub count: u64,

    /// Seed of the samples, their lights, the crops, the patches and the directions.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,

    /// Highlight detector of the light-following check (spatial models): `robust` or `paper`
    /// [default: the data set's].
    #[arg(long, value_name = "NAME", value_parser = parse_detector)]
    pub detector: Option<DetectorKind>,

    /// Side of the materials the fakes are cut from (a spatial model): each fake is an R×R
    /// window of its own material of N×N texels, which checks that the model's local
    /// statistics do not change with the sample size [default: R, the training windows].
    /// With it the command measures the SWD only (no light-following check).
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub sample_size: Option<u32>,

    /// For a fixed-size model: compare at the photos' native scale, as a spatial model is.
    /// Each fake is the model's unit-square material stretched to the data set's texel size
    /// (bilinear on the neural material F) and cut to its centre P×P window, against P×P
    /// native-scale patches of the data set: the baseline an any-size generator's SWD is
    /// compared with.
    #[arg(long, value_name = "P", conflicts_with = "sample_size",
          value_parser = clap::value_parser!(u32).range(16..=4096))]
    pub stretched_to_patches: Option<u32>,

    /// Also report what the run's discriminator looks at: its mean logit on reals, on reals
    /// under other samples' lights, on blurred reals and on fakes (RUN must be a `photomat
    /// train-gan` run folder: train.json + train_state.safetensors). A D that scores blurred
    /// reals like reals gives G no reason to make texture.
    #[arg(long)]
    pub discriminator: bool,

    /// A material library: also compare the model folder's estimator's maps of sampled
    /// materials (up to 64 of --count) with the true maps of the library's split: the
    /// diffuse, specular and roughness levels and spreads and the normals' spread and tilt,
    /// each a 1-D Wasserstein distance (flat normals where real materials have relief fail it).
    #[arg(long, value_name = "LIB")]
    pub library: Option<PathBuf>,

    /// The library's split the maps are compared with.
    #[arg(
        long,
        value_name = "SPLIT",
        default_value = "validation",
        requires = "library"
    )]
    pub library_split: Split,

    /// Side of the compared materials (sampled, and the library's box-filtered to it); a
    /// multiple of the estimator's stride.
    #[arg(long, value_name = "N", default_value_t = 256, requires = "library",
          value_parser = clap::value_parser!(u32).range(32..=2048))]
    pub map_size: u32,

    /// Print the result as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let settings = GanEvaluationSettings {
        gan: args.gan.clone(),
        data: args.data.clone(),
        count: args.count as usize,
        seed: args.seed,
        detector: args.detector,
        sample_size: args.sample_size.map(|n| n as usize),
        stretched_to_patches: args.stretched_to_patches.map(|p| p as usize),
        discriminator: args.discriminator,
    };
    let count = args.count;
    let bar = progress_bar(
        2 * count,
        "{elapsed_precise} [{bar:40}] {pos}/{len} images: {msg} ({eta} left)",
    );
    let evaluation = evaluate_gan(&settings, &mut |phase, done| match phase {
        EvalPhase::Fakes => {
            bar.set_message("relighting samples");
            bar.set_position(done as u64);
        }
        EvalPhase::Reals => {
            bar.set_message("cropping the data set");
            bar.set_position(count + done as u64);
        }
    });
    bar.finish_and_clear();
    let evaluation = evaluation?;
    let maps = match &args.library {
        Some(library) => Some(map_distribution(args, library)?),
        None => None,
    };
    if args.json {
        let mut value = evaluation.to_json();
        value["maps"] = serde_json::to_value(&maps)?;
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
    } else {
        writeln!(out, "{evaluation}")?;
        if let Some(rows) = &maps {
            writeln!(out, "{}", MapDistributionTable(rows))?;
        }
    }
    Ok(())
}

/// E's maps of sampled materials against the library split's true maps.
fn map_distribution(
    args: &Args,
    library: &std::path::Path,
) -> anyhow::Result<Vec<StatisticDistance>> {
    let count = (args.count as usize).min(MAX_MAP_MATERIALS);
    let side = args.map_size as usize;
    let sampled = sampled_stats(&args.gan, count, side, args.seed)?;
    let reference = split_stats(library, args.library_split, count, side)
        .with_context(|| format!("cannot read the library '{}'", library.display()))?;
    Ok(compare(&sampled, &reference))
}
