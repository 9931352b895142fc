//! The random per-sample roll of the neural material in tileable mode (DESIGN §4, TileGen's
//! strategy as used by the PhotoMat reference): before M relights a generated F, each sample
//! is shifted by its own random (Δrow, Δcol) with wrap-around, so that D sees every part of
//! the periodic material — seams included — under every light position, and G cannot hide a
//! seam at a fixed place.

use candle_core::{Result, Tensor, bail};
use photomat_kernels::SplitMix64;

/// Per-sample offsets (Δrow, Δcol), uniform in `0..size` each, one pair per seed.
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

/// Rolls sample b by `offsets[b]`: output pixel (i, j) is input pixel
/// ((i − Δrow) mod H, (j − Δcol) mod W) (`torch.roll` semantics). Differentiable.
///
/// # Shapes
/// (B, C, H, W), B offsets → (B, C, H, W).
pub fn roll_per_sample(x: &Tensor, offsets: &[(usize, usize)]) -> Result<Tensor> {
    let (b, _c, _h, _w) = x.dims4()?;
    if offsets.len() != b {
        bail!("roll: {} offsets for a batch of {b}", offsets.len());
    }
    let parts = offsets
        .iter()
        .enumerate()
        .map(|(i, &(dr, dc))| x.narrow(0, i, 1)?.roll(dr as i32, 2)?.roll(dc as i32, 3))
        .collect::<Result<Vec<_>>>()?;
    Tensor::cat(&parts, 0)
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
}
