//! Library materials as the simulator's materials: [`LibraryFamily`] draws, per seed, one
//! material of a split (or a mix of two), seen at a random scale, offset and orientation, so
//! that `photomat simulate --library LIB --split train` photographs them with the simulator's
//! phone (pose, exposure, white balance, vignetting, noise, JPEG; docs/datasets.md) and the
//! relief prior's trainer renders them on the fly (docs/data.md, "Flash photos of the
//! library").
//!
//! The augmentations follow the synthetic-training practice of single-image SVBRDF capture
//! (Deschaintre et al. 2018, §5; MatFusion, Sartor & Peers 2023): per photo, from the seed,
//!
//! - **zoom** `z`, log-uniform in [`Augmentation::zoom`]: the photo's square shows `z`
//!   material squares across (materials are periodic); heights scale by `1/z` with the plane,
//!   normals do not change;
//! - **offset**: a uniform periodic shift;
//! - **orientation**: one of the 8 rotations and mirrorings of the square, the normals'
//!   in-plane components turned with it;
//! - **mixing**, with probability [`Augmentation::mix_probability`]: a second material of the
//!   split, drawn the same way, blended with a weight uniform in [`Augmentation::mix_weight`]
//!   (normals renormalised), a surface no package has;
//! - **gloss**: a material whose roughness the package did not give (one default value) gets
//!   one uniform in [`Augmentation::default_roughness`], so photos show every gloss.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use candle_core::Device;
use photomat_core::image_io::PlanarImage;
use photomat_core::rng::SplitMix64;
use photomat_core::{Error, MaterialMaps, Result};

use crate::convert::RoughnessSource;
use crate::index::{LibraryIndex, MATERIALS_DIR};
use crate::material::{MaterialFolders, Provenance};
use crate::resample::halve;
use crate::split::Split;

/// How photos see library materials (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Augmentation {
    /// Range of the zoom `z` (material squares across the photo). Default 0.5–1.5.
    pub zoom: (f64, f64),
    /// Probability that a photo shows a mix of two materials. Default 0.2.
    pub mix_probability: f64,
    /// Range of the second material's weight in a mix. Default 0.3–0.7.
    pub mix_weight: (f32, f32),
    /// Range of the roughness drawn for materials without one of their own. Default
    /// 0.25–0.9: from satin paint to rough plaster.
    pub default_roughness: (f32, f32),
}

impl Default for Augmentation {
    fn default() -> Self {
        Self {
            zoom: (0.5, 1.5),
            mix_probability: 0.2,
            mix_weight: (0.3, 0.7),
            default_roughness: (0.25, 0.9),
        }
    }
}

/// Channel layout of a material's planar stack: diffuse 0–2, specular 3–5, roughness 6,
/// normal 7–9, height 10 (world units).
const CHANNELS: usize = 11;
const ROUGHNESS: usize = 6;
const NORMAL: usize = 7;
const HEIGHT: usize = 10;

/// One material of the family.
#[derive(Debug, Clone)]
struct Member {
    id: String,
    dir: PathBuf,
}

/// The materials of one split of a library, as a simulator family (module docs).
pub struct LibraryFamily {
    members: Vec<Member>,
    augmentation: Augmentation,
    /// Materials read so far, when [`LibraryFamily::keep_in_memory`] keeps them.
    memory: Option<Memory>,
}

/// A material's stack and whether its roughness came from the package.
type Stack = Arc<(PlanarImage, bool)>;

/// The materials a family keeps in memory, halved to at most `side`.
struct Memory {
    side: usize,
    stacks: Mutex<HashMap<usize, Stack>>,
}

/// A drawn photo material: the stack at the photo's size and what was drawn.
pub struct DrawnMaterial {
    /// (1, 3+3+1+3, S, S) `ggx` maps.
    pub ggx: MaterialMaps,
    /// (1, 1, S, S) heights in world units of the photo's square (side 2).
    pub height: PlanarImage,
    /// The ids of the material(s) and the draws, for the photo's record.
    pub description: String,
}

