//! `photomat eval-gan` as a library driver: a GAN model measured against a prepared data set
//! (docs/neural-models.md, "GAN training"): the sliced Wasserstein distance of its relit
//! samples to real crops ([`photomat_generator::swd::model_swd`]); for a spatial model whether
//! M follows the light ([`crate::light_following`]) and shows relief
//! ([`crate::relief_signature`]); on request what the run's discriminator looks at
//! ([`crate::discriminator_probe`]). [`evaluate_gan`] runs what the settings ask for and
//! returns a [`GanEvaluation`], whose `Display` is the command's table and whose fields are its
//! JSON.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use candle_core::Device;
use photomat_generator::GanModel;
use photomat_generator::swd::{EvalPhase, FakeWindows, SwdConfig, SwdReport, model_swd};
use photomat_generator::train::config::DEFAULT_HIGHLIGHT_PROB;
use serde_json::json;

use crate::discriminator_probe::{BLUR_RADII, DiscriminatorProbe, probe_discriminator};
use crate::highlight::DetectorKind;
use crate::light_following::{LightFollowing, light_following};
use crate::patch::PatchOptions;
use crate::relief_signature::{ReliefSignature, model_relief_signature};
use crate::source::DatasetSource;

/// What to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct GanEvaluationSettings {
    /// The GAN model folder.
    pub gan: PathBuf,
    /// The prepared data set whose crops are the reference.
    pub data: PathBuf,
    /// Relit samples and real crops compared (each).
    pub count: usize,
    /// Seed of the samples, lights, crops and directions.
    pub seed: u64,
    /// Detector of the light-following check (default: the data set's).
    pub detector: Option<DetectorKind>,
    /// Side of the spatial model's materials the fakes are windows of.
    pub sample_size: Option<usize>,
    /// For a fixed-size model: compare P×P windows of materials stretched to the photos' scale.
    pub stretched_to_patches: Option<usize>,
    /// Also probe the run's discriminator.
    pub discriminator: bool,
}

/// What [`evaluate_gan`] measured.
#[derive(Debug, Clone)]
pub struct GanEvaluation {
    pub gan: String,
    pub data: String,
    pub resolution: usize,
    /// Side of the compared images.
    pub window: usize,
    pub sample_size: usize,
    pub stretched_to_patches: Option<usize>,
    pub count: usize,
    pub seed: u64,
    pub swd: SwdReport,
    pub following: Option<LightFollowing>,
    pub relief: Option<ReliefSignature>,
    pub probe: Option<DiscriminatorProbe>,
    pub seconds: f64,
}

/// What [`evaluate_gan`] reports while it works: the SWD's fakes or reals, `done` of `count`.
pub type Progress<'a> = &'a mut dyn FnMut(EvalPhase, usize);

/// The data source and the fakes' windows of `settings` for `model`.
fn reference(
    settings: &GanEvaluationSettings,
    model: &GanModel,
) -> anyhow::Result<(DatasetSource, FakeWindows, usize)> {
    let resolution = model.config().resolution;
    let (data, windows, window) = match (settings.stretched_to_patches, settings.sample_size) {
        (Some(_), _) if model.config().spatial.is_some() => anyhow::bail!(
            "--stretched-to-patches is for fixed-size models; '{}' is spatial (its samples \
             are already at the photos' scale)",
            settings.gan.display()
        ),
        (Some(p), _) => {
            let patches = PatchOptions {
                size: p,
                highlight_prob: DEFAULT_HIGHLIGHT_PROB,
            };
            let data = DatasetSource::open_patches(&settings.data, patches);
            (data, FakeWindows::Stretched, p)
        }
        (None, Some(n)) => {
            let data = DatasetSource::for_model(&settings.data, model.config());
            (data, FakeWindows::OfLargerSamples { side: n }, resolution)
        }
        (None, None) => {
            let data = DatasetSource::for_model(&settings.data, model.config());
            (data, FakeWindows::Native, resolution)
        }
    };
    let data = data.with_context(|| {
        format!(
            "cannot compare the {resolution}×{resolution} model in '{}' with the data set '{}'",
            settings.gan.display(),
            settings.data.display()
        )
    })?;
    Ok((data, windows, window))
}

/// Measures the model of `settings` (module docs).
pub fn evaluate_gan(
    settings: &GanEvaluationSettings,
    progress: Progress,
) -> anyhow::Result<GanEvaluation> {
    let s = settings;
    let model = GanModel::load(&s.gan, &Device::Cpu)
        .with_context(|| format!("cannot load the GAN model in '{}'", s.gan.display()))?;
    let (data, windows, window) = reference(s, &model)?;
    let start = Instant::now();
    let swd = model_swd(
        &model,
        &data,
        s.count,
        s.seed,
        windows,
        &SwdConfig::default(),
        progress,
    )
    .with_context(|| {
        format!(
            "cannot measure the SWD of '{}' against '{}'",
            s.gan.display(),
            s.data.display()
        )
    })?;
    let following = match model.config().spatial {
        Some(_) if s.sample_size.is_none() => {
            let detector = s
                .detector
                .unwrap_or(data.dataset().index().detector)
                .build();
            Some(
                light_following(&model, data.dataset(), detector.as_ref(), s.count, s.seed)
                    .context("cannot measure whether the relighting follows the light")?,
            )
        }
        _ => None,
    };
    let relief = following
        .as_ref()
        .map(|f| model_relief_signature(&model, f.photo_size, s.count, s.seed))
        .transpose()
        .context("cannot measure whether the relighting shows relief")?;
    let probe = s
        .discriminator
        .then(|| probe_discriminator(&s.gan, Some(&s.data), s.count, s.seed))
        .transpose()
        .with_context(|| {
            format!(
                "cannot probe the discriminator of the run '{}' (--discriminator needs a \
                 `photomat train-gan` run folder)",
                s.gan.display()
            )
        })?;
    let resolution = model.config().resolution;
    Ok(GanEvaluation {
        gan: s.gan.display().to_string(),
        data: s.data.display().to_string(),
        resolution,
        window,
        sample_size: s.sample_size.unwrap_or(resolution),
        stretched_to_patches: s.stretched_to_patches,
        count: s.count,
        seed: s.seed,
        swd,
        following,
        relief,
        probe,
        seconds: start.elapsed().as_secs_f64(),
    })
}

