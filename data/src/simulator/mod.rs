//! Phone-flash photo simulator: procedural materials photographed by a
//! simulated phone with its flash on, written with their ground truth.
//!
//! Photo `i` of a run: its family is the `i mod F`-th of the run's F families (so every family
//! is equally represented), then, from the photo's own random stream ([`random`]): the
//! family's seed, the highlight ([`HighlightJitter`], Gaussian around the centre), the camera
//! ([`PhoneCamera`] or a fixed [`CameraModel`]) and the sensor noise; with poses on, the
//! phone's tilt and flash offset from a stream of its own ([`pose`]). The material is rendered
//! over the photo's square of side 2 with the analytic flash renderer ([`scene`]), developed
//! by the camera model ([`camera`]) and written with its shading-model maps and the true
//! highlight ([`output`], format in docs/datasets.md). Photos are simulated in parallel
//! (rayon); each depends only on `(seed, i)`, so the output is identical whatever the
//! thread count.

pub mod camera;
pub mod output;
pub mod pose;
pub mod random;
pub mod scene;

use std::path::Path;

use candle_core::Device;
use photomat_core::map_files::{SaveOptions, save_maps};
use photomat_core::output_folder::{OutputFolder, ResultKind};
use photomat_core::{Error, Highlight, Result};
use rand::Rng;
use rayon::prelude::*;

pub use camera::{CameraModel, PhoneCamera, SceneRadiance, ToneCurve, ToneKind};
pub use output::{
    FORMAT_TAG, FORMAT_VERSION, PHOTOS_DIR, PhotoFormat, SIMULATION_FILE, SimulatedPhoto,
    SimulationManifest, TRUTH_DIR, write_photo,
};
pub use pose::{PhonePose, PoseJitter};
pub use scene::{HighlightJitter, PHOTO_SIDE, Scene};

use crate::procedural::Family;

/// Where each photo's camera comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum CameraSource {
    /// A random phone camera per photo.
    Phone(PhoneCamera),
    /// The same camera for every photo (e.g. [`CameraModel::ideal`] in tests).
    Fixed(CameraModel),
}

/// Parameters of a simulation run.
#[derive(Clone)]
pub struct SimulationConfig<'a> {
    /// Number of photos.
    pub count: usize,
    /// Photo side S in pixels (also the resolution of the truth maps).
    pub size: usize,
    /// Run seed: equal seeds give byte-identical output.
    pub seed: u64,
    /// Photo file format.
    pub format: PhotoFormat,
    /// Families, cycled through in order ([`crate::procedural::families`] for all of them).
    pub families: Vec<&'a dyn Family>,
    /// The cameras.
    pub camera: CameraSource,
    /// The highlight distribution: where the untilted camera is centred.
    pub jitter: HighlightJitter,
    /// The phone poses (tilt, flash offset; [`PoseJitter::default`] for the overhead pose
    /// of the training convention).
    pub pose: PoseJitter,
}

/// Smallest photo side: the camera's centre-weighted meter needs a central half of at least
/// one pixel, and the height adapter's central differences need three texels.
pub const MIN_SIZE: usize = 4;