impl LibraryFamily {
    /// The materials of `split` of the library at `library`, less those with a licence in
    /// `exclude_licences` (e.g. `GPL-3+`, for a model whose licence cannot carry it).
    pub fn open(
        library: &Path,
        split: Split,
        exclude_licences: &[String],
        augmentation: Augmentation,
    ) -> Result<Self> {
        let index = LibraryIndex::load(library)?;
        let members: Vec<Member> = index
            .split(split)
            .into_iter()
            .filter(|m| !m.licences.iter().any(|l| exclude_licences.contains(l)))
            .map(|m| Member {
                id: m.id.clone(),
                dir: library.join(MATERIALS_DIR).join(&m.id),
            })
            .collect();
        if members.is_empty() {
            return Err(Error::file(
                library,
                format!(
                    "has no {} material{}",
                    split.name(),
                    if exclude_licences.is_empty() {
                        String::new()
                    } else {
                        format!(" outside the licences {}", exclude_licences.join(", "))
                    }
                ),
            ));
        }
        let (lo, hi) = augmentation.zoom;
        if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
            return Err(Error::Invalid(format!(
                "the zoom range {lo}–{hi} must be positive and increasing"
            )));
        }
        Ok(Self {
            members,
            augmentation,
            memory: None,
        })
    }

    /// Keeps every material read in memory, halved to at most `side` texels (a trainer that
    /// draws thousands of photos reads each material once instead of per photo: a 512² stack
    /// is 11.5 MB).
    pub fn keep_in_memory(mut self, side: usize) -> Self {
        self.memory = Some(Memory {
            side: side.max(1),
            stacks: Mutex::new(HashMap::new()),
        });
        self
    }

    /// Material `index`'s stack and whether its roughness came from the package, from memory
    /// when kept there.
    fn stack(&self, index: usize) -> Result<Stack> {
        let Some(memory) = &self.memory else {
            return Ok(Arc::new(load_stack(&self.members[index].dir)?));
        };
        if let Some(found) = memory
            .stacks
            .lock()
            .ok()
            .and_then(|m| m.get(&index).cloned())
        {
            return Ok(found);
        }
        let (mut stack, given) = load_stack(&self.members[index].dir)?;
        while stack.width > memory.side && stack.width.is_multiple_of(2) {
            stack = halve(&stack);
        }
        let kept = Arc::new((stack, given));
        if let Ok(mut m) = memory.stacks.lock() {
            m.insert(index, kept.clone());
        }
        Ok(kept)
    }

    /// How many materials the family draws from.
    pub fn len(&self) -> usize {
        self.members.len()
    }

    /// Whether the family has no material (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// What photo seed `seed` draws (module docs): the material(s) and how they are seen.
    pub fn plan(&self, seed: u64) -> Plan {
        let mut rng = SplitMix64(seed ^ 0x006c_6962_7261_7279); // "library"
        let a = self.augmentation;
        let n = self.members.len() as u64;
        let mut view = |index: usize| View {
            index,
            zoom: (a.zoom.0.ln() + (a.zoom.1.ln() - a.zoom.0.ln()) * rng.next_unit()).exp(),
            offset: (rng.next_unit(), rng.next_unit()),
            symmetry: (rng.next_u64() % 8) as u8,
            roughness: a.default_roughness.0
                + (a.default_roughness.1 - a.default_roughness.0) * rng.next_unit() as f32,
        };
        let first = view((SplitMix64(seed).next_u64() % n) as usize);
        let mut rng_mix = SplitMix64(seed ^ 0x006d_6978); // "mix"
        let mix = (n > 1 && rng_mix.next_unit() < a.mix_probability).then(|| {
            let other = (first.index + 1 + (rng_mix.next_u64() % (n - 1)) as usize) % n as usize;
            let weight =
                a.mix_weight.0 + (a.mix_weight.1 - a.mix_weight.0) * rng_mix.next_unit() as f32;
            (view(other), weight)
        });
        Plan { first, mix }
    }

    /// The material of photo seed `seed` at `size`² ([`Self::plan`]).
    pub fn draw(&self, size: usize, seed: u64) -> Result<DrawnMaterial> {
        let plan = self.plan(seed);
        let mut stack = self.view(&plan.first, size)?;
        if let Some((view, weight)) = &plan.mix {
            let second = self.view(view, size)?;
            for (x, y) in stack.data.iter_mut().zip(&second.data) {
                *x = (1.0 - weight) * *x + weight * y;
            }
            renormalise(&mut stack);
        }
        let plane = size * size;
        let part = |from: usize, channels: usize| -> Result<candle_core::Tensor> {
            PlanarImage::new(
                channels,
                size,
                size,
                stack.data[from * plane..(from + channels) * plane].to_vec(),
            )?
            .to_tensor(&Device::Cpu)
        };
        let ggx = MaterialMaps::new()
            .with("diffuse", part(0, 3)?)
            .with("specular", part(3, 3)?)
            .with("roughness", part(ROUGHNESS, 1)?)
            .with("normal", part(NORMAL, 3)?)
            .with_texel_size(Some(photomat_core::flash::PHOTO_SIDE / size as f64));
        let height = PlanarImage::new(1, size, size, stack.data[HEIGHT * plane..].to_vec())?;
        Ok(DrawnMaterial {
            ggx,
            height,
            description: self.describe_plan(&plan),
        })
    }

    /// `plan` as text: the material ids and how they were seen.
    pub fn describe_plan(&self, plan: &Plan) -> String {
        let view = |v: &View| {
            format!(
                "{} (zoom {:.2}, symmetry {})",
                self.members[v.index].id, v.zoom, v.symmetry
            )
        };
        match &plan.mix {
            None => view(&plan.first),
            Some((second, weight)) => {
                format!("{} + {weight:.2}·{}", view(&plan.first), view(second))
            }
        }
    }

    /// The material of `view` at `size`² (module docs).
    fn view(&self, view: &View, size: usize) -> Result<PlanarImage> {
        let kept = self.stack(view.index)?;
        let (mut stack, roughness_given) = (kept.0.clone(), kept.1);
        let n = stack.width as f64;
        // Source texels per photo texel; halve the source while that is 2 or more, so that
        // shrinking averages the texels a photo pixel covers.
        let mut step = view.zoom * n / size as f64;
        let mut offset = (view.offset.0 * n, view.offset.1 * n);
        while step >= 2.0 && stack.width.is_multiple_of(2) {
            stack = halve(&stack);
            step /= 2.0;
            offset = (offset.0 / 2.0, offset.1 / 2.0);
        }
        let mut out = sample_view(&stack, size, step, offset, view.symmetry);
        // Heights scale with the plane: the material appears 1/z as large.
        let plane = size * size;
        for h in &mut out.data[HEIGHT * plane..] {
            *h /= view.zoom as f32;
        }
        if !roughness_given {
            out.data[ROUGHNESS * plane..(ROUGHNESS + 1) * plane].fill(view.roughness);
        }
        Ok(out)
    }
}

