//! LeakyReLU as one fused element-wise pass forward and one backward.
//!
//! `f(x) = x` for x > 0, `a·x` otherwise, with PyTorch's derivative `f'(x) = 1` for x > 0 and
//! `a` otherwise (so `a` at exactly 0). The estimator uses slope 0.01 (paper §4
//! "Implementation"; the reference's `nn.LeakyReLU()`), the StyleGAN2 networks 0.2 (DESIGN §4).
//!
//! candle 0.11 element-wise ops allocate per call, and a composite LeakyReLU costs 2–5 ops
//! forward and ≈ 12 backward (`maximum`'s backward builds two masks, divides and accumulates;
//! DESIGN §6). On the CPU this module runs one pass each way through candle custom ops; other
//! devices use the equivalent `max(x, a·x)` composite.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor, bail};

/// LeakyReLU with negative slope `slope` ∈ [0, 1].
///
/// # Shapes
/// Any shape, f32 or f64 on the CPU (any float dtype elsewhere); same shape out.
pub fn leaky_relu(x: &Tensor, slope: f64) -> Result<Tensor> {
    if !(0.0..=1.0).contains(&slope) {
        bail!("leaky_relu: slope {slope} is outside [0, 1]");
    }
    let fused = x.device().is_cpu()
        && matches!(x.dtype(), candle_core::DType::F32 | candle_core::DType::F64);
    if fused {
        x.contiguous()?.apply_op1(LeakyRelu { slope })
    } else {
        // max(x, a·x) equals LeakyReLU for 0 ≤ a ≤ 1 (ties at 0 split the gradient).
        x.maximum(&x.affine(slope, 0.0)?)
    }
}

/// The contiguous slice a layout describes, or an error naming the op.
fn slice<'a, T>(v: &'a [T], layout: &Layout, op: &str) -> Result<&'a [T]> {
    match layout.contiguous_offsets() {
        Some((start, end)) => Ok(&v[start..end]),
        None => bail!("{op}: expected a contiguous tensor"),
    }
}

struct LeakyRelu {
    slope: f64,
}

impl CustomOp1 for LeakyRelu {
    fn name(&self) -> &'static str {
        "leaky-relu"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let out = match s {
            CpuStorage::F32(v) => {
                let a = self.slope as f32;
                let v = slice(v, l, self.name())?;
                CpuStorage::F32(v.iter().map(|&x| if x > 0.0 { x } else { a * x }).collect())
            }
            CpuStorage::F64(v) => {
                let a = self.slope;
                let v = slice(v, l, self.name())?;
                CpuStorage::F64(v.iter().map(|&x| if x > 0.0 { x } else { a * x }).collect())
            }
            other => bail!("leaky-relu: unsupported dtype {:?}", other.dtype()),
        };
        Ok((out, l.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let g = grad
            .contiguous()?
            .apply_op2_no_bwd(&x.contiguous()?, &LeakyReluGrad { slope: self.slope })?;
        Ok(Some(g))
    }
}

/// `grad · f'(x)`: (grad, x) → grad where x > 0, `slope · grad` elsewhere.
struct LeakyReluGrad {
    slope: f64,
}

impl CustomOp2 for LeakyReluGrad {
    fn name(&self) -> &'static str {
        "leaky-relu-grad"
    }

    fn cpu_fwd(
        &self,
        g: &CpuStorage,
        lg: &Layout,
        x: &CpuStorage,
        lx: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        if lg.shape() != lx.shape() {
            bail!(
                "leaky-relu-grad: gradient {:?} and input {:?} differ",
                lg.shape(),
                lx.shape()
            );
        }
        let out = match (g, x) {
            (CpuStorage::F32(g), CpuStorage::F32(x)) => {
                let a = self.slope as f32;
                let (g, x) = (slice(g, lg, self.name())?, slice(x, lx, self.name())?);
                CpuStorage::F32(
                    g.iter()
                        .zip(x)
                        .map(|(&g, &x)| if x > 0.0 { g } else { a * g })
                        .collect(),
                )
            }
            (CpuStorage::F64(g), CpuStorage::F64(x)) => {
                let a = self.slope;
                let (g, x) = (slice(g, lg, self.name())?, slice(x, lx, self.name())?);
                CpuStorage::F64(
                    g.iter()
                        .zip(x)
                        .map(|(&g, &x)| if x > 0.0 { g } else { a * g })
                        .collect(),
                )
            }
            (g, x) => bail!(
                "leaky-relu-grad: unsupported dtypes {:?}, {:?}",
                g.dtype(),
                x.dtype()
            ),
        };
        Ok((out, lg.shape().clone()))
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};

