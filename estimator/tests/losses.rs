//! Properties of the estimator losses (`docs/neural-models.md`, "Gram loss"): zero for
//! identical images, Gram gradient against central finite differences in f64, translation
//! invariance of the Gram term over periodic images, and the VGG19 loading path with small
//! synthetic files of the torchvision layout.

use std::collections::HashMap;

use candle_core::{DType, Device, Result, Tensor, Var};
use photomat_core::rng::pseudo_random;
use photomat_estimator::loss::{
    FeatureExtractor, REFERENCE_GRAM_SCALES, VGG19_CONV_INDICES, gram_loss, l1, l1_downsampled,
    load_vgg19, random_features,
};

/// Images in [0, 1] (display-encoded), seeded.
fn image(shape: (usize, usize, usize, usize), seed: u64, dtype: DType) -> Result<Tensor> {
    pseudo_random(shape, seed, DType::F64, &Device::Cpu)?
        .affine(0.5, 0.5)?
        .to_dtype(dtype)
}

fn scalar(t: &Tensor) -> Result<f64> {
    t.to_dtype(DType::F64)?.to_scalar::<f64>()
}

/// Rolls the last two axes by `shift` texels (wrap-around).
fn roll2(x: &Tensor, shift: i32) -> Result<Tensor> {
    x.roll(shift, 2)?.roll(shift, 3)
}

#[test]
fn losses_are_zero_for_identical_images_and_positive_otherwise() -> Result<()> {
    let bank = random_features(1, DType::F32, &Device::Cpu)?;
    let a = image((2, 3, 32, 32), 1, DType::F32)?;
    let b = image((2, 3, 32, 32), 2, DType::F32)?;
    assert_eq!(
        scalar(&gram_loss(&bank, &a, &a, REFERENCE_GRAM_SCALES)?)?,
        0.0
    );
    assert_eq!(scalar(&l1(&a, &a)?)?, 0.0);
    assert_eq!(scalar(&l1_downsampled(&a, &a, 16)?)?, 0.0);
    assert!(scalar(&gram_loss(&bank, &a, &b, REFERENCE_GRAM_SCALES)?)? > 0.0);
    // Independent uniform [0, 1] images: E|a − b| = 1/3.
    let d = scalar(&l1(&a, &b)?)?;
    assert!((d - 1.0 / 3.0).abs() < 0.02, "L1 {d}");
    Ok(())
}

#[test]
fn gram_loss_gradient_matches_finite_differences() -> Result<()> {
    let bank = random_features(5, DType::F64, &Device::Cpu)?;
    let a = Var::from_tensor(&image((1, 3, 8, 8), 3, DType::F64)?)?;
    let b = image((1, 3, 8, 8), 4, DType::F64)?;
    let loss = |x: &Tensor| gram_loss(&bank, x, &b, REFERENCE_GRAM_SCALES);
    let grads = loss(a.as_tensor())?.backward()?;
    let grad = grads
        .get(a.as_tensor())
        .expect("the input receives a gradient")
        .flatten_all()?
        .to_vec1::<f64>()?;
    let base = a.as_tensor().flatten_all()?.to_vec1::<f64>()?;
    let h = 1e-6;
    let mut checked = 0;
    for i in (0..base.len()).step_by(7) {
        let at = |delta: f64| -> Result<f64> {
            let mut v = base.clone();
            v[i] += delta;
            scalar(&loss(&Tensor::from_vec(v, (1, 3, 8, 8), &Device::Cpu)?)?)
        };
        let fd = (at(h)? - at(-h)?) / (2.0 * h);
        // |·| and ReLU kinks are measure-zero; random inputs stay away from them.
        let tol = 1e-6 + 1e-4 * fd.abs().max(grad[i].abs());
        assert!(
            (fd - grad[i]).abs() < tol,
            "texel {i}: backward {} vs finite difference {fd}",
            grad[i]
        );
        checked += 1;
    }
    assert!(grad.iter().any(|g| g.abs() > 1e-8), "gradient is all zero");
    assert!(checked > 20);
    Ok(())
}

#[test]
fn random_bank_gram_is_invariant_to_rolls_of_a_periodic_image() -> Result<()> {
    // With circular padding every stage commutes with rolls by multiples of its stride; at the
    // last stage the pool averages over the whole image. A 64² image rolled by 32 therefore
    // has exactly the same Grams at scales 1, ½ and ¼ (up to float summation order).
    // f64, so that summation order cannot hide a real difference.
    let bank = random_features(2, DType::F64, &Device::Cpu)?;
    let a = image((1, 3, 64, 64), 9, DType::F64)?;
    let gram =
        |b: &Tensor| -> Result<f64> { scalar(&gram_loss(&bank, &a, b, REFERENCE_GRAM_SCALES)?) };
    let rolled = roll2(&a, 32)?;
    let same = gram(&rolled)?;
    let other = gram(&image((1, 3, 64, 64), 10, DType::F64)?)?;
    assert!(
        same < 1e-12 * other,
        "rolled by 32: {same} vs another image {other}"
    );
    // A roll by one texel breaks the pooling grid: close, but no longer exact.
    let shifted = gram(&roll2(&a, 1)?)?;
    assert!(
        shifted > 1e3 * same && shifted < other,
        "rolled by 1: {shifted}"
    );
    // L1 is not translation invariant: the roll changes it.
    assert!(scalar(&l1(&a, &rolled)?)? > 0.1);
    Ok(())
}

