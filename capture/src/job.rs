//! `photomat capture` as a library driver: a [`CaptureJob`] names the photo, the output
//! folder, the model (by name or `auto`) and where the fit starts; [`CaptureJob::run`] checks
//! everything it can before the work starts (the model, the output folder, the known maps, the
//! memory a fit of that size needs), runs the capture and writes its folder whole
//! ([`photomat_core::output_folder`]), and returns a [`CaptureReport`] for the caller to print
//! (docs/capture.md).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use candle_core::Device;
use photomat_core::map_files::load_maps;
use photomat_core::memory;
use photomat_core::output_folder::{OutputFolder, ResultKind, refuse_input_inside};
use photomat_core::{Brdf, MaterialMaps, lookup};
use photomat_estimator::model_choice::BrdfChoice;
use photomat_export::TextureSet;
use photomat_prior::{PriorModel, find_prior};

use crate::options::{CaptureOptions, Stopped};
use crate::output::{Exports, write_capture};
use crate::pipeline::{capture_auto, capture_with_prior};
use crate::prior::{GanPrior, PriorOptions};
use crate::relief_prior::capture_from_relief_prior;
use crate::result::Capture;

/// What a capture's output folder holds ([`write_capture`]).
pub const CAPTURE: ResultKind = ResultKind {
    what: "a capture",
    command: "photomat capture",
    entries: &[
        "material",
        "export",
        "sheet.png",
        "relit.png",
        "capture.json",
    ],
    kept: &[],
};

/// Peak memory of a fit from constant maps: about 2 kB per texel of the square on top of
/// 100 MB (measured 2026-12-08, `height(ggx)`: 75 MB at 128², 204 MB at 256², 575 MB at
/// 512²: 1.9 kB per texel).
const DIRECT_BYTES: (u64, u64) = (100 << 20, 2000);
/// Peak memory of a fit from the generator prior: the inversion of G at the photo's size,
/// about 8 kB per texel (measured with the bundled model: 0.50 GB at 256², 2.05 GB at 512²).
const GAN_PRIOR_BYTES: (u64, u64) = (50 << 20, 8000);

/// Peak memory of a fit from the relief prior: a fit from constant maps' and the prior's
/// forward pass, about 0.6 kB per texel more (estimated from its widest levels' activations).
const RELIEF_PRIOR_BYTES: (u64, u64) = (150 << 20, 2600);

/// Where a capture's fit starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartFrom {
    /// Constant maps, a uniform warm-up first (the default without a relief prior).
    Constant,
    /// The relief prior's prediction (the default when the model folder has a prior for the
    /// model).
    Prior,
    /// The generator prior: the model folder's GAN inverted to the photo, its material decoded
    /// by the folder's estimator for the model.
    Gan,
}

/// One capture to run (module docs).
#[derive(Debug, Clone)]
pub struct CaptureJob {
    /// The flash photo (JPEG or PNG).
    pub photo: PathBuf,
    /// The output folder.
    pub out: PathBuf,
    /// The model of the maps, or `auto` (which needs the generator prior).
    pub brdf: BrdfChoice,
    pub start: StartFrom,
    /// The model folder of the prior (required for [`StartFrom::Gan`] and `auto`; where
    /// [`StartFrom::Prior`] looks for `priors/<model>/`).
    pub model_dir: Option<PathBuf>,
    /// A relief prior's folder, instead of the model folder's (`photomat train-prior`'s run
    /// folder, or `priors/<name>/`).
    pub prior_dir: Option<PathBuf>,
    pub options: CaptureOptions,
    pub prior_options: PriorOptions,
    /// A material folder whose maps the fit holds at their values.
    pub known: Option<PathBuf>,
    pub exports: Exports,
    /// Replace an earlier capture in the output folder.
    pub overwrite: bool,
}

/// What a finished capture reports.
pub struct CaptureReport {
    /// The photo, as named to the job.
    pub photo: String,
    pub capture: Capture,
    /// The output folder.
    pub out: PathBuf,
    /// The renderer textures written into `export/`.
    pub textures: TextureSet,
    pub exports: Exports,
    /// Whether the folder held an earlier capture, now replaced.
    pub replaced: bool,
    /// Lines for the user (`note: …`) about what was resolved.
    pub notes: Vec<String>,
}

/// How a job ended.
pub enum JobOutcome {
    Done(Box<CaptureReport>),
    /// [`CaptureOptions::stop`] was set: the output folder is as it was.
    Stopped,
}

/// Estimated peak bytes of a capture of `size`² texels starting from `start` (module docs).
pub fn capture_memory_bytes(size: usize, start: StartFrom) -> u64 {
    let (base, per_texel) = match start {
        StartFrom::Constant => DIRECT_BYTES,
        StartFrom::Prior => RELIEF_PRIOR_BYTES,
        StartFrom::Gan => GAN_PRIOR_BYTES,
    };
    base + per_texel * (size * size) as u64
}

