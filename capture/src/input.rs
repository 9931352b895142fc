//! A photo ready to be fitted: decoded, oriented and resampled to the capture's square as
//! `photomat prepare` does, its highlight found (or given and checked), its flash geometry and
//! the photo box-filtered for a coarse stage or the warm-up.

use anyhow::{Context, bail};
use candle_core::{DType, Device, Tensor};
use photomat_core::render::{DISPLAY_GAMMA, render_radiance_with};
use photomat_core::{Brdf, FlashGeometry, Highlight, MaterialMaps, encode_display};
use photomat_data::dataset::photo::{Framing, prepare_photo};
use photomat_data::highlight::{DetectionStatus, DetectorKind};

use crate::camera::{self, CameraTerms};
use crate::field_of_view::{self, FieldOfView};
use crate::options::CaptureOptions;
use crate::result::HighlightUsed;
use crate::square::square_side;

/// Smallest and largest side of a capture: below 16 texels there is no highlight to fit,
/// above 2048 one step's render and gradients exceed a few GB.
pub const SIZE_RANGE: (usize, usize) = (16, 2048);

/// A photo ready to be fitted: resampled, its highlight found, its flash geometry.
pub(crate) struct Input {
    /// (1, 3, N, N) display values.
    pub(crate) photo: Tensor,
    pub(crate) size: usize,
    pub(crate) highlight: HighlightUsed,
    /// The field of view the square's side comes from.
    pub(crate) fov: FieldOfView,
    pub(crate) side: f64,
    pub(crate) texel: f64,
    /// The photo's flash, on the square of side `side`.
    pub(crate) light: Highlight,
    pub(crate) geometry: FlashGeometry,
    /// Squared distance of every texel from the centre, for the vignetting ([`camera`]).
    pub(crate) rho2: Tensor,
}

impl Input {
    /// The maps of `brdf` decoded from `raw` (1, C, N, N) at this photo's texel size, and
    /// their display render under its flash, exposed by `terms`: (1, 3, N, N).
    pub(crate) fn predict(
        &self,
        brdf: &Brdf,
        terms: &CameraTerms,
        raw: &Tensor,
    ) -> anyhow::Result<(MaterialMaps, Tensor)> {
        let maps = brdf.decode(raw)?.with_texel_size(Some(self.texel));
        let radiance = render_radiance_with(brdf.as_ref(), &maps, &self.geometry)?;
        // The sum of the reflecting maps is built only where the ambient term reads it.
        let reflectance = if terms.fits_ambient() {
            maps.ambient_reflectance()?
        } else {
            None
        };
        let exposed = terms.expose(&radiance, reflectance.as_ref(), &self.rho2)?;
        Ok((maps, encode_display(&exposed)?))
    }

    /// The central `n·factor` texels of the photo (`n = size / factor`; the centre moves by
    /// half a texel at most) box-filtered by `factor` in linear light, as a sensor of n²
    /// pixels would have seen them, with the flash geometry of that smaller square.
    pub(crate) fn box_filtered(&self, factor: usize) -> anyhow::Result<Input> {
        let n = self.size / factor;
        let start = (self.size - n * factor) / 2;
        let photo = encode_display(
            &self
                .photo
                .narrow(2, start, n * factor)?
                .narrow(3, start, n * factor)?
                .powf(DISPLAY_GAMMA)?
                .avg_pool2d(factor)?,
        )?;
        let side = self.side * (n * factor) as f64 / self.size as f64;
        let geometry = FlashGeometry::with_side(&[self.light], n, side, DType::F32, &Device::Cpu)?;
        Ok(Input {
            photo,
            size: n,
            highlight: self.highlight.clone(),
            fov: self.fov,
            side,
            texel: side / n as f64,
            light: self.light,
            geometry,
            rho2: camera::rho_squared(n)?,
        })
    }
}

/// Checks the options, decodes and resamples the photo and finds its highlight.
pub(crate) fn prepare_input(
    bytes: &[u8],
    name: &str,
    options: &CaptureOptions,
) -> anyhow::Result<Input> {
    let (lo, hi) = SIZE_RANGE;
    if !(lo..=hi).contains(&options.size) {
        bail!("capture size {} is outside {lo} … {hi}", options.size);
    }
    let n = options.size;
    let framing = Framing {
        size: n,
        reject_non_square: false,
    };
    let prepared = prepare_photo(bytes, framing).map_err(|r| anyhow::anyhow!("{name}: {}", r.0))?;
    let highlight = match options.highlight {
        Some((row, col))
            if !((0.0..=n as f64).contains(&row) && (0.0..=n as f64).contains(&col)) =>
        {
            bail!(
                "{name}: --highlight {row},{col} lies outside the {n}×{n} square the photo is \
                 fitted at (rows and columns 0 … {n})"
            )
        }
        Some(pixel) => HighlightUsed {
            pixel,
            source: "given".into(),
            note: None,
        },
        None => {
            let kind = DetectorKind::default();
            let d = kind.build().detect(&prepared.image)?;
            if d.status == DetectionStatus::FallbackCentre {
                bail!(
                    "{name}: no flash highlight found ({}); give it with --highlight ROW,COL",
                    d.reason.unwrap_or_default()
                );
            }
            HighlightUsed {
                pixel: d.pixel(),
                source: kind.name().into(),
                note: d.reason,
            }
        }
    };
    let device = Device::Cpu;
    let photo = prepared.image.to_tensor(&device)?;
    let [width, height] = prepared.source_size;
    let fov = field_of_view::field_of_view(options.fov_degrees, bytes, width, height)
        .with_context(|| name.to_string())?;
    let side = square_side(fov.degrees, width, height);
    let (row, col) = highlight.pixel;
    let light = Highlight::from_pixel_on(row, col, n, side);
    let geometry = FlashGeometry::with_side(&[light], n, side, DType::F32, &device)?;
    Ok(Input {
        photo,
        size: n,
        highlight,
        fov,
        side,
        texel: side / n as f64,
        light,
        geometry,
        rho2: camera::rho_squared(n)?,
    })
}