    use super::*;
    use crate::testing::{max_abs_diff, pseudo_random};

    #[test]
    fn leaky_relu_matches_candle_nn_forward() -> Result<()> {
        for dtype in [DType::F32, DType::F64] {
            let x = pseudo_random((2, 3, 4, 5), 1, dtype, &Device::Cpu)?;
            let expected = candle_nn::ops::leaky_relu(&x, 0.01)?;
            assert_eq!(max_abs_diff(&leaky_relu(&x, 0.01)?, &expected)?, 0.0);
            // Non-contiguous input (a transposed view) gives the transposed result.
            let xt = x.transpose(2, 3)?;
            assert_eq!(
                max_abs_diff(&leaky_relu(&xt, 0.01)?, &expected.transpose(2, 3)?)?,
                0.0
            );
        }
        Ok(())
    }

    #[test]
    fn leaky_relu_gradient_is_one_or_the_slope() -> Result<()> {
        // L = Σ g ⊙ f(x)  ⇒  ∂L/∂x = g where x > 0, a·g elsewhere (PyTorch's convention,
        // including a at exactly 0).
        let a = 0.2;
        let mut values = pseudo_random((1, 2, 3, 4), 2, DType::F64, &Device::Cpu)?
            .flatten_all()?
            .to_vec1::<f64>()?;
        values[5] = 0.0;
        let x = Var::from_tensor(&Tensor::from_vec(
            values.clone(),
            (1, 2, 3, 4),
            &Device::Cpu,
        )?)?;
        let g = pseudo_random((1, 2, 3, 4), 3, DType::F64, &Device::Cpu)?;
        let store = (leaky_relu(x.as_tensor(), a)? * &g)?
            .sum_all()?
            .backward()?;
        let got = store
            .get(x.as_tensor())
            .expect("gradient")
            .flatten_all()?
            .to_vec1::<f64>()?;
        let g = g.flatten_all()?.to_vec1::<f64>()?;
        for ((got, g), x) in got.iter().zip(&g).zip(&values) {
            let expected = if *x > 0.0 { *g } else { a * g };
            assert_eq!(*got, expected, "x = {x}");
        }
        Ok(())
    }

    #[test]
    fn leaky_relu_composite_path_agrees() -> Result<()> {
        // f16 is not fused on the CPU and takes the max(x, a·x) path; a slope of ½ and inputs
        // k/8 keep every value exact in f16.
        let x = Tensor::new(&[-1.0f32, -0.375, 0.0, 0.25, 2.0], &Device::Cpu)?;
        let y = leaky_relu(&x.to_dtype(DType::F16)?, 0.5)?.to_dtype(DType::F32)?;
        assert_eq!(y.to_vec1::<f32>()?, [-0.5, -0.1875, 0.0, 0.25, 2.0]);
        assert_eq!(
            leaky_relu(&x, 0.5)?.to_vec1::<f32>()?,
            [-0.5, -0.1875, 0.0, 0.25, 2.0]
        );
        Ok(())
    }

    #[test]
    fn leaky_relu_rejects_slopes_outside_unit_interval() {
        let x = Tensor::zeros(4, DType::F32, &Device::Cpu).expect("tensor");
        assert!(leaky_relu(&x, 1.5).is_err());
        assert!(leaky_relu(&x, -0.1).is_err());
    }
}