/// Refuses a capture of `size`² from `start` whose estimated peak exceeds the memory
/// available, naming the largest size that fits.
pub fn check_memory(size: usize, start: StartFrom) -> anyhow::Result<()> {
    let estimate = |s: usize| capture_memory_bytes(s, start);
    memory::check(estimate(size), &format!("--size {size}"), |available| {
        let sizes = (4..=11).map(|k| 1usize << k);
        match memory::largest_fitting(sizes, estimate, available) {
            Some((s, bytes)) => format!(
                "use --size {s} (about {}) or less",
                memory::format_bytes(bytes)
            ),
            None => "free some memory".to_string(),
        }
    })?;
    Ok(())
}

impl CaptureJob {
    /// Runs the job (module docs); `progress(step, loss)` counts the inversion's steps, then
    /// the refinement's.
    pub fn run(&self, progress: &mut dyn FnMut(usize, f64)) -> anyhow::Result<JobOutcome> {
        let start = if self.brdf.is_auto() {
            StartFrom::Gan
        } else {
            self.start
        };
        check_memory(self.options.size, start)?;
        if let Some(known) = &self.known {
            refuse_input_inside(known, &self.out, "--known")?;
        }
        refuse_input_inside(&self.photo, &self.out, "the photo")?;
        let folder = OutputFolder::claim(&self.out, CAPTURE, self.overwrite)?;
        let bytes = std::fs::read(&self.photo)
            .with_context(|| format!("cannot read '{}'", self.photo.display()))?;
        let name = self.photo.display().to_string();
        let mut notes = Vec::new();
        let named = match &self.brdf {
            BrdfChoice::Named(spec) => Some(lookup(spec)?),
            _ => None,
        };
        let mut options = self.options.clone();
        if let (Some(dir), Some(brdf)) = (&self.known, &named) {
            options.known_maps = Some(known_maps(dir, brdf, &mut notes)?);
        } else if self.known.is_some() {
            bail!("--known needs a named --brdf: `auto` chooses the model later");
        }
        let result = match (&self.brdf, start) {
            (BrdfChoice::Auto { tolerance }, _) => {
                let prior = GanPrior::open_all(&self.model()?, &Device::Cpu)?;
                capture_auto(
                    &bytes,
                    &name,
                    &options,
                    (&prior, &self.prior_options),
                    *tolerance,
                    progress,
                )
            }
            (_, StartFrom::Gan) => {
                let brdf = named.as_ref().context("a named model")?;
                let dir = self.model()?;
                let prior = GanPrior::open(&dir, brdf, &Device::Cpu)?;
                if prior.is_none() {
                    notes.push(format!(
                        "note: '{}' has no estimator for {}: fitting from constant maps (train \
                         one with `photomat train-estimator --gan {0} --brdf '{1}' --out \
                         {0}/estimators/NAME`)",
                        dir.display(),
                        brdf.name()
                    ));
                }
                let prior_arg = prior.as_ref().map(|p| (p, &self.prior_options));
                capture_with_prior(&bytes, &name, brdf, &options, prior_arg, progress)
            }
            (_, StartFrom::Prior) => {
                let brdf = named.as_ref().context("a named model")?;
                match self.relief_prior_dir(brdf)? {
                    Some(dir) => {
                        let prior = PriorModel::load(&dir, &Device::Cpu)?;
                        let shown = dir.display().to_string();
                        capture_from_relief_prior(&bytes, &name, &prior, &shown, &options, progress)
                    }
                    None => {
                        notes.push(format!(
                            "note: no relief prior for {} (train one with `photomat \
                             train-prior --library LIB --brdf '{0}'`): fitting from constant maps",
                            brdf.name()
                        ));
                        capture_with_prior(&bytes, &name, brdf, &options, None, progress)
                    }
                }
            }
            (_, StartFrom::Constant) => {
                let brdf = named.as_ref().context("a named model")?;
                capture_with_prior(&bytes, &name, brdf, &options, None, progress)
            }
        };
        let capture = match result {
            Err(e) if e.downcast_ref::<Stopped>().is_some() => return Ok(JobOutcome::Stopped),
            other => other?,
        };
        let textures = write_capture(&capture, folder.path(), self.exports)?;
        let replaced = folder.replaces();
        let out = folder.commit()?;
        Ok(JobOutcome::Done(Box::new(CaptureReport {
            photo: name,
            capture,
            out,
            textures,
            exports: self.exports,
            replaced,
            notes,
        })))
    }

    /// The relief prior's folder for `brdf`: the one given, else the model folder's.
    fn relief_prior_dir(&self, brdf: &Brdf) -> anyhow::Result<Option<PathBuf>> {
        if let Some(dir) = &self.prior_dir {
            return Ok(Some(dir.clone()));
        }
        match &self.model_dir {
            Some(dir) => find_prior(dir, brdf),
            None => Ok(None),
        }
    }