#[test]
fn random_bank_is_deterministic_per_seed_and_has_the_documented_stages() -> Result<()> {
    let x = image((1, 3, 32, 32), 1, DType::F32)?;
    let f1 = random_features(3, DType::F32, &Device::Cpu)?.features(&x)?;
    let f2 = random_features(3, DType::F32, &Device::Cpu)?.features(&x)?;
    let f3 = random_features(4, DType::F32, &Device::Cpu)?.features(&x)?;
    let shapes: Vec<Vec<usize>> = f1.iter().map(|t| t.dims().to_vec()).collect();
    assert_eq!(
        shapes,
        [
            vec![1, 16, 16, 16],
            vec![1, 32, 8, 8],
            vec![1, 64, 4, 4],
            vec![1, 64, 2, 2],
            vec![1, 64, 1, 1]
        ]
    );
    for ((a, b), c) in f1.iter().zip(&f2).zip(&f3) {
        assert_eq!(photomat_kernels::testing::max_abs_diff(a, b)?, 0.0);
        assert!(photomat_kernels::testing::max_abs_diff(a, c)? > 0.0);
    }
    // An 8² image (a 32² render at scale ¼) has three stages with at least 2×2 to pool.
    let small = image((1, 3, 8, 8), 1, DType::F32)?;
    assert_eq!(
        random_features(3, DType::F32, &Device::Cpu)?
            .features(&small)?
            .len(),
        3
    );
    Ok(())
}

/// Tensors of a VGG19-shaped file with the given stage widths (torchvision names).
fn vgg_tensors(widths: [usize; 5], prefix: &str) -> Result<HashMap<String, Tensor>> {
    let mut tensors = HashMap::new();
    let mut c_in = 3;
    for (stage, indices) in VGG19_CONV_INDICES.iter().enumerate() {
        for &i in *indices {
            let c = widths[stage];
            let w = pseudo_random((c, c_in, 3, 3), i as u64, DType::F32, &Device::Cpu)?
                .affine((2.0 / (9 * c_in) as f64).sqrt(), 0.0)?;
            tensors.insert(format!("{prefix}{i}.weight"), w);
            tensors.insert(
                format!("{prefix}{i}.bias"),
                Tensor::zeros(c, DType::F32, &Device::Cpu)?,
            );
            c_in = c;
        }
    }
    // The classifier of a full state_dict is ignored.
    tensors.insert(
        "classifier.0.weight".into(),
        Tensor::zeros((2, 2), DType::F32, &Device::Cpu)?,
    );
    Ok(tensors)
}

#[test]
fn vgg19_loads_any_consistent_widths_and_gives_pooled_features() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    for prefix in ["features.", ""] {
        let path = dir.path().join(format!("vgg{}.safetensors", prefix.len()));
        candle_core::safetensors::save(&vgg_tensors([4, 6, 8, 8, 8], prefix)?, &path)?;
        let vgg = load_vgg19(&path, DType::F32, &Device::Cpu)?;
        assert_eq!(vgg.stage_channels(), [4, 6, 8, 8, 8]);
        assert!(vgg.describe().contains("vgg19"));
        let x = image((2, 3, 32, 32), 1, DType::F32)?;
        let f = vgg.features(&x)?;
        let sides: Vec<(usize, usize)> = f.iter().map(|t| (t.dims()[1], t.dims()[3])).collect();
        assert_eq!(sides, [(4, 16), (6, 8), (8, 4), (8, 2), (8, 1)]);
        let y = image((2, 3, 32, 32), 2, DType::F32)?;
        assert!(scalar(&gram_loss(&vgg, &x, &y, REFERENCE_GRAM_SCALES)?)? > 0.0);
        assert_eq!(
            scalar(&gram_loss(&vgg, &x, &x, REFERENCE_GRAM_SCALES)?)?,
            0.0
        );
    }
    Ok(())
}

#[test]
fn vgg19_errors_name_the_file_and_the_tensor() -> anyhow::Result<()> {
    let dir = tempfile::tempdir()?;
    // A mis-named tensor: features.12.weight stored as features.13.weight.
    let mut t = vgg_tensors([4, 6, 8, 8, 8], "features.")?;
    let w = t.remove("features.12.weight").expect("present");
    t.insert("features.13.weight".into(), w);
    let path = dir.path().join("misnamed.safetensors");
    candle_core::safetensors::save(&t, &path)?;
    let err = load_vgg19(&path, DType::F32, &Device::Cpu)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("misnamed.safetensors") && err.contains("features.12.weight"),
        "{err}"
    );

    // Widths inconsistent from layer to layer: features.5 expects 4 input channels.
    let mut t = vgg_tensors([4, 6, 8, 8, 8], "features.")?;
    t.insert(
        "features.5.weight".into(),
        Tensor::zeros((6, 5, 3, 3), DType::F32, &Device::Cpu)?,
    );
    let path = dir.path().join("misshaped.safetensors");
    candle_core::safetensors::save(&t, &path)?;
    let err = load_vgg19(&path, DType::F32, &Device::Cpu)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("misshaped.safetensors")
            && err.contains("features.5.weight")
            && err.contains("[6, 5, 3, 3]"),
        "{err}"
    );

    let missing = dir.path().join("absent.safetensors");
    let err = load_vgg19(&missing, DType::F32, &Device::Cpu)
        .unwrap_err()
        .to_string();
    assert!(err.contains("absent.safetensors"), "{err}");
    Ok(())
}