/// How one material is seen in a photo ([`LibraryFamily::plan`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// The material's index in the family.
    pub index: usize,
    /// Material squares across the photo.
    pub zoom: f64,
    /// Periodic shift (row, column) as fractions of the material's side.
    pub offset: (f64, f64),
    /// Element of the square's symmetry group, 0–7 ([`sample_view`]).
    pub symmetry: u8,
    /// The roughness given to a material without one of its own.
    pub roughness: f32,
}

/// What one photo seed draws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    pub first: View,
    /// A second material and its weight.
    pub mix: Option<(View, f32)>,
}

impl photomat_data::procedural::Family for LibraryFamily {
    fn name(&self) -> &'static str {
        "library"
    }

    fn brdf(&self) -> String {
        "ggx".into()
    }

    fn generate(&self, size: usize, seed: u64, device: &Device) -> Result<MaterialMaps> {
        let maps = self.draw(size, seed)?.ggx;
        maps.map_tensors(|t| Ok(t.to_device(device)?))
    }

    fn describe(&self, seed: u64) -> Option<String> {
        Some(self.describe_plan(&self.plan(seed)))
    }
}

/// The 11-channel stack of the material folder `dir` (module docs' layout) and whether its
/// roughness came from the package.
fn load_stack(dir: &Path) -> Result<(PlanarImage, bool)> {
    let folders = MaterialFolders::of(dir);
    let ggx = folders.load_ggx()?;
    let height = folders.load_height()?;
    let given = match &ggx.manifest.source {
        Some(source) => serde_json::from_value::<Provenance>(source.clone())
            .map(|p| !matches!(p.roughness, RoughnessSource::Default))
            .unwrap_or(true),
        None => true,
    };
    let mut data = Vec::new();
    let mut side = 0;
    for name in ["diffuse", "specular", "roughness", "normal"] {
        let image = PlanarImage::from_tensor(ggx.maps.get(name)?)?;
        side = image.width;
        data.extend(image.data);
    }
    // World units: the map value times the height model's scale.
    let scale = height
        .brdf
        .name()
        .split("scale=")
        .nth(1)
        .and_then(|s| s.trim_end_matches(')').parse::<f64>().ok())
        .ok_or_else(|| Error::file(dir, "the height folder's model has no scale"))?;
    let h = PlanarImage::from_tensor(height.maps.get("height")?)?;
    data.extend(h.data.iter().map(|v| v * scale as f32));
    Ok((PlanarImage::new(CHANNELS, side, side, data)?, given))
}

