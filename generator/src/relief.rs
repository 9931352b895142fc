//! Relief in the neural material: M shades every texel in the frame of a normal that comes from
//! a learned height channel of F (`docs/neural-models.md`, "Relief").
//!
//! PhotoMat's M is a per-texel MLP on `F ‖ ω` (paper §3): nothing ties a texel's response to the
//! light to its neighbours', so relief — a field of tilted normals, whose shading under a moved
//! light follows the height's derivative along the light's motion — is one of many per-texel
//! light dependences M may learn, and at CPU scale it learns none: in the bundled model's
//! renders under two lights the log-ratio's detail follows the texture itself (window R² 0.33),
//! not its derivative along the lights' axis (0.009, against 0.012 across it), while the
//! simulator's photos of fabric, leather, paint, stone and tiles give 0.18–0.50 along
//! (`docs/benchmarks/relief.md`, "Does M's relighting show relief?"). An estimator fitted to such
//! renders rightly keeps its normals flat.
//!
//! With relief on, a zero-initialised linear projection of the features gives a height
//! `h = Σ_c a_c F_c` (in texels); its central differences give the normal
//! `n = normalize(−∂h/∂x, −∂h/∂y, 1)` (x right, y up: `docs/conventions.md`), and M reads ω
//! expressed in the frame of n — `Q·ω` with Q the smallest rotation taking n to +z — instead of ω
//! (its lobes `ω_z^s` then are `(n·ω)^s`, Blinn–Phong peaks around the tilted normal under a
//! collocated flash). Relief is then the one light dependence that moves with the neighbours,
//! and its height is a linear readout of F for the estimator. With `a = 0` (the start, or a
//! model trained before the option) M is exactly the paper's.
//!
//! Edges: a whole material is periodic, so its differences wrap around ([`Edges::Wrap`]); a
//! window cut from a larger field (the spatial trainer's patches) has no neighbour beyond its
//! border, so there the border texel repeats itself ([`Edges::Clamp`]) rather than reading the
//! opposite edge of an unrelated window.
//!
//! Parameter name under M's `vb`: `relief.weight` (1, feature_channels), zero at creation.

use candle_core::{Result, Tensor};
use candle_nn::{Init, VarBuilder};

/// How the height's differences treat the border of the feature field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edges {
    /// The field is one period of a tileable material: differences wrap around.
    Wrap,
    /// The field is a window of a larger one: the border texel stands for its missing
    /// neighbour (a one-sided difference, halved).
    Clamp,
}

/// The learned height projection of F.
#[derive(Debug, Clone)]
pub struct Relief {
    /// Stored weight (1, C); the effective one is `weight · gain` (equalised learning rate).
    weight: Tensor,
    gain: f64,
}

impl Relief {
    /// A projection of `feature_channels` features, zero at creation, with the equalised-lr
    /// gain `lr_multiplier / √C` of M's other layers ([`crate::equalized`]).
    pub fn new(feature_channels: usize, lr_multiplier: f64, vb: VarBuilder) -> Result<Self> {
        let weight = vb.get_with_hints((1, feature_channels), "weight", Init::Const(0.0))?;
        Ok(Self {
            weight,
            gain: lr_multiplier / (feature_channels as f64).sqrt(),
        })
    }

    /// The height field h = Σ_c a_c F_c, in texels.
    ///
    /// # Shapes
    /// features (B, C, H, W) → (B, 1, H, W).
    pub fn height(&self, features: &Tensor) -> Result<Tensor> {
        let (b, c, h, w) = features.dims4()?;
        let a = (&self.weight * self.gain)?;
        a.broadcast_matmul(&features.reshape((b, c, h * w))?)?
            .reshape((b, 1, h, w))
    }

    /// ω in the frame of the relief's normal at every texel (module docs).
    ///
    /// # Shapes
    /// features (B, C, H, W), omega (B, 3, H, W) → (B, 3, H, W).
    pub fn local_omega(&self, features: &Tensor, omega: &Tensor, edges: Edges) -> Result<Tensor> {
        let normal = normals(&self.height(features)?, edges)?;
        into_normal_frame(&normal, omega)
    }
}

