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
use std::time::Instant;

use anyhow::Context;
use candle_core::Device;
use photomat_data::discriminator_probe::{BLUR_RADII, DiscriminatorProbe, probe_discriminator};
use photomat_data::highlight::DetectorKind;
use photomat_data::light_following::{LightFollowing, light_following};
use photomat_data::patch::PatchOptions;
use photomat_data::relief_signature::{ReliefSignature, model_relief_signature};
use photomat_data::source::DatasetSource;
use photomat_generator::GanModel;
use photomat_generator::swd::{EvalPhase, FakeWindows, SwdConfig, SwdReport, model_swd};
use photomat_generator::train::config::DEFAULT_HIGHLIGHT_PROB;
use serde_json::json;

use crate::common::{parse_detector, progress_bar};

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

    /// Print the result as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args, out: &mut dyn Write) -> anyhow::Result<()> {
    let device = Device::Cpu;
    let model = GanModel::load(&args.gan, &device)
        .with_context(|| format!("cannot load the GAN model in '{}'", args.gan.display()))?;
    let resolution = model.config().resolution;
    let (data, windows, window) = match (args.stretched_to_patches, args.sample_size) {
        (Some(_), _) if model.config().spatial.is_some() => anyhow::bail!(
            "--stretched-to-patches is for fixed-size models; '{}' is spatial (its samples \
             are already at the photos' scale)",
            args.gan.display()
        ),
        (Some(p), _) => {
            let patches = PatchOptions {
                size: p as usize,
                highlight_prob: DEFAULT_HIGHLIGHT_PROB,
            };
            let data = DatasetSource::open_patches(&args.data, patches);
            (data, FakeWindows::Stretched, p as usize)
        }
        (None, Some(n)) => {
            let data = DatasetSource::for_model(&args.data, model.config());
            let windows = FakeWindows::OfLargerSamples { side: n as usize };
            (data, windows, resolution)
        }
        (None, None) => {
            let data = DatasetSource::for_model(&args.data, model.config());
            (data, FakeWindows::Native, resolution)
        }
    };
    let data = data.with_context(|| {
        format!(
            "cannot compare the {resolution}×{resolution} model in '{}' with the data set '{}'",
            args.gan.display(),
            args.data.display()
        )
    })?;
    let count = args.count as usize;

    let bar = progress_bar(
        2 * args.count,
        "{elapsed_precise} [{bar:40}] {pos}/{len} images: {msg} ({eta} left)",
    );
    let start = Instant::now();
    let report = model_swd(
        &model,
        &data,
        count,
        args.seed,
        windows,
        &SwdConfig::default(),
        &mut |phase, done| match phase {
            EvalPhase::Fakes => {
                bar.set_message("relighting samples");
                bar.set_position(done as u64);
            }
            EvalPhase::Reals => {
                bar.set_message("cropping the data set");
                bar.set_position((count + done) as u64);
            }
        },
    );
    bar.finish_and_clear();
    let report = report.with_context(|| {
        format!(
            "cannot measure the SWD of '{}' against '{}'",
            args.gan.display(),
            args.data.display()
        )
    })?;
    let following = match model.config().spatial {
        None => None,
        Some(_) if args.sample_size.is_some() => None,
        Some(_) => {
            let detector = args
                .detector
                .unwrap_or(data.dataset().index().detector)
                .build();
            Some(
                light_following(&model, data.dataset(), detector.as_ref(), count, args.seed)
                    .context("cannot measure whether the relighting follows the light")?,
            )
        }
    };
    let relief = following
        .as_ref()
        .map(|f| model_relief_signature(&model, f.photo_size, count, args.seed))
        .transpose()
        .context("cannot measure whether the relighting shows relief")?;
    let probe = args
        .discriminator
        .then(|| probe_discriminator(&args.gan, Some(&args.data), count, args.seed))
        .transpose()
        .with_context(|| {
            format!(
                "cannot probe the discriminator of the run '{}' (--discriminator needs a \
                 `photomat train-gan` run folder)",
                args.gan.display()
            )
        })?;
    let seconds = start.elapsed().as_secs_f64();
    print_report(
        args,
        (resolution, window),
        &report,
        (following.as_ref(), relief.as_ref()),
        probe.as_ref(),
        seconds,
        out,
    )
}