    /// The model folder of the prior.
    fn model(&self) -> anyhow::Result<PathBuf> {
        self.model_dir
            .clone()
            .context("a capture from the generator prior needs a model folder")
    }
}

/// The maps of the material folder `dir` that `brdf` takes (the others are named in a note);
/// a folder that holds none of them is an error.
fn known_maps(dir: &Path, brdf: &Brdf, notes: &mut Vec<String>) -> anyhow::Result<MaterialMaps> {
    let loaded = load_maps(dir, None)
        .with_context(|| format!("--known: cannot load '{}'", dir.display()))?;
    let takes: Vec<&str> = brdf.params().iter().map(|p| p.name).collect();
    let mut held = MaterialMaps::new();
    let mut skipped = Vec::new();
    for (name, map) in loaded.maps.iter() {
        if takes.contains(&name) {
            held.insert(name, map.clone());
        } else {
            skipped.push(name);
        }
    }
    if held.names().is_empty() {
        bail!(
            "--known: '{}' has none of {}'s maps ({}); it has {}",
            dir.display(),
            brdf.name(),
            takes.join(", "),
            loaded.maps.names().join(", ")
        );
    }
    if !skipped.is_empty() {
        notes.push(format!(
            "note: --known: {} of '{}' not held ({} does not take them)",
            skipped.join(", "),
            dir.display(),
            brdf.name()
        ));
    }
    Ok(held)
}

impl std::fmt::Display for CaptureReport {
    /// The lines `photomat capture` prints after a capture.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.capture;
        let (row, col) = c.highlight.pixel;
        let (_, _, size, _) = c.photo.dims4().map_err(|_| std::fmt::Error)?;
        let camera = c
            .vignetting
            .map_or(String::new(), |a| format!(", vignetting {a:.3}"))
            + &c.ambient
                .map_or(String::new(), |a| format!(", ambient {a:.3}"));
        writeln!(
            f,
            "captured {} as {} ({size}², a square of {:.3} at flash height 1 from a {:.1}° field \
             of view ({}); flash above pixel ({row:.1}, {col:.1}) by {}, gain {:.3}{camera}): \
             loss {:.4} → {:.4} in {} steps, {:.1} s",
            self.photo,
            c.brdf.name(),
            c.side,
            c.fov.degrees,
            c.fov.source,
            c.highlight.source,
            c.gain,
            c.losses.first().copied().unwrap_or(f64::NAN),
            c.losses.last().copied().unwrap_or(f64::NAN),
            c.losses.len(),
            c.seconds
        )?;
        if let Some(coarse) = &c.coarse {
            writeln!(
                f,
                "  of which {} steps at {}² in {:.1} s, the last {} at {size}²",
                coarse.steps,
                coarse.size,
                coarse.seconds,
                c.losses.len() - coarse.steps,
            )?;
        }
        if let Some(prior) = &c.prior {
            let inversion = &prior.inversion;
            writeln!(
                f,
                "  generator prior from {}: inversion loss {:.4} → {:.4} in {} steps, {:.1} s",
                prior.model,
                inversion.losses.first().copied().unwrap_or(f64::NAN),
                inversion.losses.last().copied().unwrap_or(f64::NAN),
                inversion.losses.len(),
                inversion.seconds
            )?;
        }
        if let Some(selection) = &c.selection {
            let errors: Vec<String> = selection
                .candidates
                .iter()
                .map(|c| format!("{} {:.4}", c.brdf, c.l1_linear))
                .collect();
            writeln!(
                f,
                "  --brdf auto (tolerance {}): {} of {} (linear L1 of E's maps: {})",
                selection.tolerance,
                selection.chosen,
                selection.candidates.len(),
                errors.join(", ")
            )?;
        }
        let dir = self.out.display();
        if self.replaced {
            writeln!(f, "  replaced the earlier capture in {dir}")?;
        }
        writeln!(
            f,
            "  {dir}/material/  the maps (photomat render --maps {dir}/material --orbit 8)"
        )?;
        let documents = match (self.exports.gltf, self.exports.mtlx) {
            (true, true) => " and material.{gltf,mtlx}",
            (true, false) => " and material.gltf",
            (false, true) => " and material.mtlx",
            (false, false) => "",
        };
        writeln!(
            f,
            "  {dir}/export/  renderer textures ({}){documents}",
            self.textures.files().join(", ")
        )?;
        let panels = if c.prior.is_some() {
            "photo | M's relighting | E's maps | re-render | ×4 error"
        } else {
            "photo | re-render | ×4 error"
        };
        writeln!(f, "  {dir}/sheet.png  {panels}")?;
        writeln!(
            f,
            "  {dir}/relit.png  the maps under eight new flash positions"
        )?;
        write!(
            f,
            "  {dir}/capture.json  geometry, highlight, gain, losses, timings"
        )
    }
}