/// Unit normals of a height field in texel units: `normalize(−∂h/∂x, −∂h/∂y, 1)` by central
/// differences, rows growing towards −y.
///
/// # Shapes
/// (B, 1, H, W) → (B, 3, H, W).
pub fn normals(height: &Tensor, edges: Edges) -> Result<Tensor> {
    let (east, west, north, south) = match edges {
        Edges::Wrap => (
            height.roll(-1, 3)?,
            height.roll(1, 3)?,
            height.roll(1, 2)?,
            height.roll(-1, 2)?,
        ),
        Edges::Clamp => (
            shift_clamped(height, 3, 1)?,
            shift_clamped(height, 3, -1)?,
            shift_clamped(height, 2, -1)?,
            shift_clamped(height, 2, 1)?,
        ),
    };
    let dx = ((east - west)? * 0.5)?;
    let dy = ((north - south)? * 0.5)?;
    let nz = dx.ones_like()?;
    let v = Tensor::cat(&[dx.neg()?, dy.neg()?, nz], 1)?;
    // |v| ≥ 1 (its z is 1): the division is always safe.
    v.broadcast_div(&v.sqr()?.sum_keepdim(1)?.sqrt()?)
}

/// `x` read one texel further along `dim` (`by` = +1: the next texel, −1: the previous), the
/// border texel repeated where that leaves the field.
fn shift_clamped(x: &Tensor, dim: usize, by: i32) -> Result<Tensor> {
    let n = x.dim(dim)?;
    if n < 2 {
        return Ok(x.clone());
    }
    if by > 0 {
        Tensor::cat(&[x.narrow(dim, 1, n - 1)?, x.narrow(dim, n - 1, 1)?], dim)
    } else {
        Tensor::cat(&[x.narrow(dim, 0, 1)?, x.narrow(dim, 0, n - 1)?], dim)
    }
}

