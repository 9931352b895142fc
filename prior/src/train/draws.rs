//! The relief prior's training examples, rendered on the fly: per example a library material
//! drawn and seen as `photomat simulate --library` sees it ([`photomat_library::photos`]:
//! zoom, offset, orientation, mixing, gloss), photographed by the simulator's random phone
//! (highlight jitter, exposure, white balance, vignetting, beam profile, ambient light, noise,
//! tone curve; `photomat_data::simulator`), with its true maps and heights. Every example is a
//! pure function of the run seed and its index, so a resumed run draws what an uninterrupted
//! one would.
//!
//! Materials are read once and kept in memory at the crop's side or twice it (a 256² crop
//! reads them at 512²: 11.5 MB each, 6.3 GB for 544), as the photos' zoom needs at most that.

use std::collections::HashMap;
use std::sync::Mutex;

use candle_core::{Device, Tensor};
use photomat_core::rng::mix64;
use photomat_core::{Highlight, MaterialMaps, lookup};
use photomat_data::simulator::{HighlightJitter, PHOTO_SIDE, PhoneCamera, Scene};
use photomat_library::photos::LibraryFamily;
use rand::SeedableRng;
use rand::rngs::StdRng;

/// One training example.
pub struct Example {
    /// The photo, display values (3, N, N) as a (1, 3, N, N) tensor.
    pub photo: Tensor,
    /// Where the flash was.
    pub highlight: Highlight,
    /// The photographed `ggx` maps, (1, C, N, N).
    pub truth: MaterialMaps,
    /// The true heights in world units (1, 1, N, N).
    pub height: Tensor,
}

/// Draws examples from a library split (module docs).
pub struct Draws {
    family: LibraryFamily,
    size: usize,
    camera: PhoneCamera,
    jitter: HighlightJitter,
    /// Examples already rendered, by index: a step's examples are rendered once even when a
    /// validation pass asks for them again.
    cache: Mutex<HashMap<u64, ExampleData>>,
}

/// An example's tensors as plain data (tensors are not `Sync`).
#[derive(Clone)]
struct ExampleData {
    photo: Vec<f32>,
    highlight: Highlight,
    truth: Vec<(String, usize, Vec<f32>)>,
    height: Vec<f32>,
}

impl Draws {
    /// Examples of `size`² from `family`.
    pub fn new(family: LibraryFamily, size: usize) -> Self {
        Self {
            family,
            size,
            camera: PhoneCamera::default(),
            jitter: HighlightJitter::default(),
            cache: Mutex::new(HashMap::new()),
        }
    }

    /// Side of the examples.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Example `index` of the stream `seed` (module docs).
    pub fn example(&self, seed: u64, index: u64) -> anyhow::Result<Example> {
        let key = mix64(seed ^ mix64(index));
        let data = match self.cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
            Some(data) => data,
            None => self.render(key)?,
        };
        let n = self.size;
        let device = Device::Cpu;
        let mut truth = MaterialMaps::new().with_texel_size(Some(PHOTO_SIDE / n as f64));
        for (name, channels, values) in &data.truth {
            truth.insert(
                name.as_str(),
                Tensor::from_vec(values.clone(), (1, *channels, n, n), &device)?,
            );
        }
        Ok(Example {
            photo: Tensor::from_vec(data.photo, (1, 3, n, n), &device)?,
            highlight: data.highlight,
            truth,
            height: Tensor::from_vec(data.height, (1, 1, n, n), &device)?,
        })
    }

    /// Renders the example of stream key `key`.
    fn render(&self, key: u64) -> anyhow::Result<ExampleData> {
        let n = self.size;
        let drawn = self.family.draw(n, key)?;
        let mut rng = StdRng::seed_from_u64(key);
        let (row, col) = self.jitter.sample(n, &mut rng);
        let highlight = Highlight::from_pixel_on(row, col, n, PHOTO_SIDE);
        let scene = Scene::new(lookup("ggx")?, drawn.ggx.clone())?;
        let light = scene.light(highlight)?;
        let camera = self.camera.sample(&light, &mut rng)?;
        let photo = camera.develop(&light, &mut rng)?;
        let mut truth = Vec::new();
        for (name, map) in drawn.ggx.iter() {
            let (_, c, _, _) = map.dims4()?;
            truth.push((name.to_string(), c, map.flatten_all()?.to_vec1::<f32>()?));
        }
        Ok(ExampleData {
            photo: photo.data,
            highlight,
            truth,
            height: drawn.height.data,
        })
    }

    /// Renders the examples `indices` of stream `seed` ahead (in parallel), so that a step's
    /// batch is ready; they are kept until [`Self::forget`].
    pub fn prepare(&self, seed: u64, indices: &[u64]) -> anyhow::Result<()> {
        use rayon::prelude::*;
        let rendered: Vec<(u64, ExampleData)> = indices
            .par_iter()
            .map(|&i| {
                let key = mix64(seed ^ mix64(i));
                self.render(key).map(|d| (key, d))
            })
            .collect::<anyhow::Result<_>>()?;
        if let Ok(mut cache) = self.cache.lock() {
            cache.extend(rendered);
        }
        Ok(())
    }

    /// Drops the rendered examples of `indices` of stream `seed`.
    pub fn forget(&self, seed: u64, indices: &[u64]) {
        if let Ok(mut cache) = self.cache.lock() {
            for &i in indices {
                cache.remove(&mix64(seed ^ mix64(i)));
            }
        }
    }
}
