//! Per-sample wrap-around rolls of NCHW tensors (`torch.roll` per batch item).
//!
//! Two trainers roll periodic materials:
//! - the tileable GAN (TileGen's strategy, as used by the PhotoMat reference): before M
//!   relights a generated F, each sample is shifted by its own random offset, so that D sees
//!   every part of the periodic material — seams included — under every light position, and G
//!   cannot hide a seam at a fixed place ([`roll_offsets`], [`roll_per_sample`]);
//! - the estimator's fine-tune (PhotoMat §4): the decoded maps and F are rolled alike per
//!   sample before rendering under the same light, which removes the flash falloff E would
//!   otherwise bake into the maps ([`roll_maps`]).

use candle_core::{Result, Tensor, bail};
use photomat_core::MaterialMaps;
use photomat_core::rng::SplitMix64;

/// Per-sample offsets (Δrow, Δcol), uniform in `0..size` each, one pair per seed (the two
/// first draws of the SplitMix64 stream seeded by it).
pub fn roll_offsets(seeds: &[u64], size: usize) -> Vec<(usize, usize)> {
    seeds
        .iter()
        .map(|&s| {
            let mut rng = SplitMix64(s);
            let r = (rng.next_unit() * size as f64) as usize;
            let c = (rng.next_unit() * size as f64) as usize;
            // next_unit() < 1 keeps both below `size`; the min only guards float rounding.
            (r.min(size - 1), c.min(size - 1))
        })
        .collect()
}

/// Rolls batch item b of `x` by `offsets[b]` = (Δrow, Δcol), wrapping around: output texel
/// (i, j) is input texel ((i − Δrow) mod H, (j − Δcol) mod W), i.e. input texel (i, j) moves
/// to ((i + Δrow) mod H, (j + Δcol) mod W) (`torch.roll` semantics). Differentiable.
///
/// # Shapes
/// (B, C, H, W) with B = `offsets.len()` → (B, C, H, W).
pub fn roll_per_sample(x: &Tensor, offsets: &[(usize, usize)]) -> Result<Tensor> {
    let (_, _, h, w) = x.dims4()?;
    window_per_sample(x, offsets, (h, w))
}

/// The top-left `(h', w')` window of [`roll_per_sample`]`(x, offsets)`, taken from the
/// periodic extension when the window is larger than the map, as one fused op
/// ([`photomat_kernels::periodic_window`]: one pass each way where the roll and the cut
/// compose a dozen copies). Differentiable to any order.
///
/// # Shapes
/// (B, C, H, W) with B = `offsets.len()` and H, W ≥ 1 (offsets of any size wrap) →
/// (B, C, h', w').
pub fn window_per_sample(
    x: &Tensor,
    offsets: &[(usize, usize)],
    window: (usize, usize),
) -> Result<Tensor> {
    let (b, _c, h, w) = x.dims4()?;
    if offsets.len() != b {
        bail!("roll: {} offsets for a batch of {b}", offsets.len());
    }
    if h == 0 || w == 0 {
        bail!("roll: an empty {h}×{w} map");
    }
    // Output texel (i, j) reads input texel ((i − Δrow) mod H, (j − Δcol) mod W): the window
    // starts at ((H − Δrow) mod H, (W − Δcol) mod W).
    let origins: Vec<(usize, usize)> = offsets
        .iter()
        .map(|&(dr, dc)| ((h - dr % h) % h, (w - dc % w) % w))
        .collect();
    photomat_kernels::periodic_window(x, &origins, window)
}

/// [`roll_per_sample`] on every map, by the same offsets.
///
/// # Shapes
/// Each map (B, C, H, W) with B = `offsets.len()` → (B, C, H, W).
pub fn roll_maps(maps: &MaterialMaps, offsets: &[(usize, usize)]) -> Result<MaterialMaps> {
    // map_tensors keeps the set's texel size.
    maps.map_tensors(|map| Ok(roll_per_sample(map, offsets)?))
        .map_err(candle_core::Error::wrap)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn rolls_each_sample_by_its_offset() {
        let x = Tensor::arange(0f32, 2.0 * 3.0 * 4.0, &Device::Cpu)
            .unwrap()
            .reshape((2, 1, 3, 4))
            .unwrap();
        let y = roll_per_sample(&x, &[(0, 0), (1, 3)]).unwrap();
        let a = y.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let src = x.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        for i in 0..3 {
            for j in 0..4 {
                assert_eq!(a[i * 4 + j], src[i * 4 + j]);
                let (si, sj) = ((i + 3 - 1) % 3, (j + 4 - 3) % 4);
                assert_eq!(a[12 + i * 4 + j], src[12 + si * 4 + sj]);
            }
        }
        let offs = roll_offsets(&[1, 2, 3, 4, 5, 6, 7, 8], 32);
        assert!(offs.iter().all(|&(r, c)| r < 32 && c < 32));
        assert!(offs.windows(2).any(|w| w[0] != w[1]));
    }

    #[test]
    fn each_item_moves_by_its_own_offset() -> Result<()> {
        let x = Tensor::arange(0f32, 18., &Device::Cpu)?.reshape((2, 1, 3, 3))?;
        let y = roll_per_sample(&x, &[(1, 0), (0, 2)])?;
        let v = y.flatten_all()?.to_vec1::<f32>()?;
        // Item 0: rows down by one; item 1: columns right by two.
        assert_eq!(&v[..9], &[6., 7., 8., 0., 1., 2., 3., 4., 5.]);
        assert_eq!(&v[9..], &[10., 11., 9., 13., 14., 12., 16., 17., 15.]);
        assert!(roll_per_sample(&x, &[(0, 0)]).is_err());
        Ok(())
    }

    #[test]
    fn maps_roll_alike() -> photomat_core::Result<()> {
        let x = Tensor::arange(0f32, 18., &Device::Cpu)?.reshape((2, 1, 3, 3))?;
        let mut maps = MaterialMaps::new();
        maps.insert("roughness", x.clone());
        maps.insert("height", (&x * 2.0)?);
        let offsets = [(2, 1), (1, 1)];
        let rolled = roll_maps(&maps, &offsets)?;
        let direct = roll_per_sample(&x, &offsets)?;
        let values = |t: &Tensor| t.flatten_all()?.to_vec1::<f32>();
        assert_eq!(values(rolled.get("roughness")?)?, values(&direct)?);
        assert_eq!(values(rolled.get("height")?)?, values(&(&direct * 2.0)?)?);
        Ok(())
    }

    #[test]
    fn window_is_the_top_left_of_the_roll() -> Result<()> {
        let x = Tensor::arange(0f64, 2.0 * 3.0 * 6.0 * 7.0, &Device::Cpu)?.reshape((2, 3, 6, 7))?;
        let offsets = [(5, 1), (0, 6)];
        let rolled = roll_per_sample(&x, &offsets)?;
        let window = window_per_sample(&x, &offsets, (4, 5))?;
        let expected = rolled.narrow(2, 0, 4)?.narrow(3, 0, 5)?;
        // Copies of the same values: exactly equal.
        let diff = (window - expected)?.abs()?.max_all()?.to_scalar::<f64>()?;
        assert_eq!(diff, 0.0);
        Ok(())
    }
}