/// `Q·ω` with Q the smallest rotation taking the unit normal n to +z (Rodrigues' formula about
/// n × z): `Q·ω = c·ω + u × ω + u (u·ω)/(1 + c)` with `u = (n_y, −n_x, 0)`, `c = n_z`, so the
/// result's z is n·ω and n = +z leaves ω unchanged. n_z > 0 for every normal of [`normals`],
/// so `1 + c > 1`.
///
/// # Shapes
/// normal (B, 3, H, W), omega (B, 3, H, W) → (B, 3, H, W).
pub fn into_normal_frame(normal: &Tensor, omega: &Tensor) -> Result<Tensor> {
    let (nx, ny, nz) = (
        normal.narrow(1, 0, 1)?,
        normal.narrow(1, 1, 1)?,
        normal.narrow(1, 2, 1)?,
    );
    let (wx, wy, wz) = (
        omega.narrow(1, 0, 1)?,
        omega.narrow(1, 1, 1)?,
        omega.narrow(1, 2, 1)?,
    );
    // (u·ω)/(1 + c) with u = (n_y, −n_x, 0).
    let along = ((&ny * &wx)? - (&nx * &wy)?)?.div(&(&nz + 1.0)?)?;
    let x = (((&nz * &wx)? - (&nx * &wz)?)? + (&ny * &along)?)?;
    let y = (((&nz * &wy)? - (&ny * &wz)?)? - (&nx * &along)?)?;
    let z = (((&nz * &wz)? + (&nx * &wx)?)? + (&ny * &wy)?)?;
    Tensor::cat(&[x, y, z], 1)
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};
    use photomat_core::rng::pseudo_random;

    use super::*;

    fn unit(v: [f64; 3]) -> [f64; 3] {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    }

    fn field(v: [f64; 3]) -> Result<Tensor> {
        Tensor::new(&v, &Device::Cpu)?.reshape((1, 3, 1, 1))
    }

    fn values(t: &Tensor) -> Result<Vec<f64>> {
        t.flatten_all()?.to_vec1::<f64>()
    }

    #[test]
    fn rotation_takes_the_normal_to_z_and_keeps_angles() -> Result<()> {
        let n = unit([0.3, -0.2, 0.9]);
        let normal = field(n)?;
        // n itself goes to +z.
        let z = values(&into_normal_frame(&normal, &normal)?)?;
        for (got, want) in z.iter().zip([0.0, 0.0, 1.0]) {
            assert!((got - want).abs() < 1e-12, "{z:?}");
        }
        // Another direction keeps its length and its angle to n (the new z is n·ω).
        let w = unit([-0.4, 0.5, 0.7]);
        let r = values(&into_normal_frame(&normal, &field(w)?)?)?;
        let len = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-12);
        let dot = n[0] * w[0] + n[1] * w[1] + n[2] * w[2];
        assert!((r[2] - dot).abs() < 1e-12);
        // A flat normal changes nothing.
        let flat = values(&into_normal_frame(&field([0.0, 0.0, 1.0])?, &field(w)?)?)?;
        for (got, want) in flat.iter().zip(w) {
            assert!((got - want).abs() < 1e-12);
        }
        Ok(())
    }

    #[test]
    fn a_ramp_tilts_every_normal_against_its_slope() -> Result<()> {
        // h = 0.2·x − 0.1·row: ∂h/∂x = 0.2, ∂h/∂y = +0.1 (rows grow towards −y).
        let (rows, cols) = (5usize, 6usize);
        let h: Vec<f64> = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| 0.2 * c as f64 - 0.1 * r as f64))
            .collect();
        let h = Tensor::from_vec(h, (1, 1, rows, cols), &Device::Cpu)?;
        let want = unit([-0.2, -0.1, 1.0]);
        let n = normals(&h, Edges::Clamp)?;
        // Interior texels: the exact slope; border texels see half of it along their edge.
        let inner = values(&n.narrow(2, 1, rows - 2)?.narrow(3, 1, cols - 2)?)?;
        let count = (rows - 2) * (cols - 2);
        for (axis, want) in want.iter().enumerate() {
            for got in &inner[axis * count..(axis + 1) * count] {
                assert!((got - want).abs() < 1e-12, "axis {axis}: {got} vs {want}");
            }
        }
        let corner = values(&n.narrow(2, 0, 1)?.narrow(3, 0, 1)?)?;
        let half = unit([-0.1, -0.05, 1.0]);
        for (got, want) in corner.iter().zip(half) {
            assert!((got - want).abs() < 1e-12);
        }
        Ok(())
    }

    #[test]
    fn wrapped_normals_of_a_periodic_height_shift_with_it() -> Result<()> {
        let h = pseudo_random((1, 1, 8, 8), 3, DType::F64, &Device::Cpu)?;
        let shifted = h.roll(3, 3)?.roll(-2, 2)?;
        let a = normals(&h, Edges::Wrap)?.roll(3, 3)?.roll(-2, 2)?;
        let b = normals(&shifted, Edges::Wrap)?;
        assert_eq!((a - b)?.abs()?.max_all()?.to_scalar::<f64>()?, 0.0);
        Ok(())
    }

    #[test]
    fn a_zero_projection_leaves_omega_unchanged_and_passes_gradient() -> Result<()> {
        let vars = candle_nn::VarMap::new();
        let vb = VarBuilder::from_varmap(&vars, DType::F64, &Device::Cpu);
        let relief = Relief::new(4, 1.0, vb.pp("relief"))?;
        let features = pseudo_random((2, 4, 6, 6), 1, DType::F64, &Device::Cpu)?;
        let up = Tensor::new(&[0.0, 0.0, 3.0], &Device::Cpu)?.reshape((1, 3, 1, 1))?;
        let raw = pseudo_random((2, 3, 6, 6), 2, DType::F64, &Device::Cpu)?.broadcast_add(&up)?;
        let omega = raw.broadcast_div(&raw.sqr()?.sum_keepdim(1)?.sqrt()?)?;
        let local = relief.local_omega(&features, &omega, Edges::Clamp)?;
        assert_eq!(
            (&local - &omega)?.abs()?.max_all()?.to_scalar::<f64>()?,
            0.0
        );
        // The height's weight gets a gradient at zero: the relief can start to grow.
        let weight: Var = vars.data().lock().unwrap()["relief.weight"].clone();
        let loss = local.narrow(1, 2, 1)?.sqr()?.sum_all()?;
        let grads = loss.backward()?;
        let g = grads.get(weight.as_tensor()).expect("weight gradient");
        assert!(g.abs()?.max_all()?.to_scalar::<f64>()? > 0.0);
        Ok(())
    }
}
