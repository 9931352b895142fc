//! The GAN losses of StyleGAN2 (Karras et al. 2020; StyleGAN2-ADA `loss.py`,
//! `StyleGAN2Loss`): the non-saturating logistic losses of G and D (Goodfellow et al. 2014)
//! written with softplus, and the lazy R1 penalty (Mescheder et al. 2018) scaled as in the
//! reference.
//!
//! - G: `mean softplus(−D(G(z), ω))`;
//! - D: `mean softplus(D(G(z), ω)) + mean softplus(−D(x, ω)) + λ · mean softplus(D(x, ω'))`,
//!   the last term the matching-aware discriminator of Reed et al. 2016 (§4.1): a real image
//!   under lights ω' drawn for another sample is a fake, so D learns what the light does to
//!   an image and M cannot ignore ω (λ = 0 gives StyleGAN2's loss exactly);
//! - R1 (every k steps): `mean(‖∇ₓ D(x, ω)‖²) · γ/2 · k` — multiplied by the interval k so
//!   that the penalty's average weight per step is γ/2 (lazy regularisation, StyleGAN2 §B).

use candle_core::{Result, Tensor};

/// `softplus(x) = log(1 + eˣ)`, computed as `max(x, 0) + log(1 + e^{−|x|})`: the exponential
/// never overflows, whatever the logit.
///
/// # Shapes
/// any → same.
pub fn softplus(x: &Tensor) -> Result<Tensor> {
    x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?
}

/// G's non-saturating loss from D's logits on fakes.
///
/// # Shapes
/// (B, 1) → scalar.
pub fn generator_loss(fake_logits: &Tensor) -> Result<Tensor> {
    softplus(&fake_logits.neg()?)?.mean_all()
}

/// D's logistic loss from its logits on fakes and reals, plus `mismatch_weight` λ times the
/// loss of reals under mismatched lights as fakes (module docs) when those logits are given.
///
/// # Shapes
/// (B, 1), (B', 1), optionally (B'', 1) → scalar.
pub fn discriminator_loss(
    real_logits: &Tensor,
    fake_logits: &Tensor,
    mismatch: Option<(&Tensor, f64)>,
) -> Result<Tensor> {
    let loss = (softplus(fake_logits)?.mean_all()? + softplus(&real_logits.neg()?)?.mean_all()?)?;
    match mismatch {
        Some((logits, weight)) => loss + (softplus(logits)?.mean_all()? * weight)?,
        None => Ok(loss),
    }
}

/// The lazy R1 loss from the per-sample penalties of
/// [`crate::Discriminator::r1_penalty`]: `mean(r1) · γ/2 · interval`.
///
/// # Shapes
/// (B) → scalar.
pub fn r1_loss(penalty: &Tensor, gamma: f64, interval: usize) -> Result<Tensor> {
    penalty.mean_all()? * (gamma / 2.0 * interval as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn values(t: &Tensor) -> Vec<f64> {
        t.flatten_all().unwrap().to_vec1::<f64>().unwrap()
    }

    #[test]
    fn softplus_is_stable_and_exact() {
        let x = Tensor::new(&[-800.0f64, -2.0, 0.0, 3.0, 800.0], &Device::Cpu).unwrap();
        let y = values(&softplus(&x).unwrap());
        let expect = [
            0.0,
            (1.0 + (-2f64).exp()).ln(),
            2f64.ln(),
            (1.0 + 3f64.exp()).ln(),
            800.0,
        ];
        for (a, b) in y.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{y:?}");
        }
    }

    #[test]
    fn losses_match_closed_forms_and_gradients() {
        let dev = Device::Cpu;
        let real = Var::new(&[[1.0f64], [-0.5]], &dev).unwrap();
        let fake = Var::new(&[[0.25f64], [2.0]], &dev).unwrap();
        let sp = |v: f64| (1.0 + v.exp()).ln();
        let d = discriminator_loss(&real, &fake, None).unwrap();
        let expect = (sp(0.25) + sp(2.0)) / 2.0 + (sp(-1.0) + sp(0.5)) / 2.0;
        assert!((d.to_scalar::<f64>().unwrap() - expect).abs() < 1e-12);
        // ∂/∂fake_i = σ(fake_i)/B, ∂/∂real_i = −σ(−real_i)/B.
        let grads = d.backward().unwrap();
        let sig = |v: f64| 1.0 / (1.0 + (-v).exp());
        let gf = values(grads.get(&fake).unwrap());
        let gr = values(grads.get(&real).unwrap());
        assert!((gf[1] - sig(2.0) / 2.0).abs() < 1e-12);
        assert!((gr[0] + sig(-1.0) / 2.0).abs() < 1e-12);

        let g = generator_loss(&fake).unwrap().to_scalar::<f64>().unwrap();
        assert!((g - (sp(-0.25) + sp(-2.0)) / 2.0).abs() < 1e-12);

        // The mismatch term adds λ · mean softplus(wrong), with gradient λ·σ(wrong_i)/B.
        let wrong = Var::new(&[[-1.5f64], [0.75]], &dev).unwrap();
        let dm = discriminator_loss(&real, &fake, Some((&wrong, 0.5))).unwrap();
        let extra = 0.5 * (sp(-1.5) + sp(0.75)) / 2.0;
        assert!((dm.to_scalar::<f64>().unwrap() - expect - extra).abs() < 1e-12);
        let gw = values(dm.backward().unwrap().get(&wrong).unwrap());
        assert!((gw[1] - 0.5 * sig(0.75) / 2.0).abs() < 1e-12);

        let r1 = Tensor::new(&[2.0f64, 4.0], &dev).unwrap();
        let l = r1_loss(&r1, 0.5, 16).unwrap().to_scalar::<f64>().unwrap();
        assert!((l - 3.0 * 0.25 * 16.0).abs() < 1e-12);
    }
}
