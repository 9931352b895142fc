//! Per-sample wrap-around rolls for the fine-tune (DESIGN §4: "randomly roll the decoded maps
//! per sample (wrap-around) before rendering under the same light"), applied identically to
//! the maps and to F so that M sees the same shifted material.

use candle_core::{Result, Tensor, bail};
use photomat_core::MaterialMaps;

/// Rolls batch item b of `x` by `rolls[b]` = (rows, columns), wrapping around: texel (i, j)
/// moves to ((i + rows) mod H, (j + cols) mod W), as `torch.roll`.
///
/// # Shapes
/// (B, C, H, W) with B = `rolls.len()` → (B, C, H, W).
pub fn roll_per_sample(x: &Tensor, rolls: &[(usize, usize)]) -> Result<Tensor> {
    let (b, _c, _h, _w) = x.dims4()?;
    if b != rolls.len() {
        bail!("{} rolls for a batch of {b}", rolls.len());
    }
    let items = rolls
        .iter()
        .enumerate()
        .map(|(i, &(dy, dx))| x.narrow(0, i, 1)?.roll(dy as i32, 2)?.roll(dx as i32, 3))
        .collect::<Result<Vec<_>>>()?;
    Tensor::cat(&items, 0)
}

/// [`roll_per_sample`] on every map.
pub fn roll_maps(maps: &MaterialMaps, rolls: &[(usize, usize)]) -> Result<MaterialMaps> {
    let mut out = MaterialMaps::new();
    for (name, map) in maps.iter() {
        out.insert(name, roll_per_sample(map, rolls)?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

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
}