impl GanEvaluation {
    /// The measurement as `photomat eval-gan --json` prints it.
    pub fn to_json(&self) -> serde_json::Value {
        let levels: Vec<_> = self
            .swd
            .per_level
            .iter()
            .map(|&(side, swd)| json!({ "side": side, "swd_x1e3": swd }))
            .collect();
        json!({
            "gan": self.gan,
            "data": self.data,
            "resolution": self.resolution,
            "window": self.window,
            "sample_size": self.sample_size,
            "stretched_to_patches": self.stretched_to_patches,
            "count": self.count,
            "seed": self.seed,
            "levels": levels,
            "mean_x1e3": self.swd.mean,
            "light_following_pct_of_width": self.following,
            "relief_signature": self.relief,
            "discriminator": self.probe,
            "seconds": self.seconds,
        })
    }

    fn write_swd(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (count, window) = (self.count, self.window);
        let cut = match (
            self.sample_size != self.resolution,
            self.stretched_to_patches,
        ) {
            (true, _) => format!(", windows of {0}×{0} samples", self.sample_size),
            (_, Some(_)) => ", centre windows of materials stretched to the photos' scale".into(),
            _ => String::new(),
        };
        writeln!(
            f,
            "SWD ×10³ between {count} relit samples of '{}' and {count} crops of '{}' \
             ({window}×{window}{cut}, seed {}; lower is closer):",
            self.gan, self.data, self.seed
        )?;
        writeln!(f, "{:>9}  {:>10}", "level", "SWD×1e3")?;
        for &(s, swd) in &self.swd.per_level {
            writeln!(f, "{:>9}  {swd:>10.3}", format!("{s}×{s}"))?;
        }
        writeln!(f, "{:>9}  {:>10.3}", "mean", self.swd.mean)
    }

    fn write_following(
        &self,
        f: &mut std::fmt::Formatter<'_>,
        l: &LightFollowing,
    ) -> std::fmt::Result {
        writeln!(
            f,
            "light following: detected vs conditioned highlight, % of the {s}-texel width \
             ({n} images each; near the reals' figure: M follows the light):",
            s = l.size,
            n = l.count
        )?;
        writeln!(
            f,
            "{:>9}  {:>6}  {:>6}  {:>6}  {:>6}",
            "", "mean", "median", "p90", "max"
        )?;
        let photo = format!("M {}²", l.photo_size);
        for (name, d) in [
            ("M", &l.fakes),
            ("reals", &l.reals),
            (photo.as_str(), &l.photo_fakes),
            ("centre", &l.photo_centre_guess),
        ] {
            writeln!(
                f,
                "{name:>9}  {:>6.1}  {:>6.1}  {:>6.1}  {:>6.1}",
                d.mean, d.median, d.p90, d.max
            )?;
        }
        writeln!(
            f,
            "(M {s}²: whole-photo samples, highlights uniform over the central half, where the \
             detector's own error is below 1 %; centre: always guessing the centre there)",
            s = l.photo_size
        )
    }

    fn write_relief(
        &self,
        f: &mut std::fmt::Formatter<'_>,
        r: &ReliefSignature,
    ) -> std::fmt::Result {
        writeln!(
            f,
            "relief: R² of the detail of log(image under +y light / under −y light) with the \
             texture's derivative along y {:.3} (relief), along x {:.3} (control), the texture \
             itself {:.3} ({} materials at the photos' scale)",
            r.along, r.across, r.texture, self.count
        )?;
        if let Some(degrees) = r.m_relief_rms_degrees {
            writeln!(f, "M's own relief normals: {degrees:.2}° rms from +z")?;
        }
        Ok(())
    }

    fn write_probe(f: &mut std::fmt::Formatter<'_>, p: &DiscriminatorProbe) -> std::fmt::Result {
        writeln!(
            f,
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
            writeln!(f, "{name:>22}  {value:>+8.3}")?;
        }
        writeln!(
            f,
            "texture gap (reals − blurred reals) {:+.3}, light gap (reals − other lights) {:+.3}: \
             a gap near 0 is something D does not look at, and G will not learn",
            p.texture_gap(),
            p.light_gap()
        )
    }
}

impl std::fmt::Display for GanEvaluation {
    /// The table `photomat eval-gan` prints.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.write_swd(f)?;
        if let Some(l) = &self.following {
            self.write_following(f, l)?;
        }
        if let Some(r) = &self.relief {
            self.write_relief(f, r)?;
        }
        if let Some(p) = &self.probe {
            Self::write_probe(f, p)?;
        }
        write!(f, "measured in {:.1} s", self.seconds)
    }
}