/// `stack` sampled on a `size`² grid: photo texel (r, c) looks at source position
/// `offset + step·M·(c + ½, −(r + ½))` (periodic, bilinear), M the `symmetry`-th element of the
/// square's symmetry group; the normals' (x, y) are turned by Mᵀ (a feature of normal n in the
/// material appears in the photo with normal Mᵀn).
fn sample_view(
    stack: &PlanarImage,
    size: usize,
    step: f64,
    offset: (f64, f64),
    symmetry: u8,
) -> PlanarImage {
    // M as (a, b; c, d): the rotations by k·90° (k = symmetry mod 4), then a mirror of x.
    let (mut a, mut b, c, d) = match symmetry % 4 {
        0 => (1.0, 0.0, 0.0, 1.0),
        1 => (0.0, -1.0, 1.0, 0.0),
        2 => (-1.0, 0.0, 0.0, -1.0),
        _ => (0.0, 1.0, -1.0, 0.0),
    };
    // The mirrored four: x negated after the rotation.
    if symmetry >= 4 {
        a = -a;
        b = -b;
    }
    let plane = size * size;
    let mut out = vec![0.0f32; CHANNELS * plane];
    for r in 0..size {
        for col in 0..size {
            // Plane coordinates (x right, y up) of the photo texel, in photo texels.
            let (x, y) = (col as f64 + 0.5, -(r as f64 + 0.5));
            let (sx, sy) = (a * x + b * y, c * x + d * y);
            let (src_col, src_row) = (offset.1 + step * sx, offset.0 - step * sy);
            let i = r * size + col;
            for ch in 0..CHANNELS {
                out[ch * plane + i] = stack.sample_periodic(ch, src_row, src_col);
            }
            let (nx, ny) = (
                out[NORMAL * plane + i] as f64,
                out[(NORMAL + 1) * plane + i] as f64,
            );
            out[NORMAL * plane + i] = (a * nx + c * ny) as f32;
            out[(NORMAL + 1) * plane + i] = (b * nx + d * ny) as f32;
        }
    }
    let mut image = PlanarImage {
        channels: CHANNELS,
        height: size,
        width: size,
        data: out,
    };
    renormalise(&mut image);
    image
}

/// Renormalises the normal channels of a stack (after interpolation or mixing).
fn renormalise(stack: &mut PlanarImage) {
    let plane = stack.width * stack.height;
    for i in 0..plane {
        let v: Vec<f32> = (0..3)
            .map(|k| stack.data[(NORMAL + k) * plane + i])
            .collect();
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            .sqrt()
            .max(f32::MIN_POSITIVE);
        for (k, value) in v.iter().enumerate() {
            stack.data[(NORMAL + k) * plane + i] = value / l;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stack whose height is a ramp along x (periodic saw) with matching normals.
    fn ramp(n: usize) -> PlanarImage {
        let plane = n * n;
        let mut data = vec![0.5f32; CHANNELS * plane];
        for r in 0..n {
            for c in 0..n {
                let i = r * n + c;
                // A feature at the left of the material: normal tilted towards −x.
                let nx = if c < n / 2 { -0.6 } else { 0.0 };
                let nz = (1.0f32 - nx * nx).sqrt();
                data[NORMAL * plane + i] = nx;
                data[(NORMAL + 1) * plane + i] = 0.0;
                data[(NORMAL + 2) * plane + i] = nz;
                data[HEIGHT * plane + i] = c as f32;
            }
        }
        PlanarImage::new(CHANNELS, n, n, data).unwrap()
    }

    #[test]
    fn a_quarter_turn_turns_the_normals_with_the_features() {
        let n = 8;
        let stack = ramp(n);
        let plain = sample_view(&stack, n, 1.0, (0.0, 0.0), 0);
        // Unchanged without a symmetry: the left half tilts to −x.
        let plane = n * n;
        assert!((plain.data[NORMAL * plane] + 0.6).abs() < 1e-6);
        // Symmetry 1, M = (0 −1; 1 0): the photo's texel at plane (x, y) shows the material
        // at (−y, x), so the material's left half (x < n/2) appears where −y < n/2, at the
        // top rows; its normal (−0.6, 0) becomes Mᵀ(−0.6, 0) = (0, 0.6).
        let turned = sample_view(&stack, n, 1.0, (0.0, 0.0), 1);
        let top = 0;
        assert!((turned.data[NORMAL * plane + top]).abs() < 1e-6);
        assert!((turned.data[(NORMAL + 1) * plane + top] - 0.6).abs() < 1e-6);
        for symmetry in 0..8 {
            let view = sample_view(&stack, n, 1.0, (0.0, 0.0), symmetry);
            for i in 0..plane {
                let l: f32 = (0..3)
                    .map(|k| view.data[(NORMAL + k) * plane + i].powi(2))
                    .sum();
                assert!((l - 1.0).abs() < 1e-5, "unit normals");
            }
        }
    }
}