/// Run a simulation into `out` (created): `photos/`, `truth/` and `simulation.json`, as
/// docs/datasets.md describes. `progress` is called once per finished photo (from worker
/// threads). The folder is written whole when the run ends ([`SIMULATION`],
/// [`photomat_core::output_folder`]): an earlier simulation is refused unless `overwrite`,
/// which replaces it whole, and a folder holding files a simulation does not write is refused.
pub fn simulate(
    out: &Path,
    config: &SimulationConfig<'_>,
    overwrite: bool,
    progress: &(dyn Fn() + Sync),
) -> Result<SimulationManifest> {
    if config.families.is_empty() {
        return Err(Error::Invalid(
            "the simulator needs at least one material family".into(),
        ));
    }
    if config.size < MIN_SIZE {
        return Err(Error::Invalid(format!(
            "photos must be at least {MIN_SIZE}×{MIN_SIZE} pixels, got {0}×{0}",
            config.size
        )));
    }
    if let CameraSource::Fixed(camera) = &config.camera {
        camera.validate()?;
    }
    config.pose.validate()?;
    // Written whole when the run ends: an earlier simulation is refused unless overwritten,
    // and a killed run leaves the folder as it was.
    let folder = OutputFolder::claim(out, SIMULATION, overwrite)?;
    let staging = folder.path();
    for dir in [PHOTOS_DIR, TRUTH_DIR] {
        let dir = staging.join(dir);
        std::fs::create_dir_all(&dir)
            .map_err(|e| Error::file(&dir, format!("cannot create: {e}")))?;
    }
    let photos = (0..config.count)
        .into_par_iter()
        .map(|index| {
            let record = simulate_photo(staging, config, index);
            progress();
            record
        })
        .collect::<Result<Vec<_>>>()?;
    let manifest = SimulationManifest {
        format: FORMAT_TAG.into(),
        version: FORMAT_VERSION,
        seed: config.seed,
        size: config.size,
        photos,
    };
    manifest.write(staging)?;
    folder.commit()?;
    Ok(manifest)
}

/// What a simulation's folder holds.
pub const SIMULATION: ResultKind = ResultKind {
    what: "a simulation",
    command: "photomat simulate",
    entries: &[PHOTOS_DIR, TRUTH_DIR, SIMULATION_FILE],
    kept: &[],
};

/// Simulate and write photo `index`; its record for `simulation.json`.
fn simulate_photo(
    out: &Path,
    config: &SimulationConfig<'_>,
    index: usize,
) -> Result<SimulatedPhoto> {
    let mut rng = random::photo_rng(config.seed, index as u64);
    let family = config.families[index % config.families.len()];
    let family_name = family.name();
    // Below 2^32: every JSON reader keeps the seed exact.
    let family_seed = rng.random::<u32>() as u64;
    let context = |e: Error| {
        Error::Invalid(format!(
            "photo {index} (family '{family_name}', seed {family_seed}): {e}"
        ))
    };
    let (row, col) = config.jitter.sample(config.size, &mut rng);
    let above = Highlight::from_pixel_on(row, col, config.size, PHOTO_SIDE);
    let pose = if config.pose.is_overhead() {
        PhonePose::OVERHEAD
    } else {
        config
            .pose
            .sample(&mut random::pose_rng(config.seed, index as u64))
    };
    let scene =
        Scene::from_family(family, config.size, family_seed, &Device::Cpu).map_err(context)?;
    let (seen, light) = scene.seen_from(above, &pose).map_err(context)?;
    // The true highlight is the flash's mirror point as the lens sees it; for the overhead
    // pose that is the drawn point itself, kept as drawn so that no rounding changes it.
    let (row, col) = if pose.is_overhead() {
        (row, col)
    } else {
        pose.pixel_of(above, pose.mirror_point(above), config.size, PHOTO_SIDE)
    };
    let highlight = Highlight::from_pixel_on(row, col, config.size, PHOTO_SIDE);
    let camera = match &config.camera {
        CameraSource::Phone(phone) => phone.sample(&light, &mut rng).map_err(context)?,
        CameraSource::Fixed(camera) => *camera,
    };
    let photo = camera.develop(&light, &mut rng).map_err(context)?;

    let stem = format!("{index:06}");
    let photo_rel = format!("{PHOTOS_DIR}/{stem}.{}", config.format.extension());
    let truth_rel = format!("{TRUTH_DIR}/{stem}");
    write_photo(&out.join(&photo_rel), &photo, config.format)?;
    save_maps(
        &out.join(&truth_rel),
        seen.brdf().as_ref(),
        seen.maps(),
        &SaveOptions::default(),
    )?;
    Ok(SimulatedPhoto {
        photo: photo_rel,
        truth: truth_rel,
        family: family_name.into(),
        family_seed,
        material: family.describe(family_seed),
        highlight_px: [row, col],
        highlight: [highlight.x, highlight.y],
        camera,
        pose: (!pose.is_overhead()).then_some(pose),
    })
}