/// The measurement as JSON (`--json`) or as a table; `resolution` is the model's side,
/// `window` the side of the compared images; the light-following and relief checks are those
/// of a spatial model.
fn print_report(
    args: &Args,
    (resolution, window): (usize, usize),
    report: &SwdReport,
    (following, relief): (Option<&LightFollowing>, Option<&ReliefSignature>),
    probe: Option<&DiscriminatorProbe>,
    seconds: f64,
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    let count = args.count as usize;
    if args.json {
        let levels: Vec<_> = report
            .per_level
            .iter()
            .map(|&(side, swd)| json!({ "side": side, "swd_x1e3": swd }))
            .collect();
        let value = json!({
            "gan": args.gan.display().to_string(),
            "data": args.data.display().to_string(),
            "resolution": resolution,
            "window": window,
            "sample_size": args.sample_size.map_or(resolution, |n| n as usize),
            "stretched_to_patches": args.stretched_to_patches,
            "count": count,
            "seed": args.seed,
            "levels": levels,
            "mean_x1e3": report.mean,
            "light_following_pct_of_width": following,
            "relief_signature": relief,
            "discriminator": probe,
            "seconds": seconds,
        });
        writeln!(out, "{}", serde_json::to_string_pretty(&value)?)?;
        return Ok(());
    }
    let cut = match (args.sample_size, args.stretched_to_patches) {
        (Some(n), _) => format!(", windows of {n}×{n} samples"),
        (_, Some(_)) => ", centre windows of materials stretched to the photos' scale".into(),
        _ => String::new(),
    };
    writeln!(
        out,
        "SWD ×10³ between {count} relit samples of '{}' and {count} crops of '{}' \
         ({window}×{window}{cut}, seed {}; lower is closer):",
        args.gan.display(),
        args.data.display(),
        args.seed
    )?;
    writeln!(out, "{:>9}  {:>10}", "level", "SWD×1e3")?;
    for &(s, swd) in &report.per_level {
        writeln!(out, "{:>9}  {swd:>10.3}", format!("{s}×{s}"))?;
    }
    writeln!(out, "{:>9}  {:>10.3}", "mean", report.mean)?;
    if let Some(f) = following {
        writeln!(
            out,
            "light following: detected vs conditioned highlight, % of the {s}-texel width \
             ({n} images each; near the reals' figure: M follows the light):",
            s = f.size,
            n = f.count
        )?;
        writeln!(
            out,
            "{:>9}  {:>6}  {:>6}  {:>6}  {:>6}",
            "", "mean", "median", "p90", "max"
        )?;
        let photo = format!("M {}²", f.photo_size);
        for (name, d) in [
            ("M", &f.fakes),
            ("reals", &f.reals),
            (photo.as_str(), &f.photo_fakes),
            ("centre", &f.photo_centre_guess),
        ] {
            writeln!(
                out,
                "{name:>9}  {:>6.1}  {:>6.1}  {:>6.1}  {:>6.1}",
                d.mean, d.median, d.p90, d.max
            )?;
        }
        writeln!(
            out,
            "(M {s}²: whole-photo samples, highlights uniform over the central half, where the \
             detector's own error is below 1 %; centre: always guessing the centre there)",
            s = f.photo_size
        )?;
    }
    if let Some(r) = relief {
        writeln!(
            out,
            "relief: R² of the detail of log(image under +y light / under −y light) with the \
             texture's derivative along y {:.3} (relief), along x {:.3} (control), the texture \
             itself {:.3} ({count} materials at the photos' scale)",
            r.along, r.across, r.texture
        )?;
        if let Some(degrees) = r.m_relief_rms_degrees {
            writeln!(out, "M's own relief normals: {degrees:.2}° rms from +z")?;
        }
    }
    if let Some(p) = probe {
        writeln!(
            out,
            "what D looks at (step {}, mean logit over {} images each; higher: more real):",
            p.step, p.count
        )?;
        let [r1, r3] = BLUR_RADII.map(|r| 2 * r + 1);
        for (name, value) in [
            ("reals".to_string(), p.reals),
            ("reals, other lights".to_string(), p.reals_other_lights),
            (format!("reals blurred {r1}×{r1}"), p.reals_blurred[0]),
            (format!("reals blurred {r3}×{r3}"), p.reals_blurred[1]),
            ("fakes".to_string(), p.fakes),
            ("fakes, other lights".to_string(), p.fakes_other_lights),
        ] {
            writeln!(out, "{name:>22}  {value:>+8.3}")?;
        }
        writeln!(
            out,
            "texture gap (reals − blurred reals) {:+.3}, light gap (reals − other lights) {:+.3}: \
             a gap near 0 is something D does not look at, and G will not learn",
            p.texture_gap(),
            p.light_gap()
        )?;
    }
    writeln!(out, "measured in {seconds:.1} s")?;
    Ok(())
}
