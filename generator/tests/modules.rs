//! Shapes, parameter counts and properties of G, M and D on tiny configurations.

use anyhow::Result;
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_core::{FlashGeometry, Highlight};
use photomat_generator::fir::{
    blur_matrix, downsample_matrix, downsample2d, upsample_matrix, upsample2d,
};
use photomat_generator::padding::Padding;
use photomat_generator::{
    Discriminator, Generator, GeneratorConfig, NoiseInput, Relight, mix_styles, parameter_count,
    seeded_uniform,
};

fn tiny(resolution: usize, channel_multiplier: f64) -> GeneratorConfig {
    GeneratorConfig {
        resolution,
        channel_multiplier,
        ..Default::default()
    }
}

fn max_abs(t: &Tensor) -> candle_core::Result<f64> {
    t.abs()?
        .flatten_all()?
        .max(0)?
        .to_dtype(DType::F64)?
        .to_scalar::<f64>()
}

/// G's trainable parameters by the StyleGAN2 formula (per block: modulated convs with affine
/// w_dim → C_in, weight, noise strength, bias; toFeature with affine, 1×1 weight, bias).
fn g_params_formula(cfg: &GeneratorConfig) -> usize {
    let w = cfg.latent_dim;
    let mapping = cfg.mapping_depth * (w * w + w);
    let layer = |ci: usize, co: usize| (w * ci + ci) + co * ci * 9 + 1 + co;
    let tofeat = |ci: usize| (w * ci + ci) + cfg.feature_channels * ci + cfg.feature_channels;
    let c = |r: usize| cfg.channels_at(r);
    let mut synthesis = c(4) * 16 + layer(c(4), c(4)) + tofeat(c(4));
    let mut r = 8;
    while r <= cfg.resolution {
        synthesis += layer(c(r / 2), c(r)) + layer(c(r), c(r)) + tofeat(c(r));
        r *= 2;
    }
    mapping + synthesis
}

/// D's parameters by the StyleGAN2 formula.
fn d_params_formula(cfg: &GeneratorConfig) -> usize {
    let c = |r: usize| cfg.channels_at(r);
    let conv =
        |ci: usize, co: usize, k: usize, bias: bool| co * ci * k * k + if bias { co } else { 0 };
    let mut total = conv(6, c(cfg.resolution), 1, true);
    let mut r = cfg.resolution;
    while r > 4 {
        total += conv(c(r), c(r), 3, true)
            + conv(c(r), c(r / 2), 3, true)
            + conv(c(r), c(r / 2), 1, false);
        r /= 2;
    }
    let c4 = c(4);
    total + conv(c4 + 1, c4, 3, true) + (16 * c4 * c4 + c4) + (c4 + 1)
}

#[test]
fn generator_shapes_and_parameter_counts() -> Result<()> {
    let dev = Device::Cpu;
    for (res, mult) in [(32, 1.0 / 64.0), (64, 1.0 / 32.0), (128, 1.0 / 64.0)] {
        let cfg = tiny(res, mult);
        let vm = VarMap::new();
        let vb = VarBuilder::from_varmap(&vm, DType::F32, &dev);
        let g = Generator::new(&cfg, vb.pp("g"))?;
        let z = seeded_uniform((2, cfg.latent_dim), 1, DType::F32, &dev)?;
        let ws = g.ws(&z, 1.0)?;
        assert_eq!(ws.dims3()?, (2, 2 * res.trailing_zeros() as usize - 2, 512));
        let f = g.synthesis().forward(&ws, &NoiseInput::Random)?;
        assert_eq!(f.dims4()?, (2, 32, res, res));
        assert_eq!(
            parameter_count(&vm, false),
            g_params_formula(&cfg),
            "G {res}² ×{mult}"
        );
        assert_eq!(
            parameter_count(&vm, true),
            g_params_formula(&cfg) + 512,
            "w_avg buffer"
        );
        let dvm = VarMap::new();
        let d = Discriminator::new(&cfg, VarBuilder::from_varmap(&dvm, DType::F32, &dev))?;
        assert_eq!(
            parameter_count(&dvm, true),
            d_params_formula(&cfg),
            "D {res}² ×{mult}"
        );
        let img = seeded_uniform((2, 3, res, res), 2, DType::F32, &dev)?;
        assert_eq!(d.forward(&img, &img)?.dims2()?, (2, 1));
    }
    Ok(())
}

#[test]
fn parameter_counts_of_the_small_config_by_hand() -> Result<()> {
    // 32², multiplier 1/64: 8 channels at every block. By hand:
    //   mapping 2·(512·512 + 512) = 525 312
    //   conv layer 8→8: affine 512·8 + 8 = 4104, weight 8·8·9 = 576, noise 1, bias 8 = 4689
    //   toFeature: affine 4104 + weight 32·8 = 256 + bias 32 = 4392
    //   b4 = const 8·16 + 4689 + 4392 = 9209; b8, b16, b32 = 4689·2 + 4392 = 13 770 each
    //   G = 525 312 + 9209 + 3·13 770 = 575 831 (+ 512 for the w_avg buffer)
    //   M = (35·64 + 64) + 6·(64·64 + 64) + (64·3 + 3) = 2304 + 24 960 + 195 = 27 459
    //   D: b32 = fromrgb 6·8 + 8 + conv0 584 + conv1 584 + skip 64 = 1288; b16 = b8 = 1232;
    //      epilogue conv 9·8·9 + 8 = 656, fc 128·8 + 8 = 1032, out 9 → D = 5449
    let cfg = tiny(32, 1.0 / 64.0);
    let dev = Device::Cpu;
    let count = |build: &dyn Fn(VarBuilder) -> candle_core::Result<()>| -> Result<(usize, usize)> {
        let vm = VarMap::new();
        build(VarBuilder::from_varmap(&vm, DType::F32, &dev))?;
        Ok((parameter_count(&vm, false), parameter_count(&vm, true)))
    };
    assert_eq!(
        count(&|vb| Generator::new(&cfg, vb).map(|_| ()))?,
        (575_831, 576_343)
    );
    assert_eq!(
        count(&|vb| Relight::new(&cfg, vb).map(|_| ()))?,
        (27_459, 27_459)
    );
    assert_eq!(
        count(&|vb| Discriminator::new(&cfg, vb).map(|_| ()))?,
        (5449, 5449)
    );
    Ok(())
}

#[test]
fn truncation_psi_zero_gives_w_avg_and_w_avg_tracks_the_mean() -> Result<()> {
    let dev = Device::Cpu;
    let cfg = tiny(32, 1.0 / 64.0);
    let vm = VarMap::new();
    let g = Generator::new(&cfg, VarBuilder::from_varmap(&vm, DType::F32, &dev))?;
    // From w_avg = 0, one update with batch mean m gives (1 − 0.995)·m.
    let w = seeded_uniform((3, 512), 4, DType::F32, &dev)?;
    g.mapping().update_w_avg(&w)?;
    let expected = (w.mean(0)? * 0.005)?;
    assert!(max_abs(&(g.mapping().w_avg() - &expected)?)? < 1e-7);
    let z = seeded_uniform((2, 512), 5, DType::F32, &dev)?;
    let ws = g.ws(&z, 0.0)?;
    let avg = g
        .mapping()
        .w_avg()
        .reshape((1, 1, 512))?
        .broadcast_as(ws.shape())?;
    assert_eq!(max_abs(&(&ws - avg)?)?, 0.0);
    // ψ = 1 leaves w untouched, and w differs from w_avg.
    let ws1 = g.ws(&z, 1.0)?;
    assert!(max_abs(&(&ws1 - &ws)?)? > 1e-3);
    Ok(())
}

#[test]
fn style_mixing_takes_layers_from_both_latents() -> Result<()> {
    let dev = Device::Cpu;
    let a = Tensor::zeros((2, 8, 4), DType::F32, &dev)?;
    let b = Tensor::ones((2, 8, 4), DType::F32, &dev)?;
    let m = mix_styles(&a, &b, 3)?;
    let per_layer = m.mean((0, 2))?.to_vec1::<f32>()?;
    assert_eq!(per_layer, [0., 0., 0., 1., 1., 1., 1., 1.]);
    assert!(mix_styles(&a, &b, 9).is_err());
    // Mixed styles drive the generator: F changes when the fine layers come from another z.
    let cfg = tiny(32, 1.0 / 64.0);
    let vm = VarMap::new();
    let g = Generator::new(&cfg, VarBuilder::from_varmap(&vm, DType::F32, &dev))?;
    let wa = g.ws(&seeded_uniform((1, 512), 6, DType::F32, &dev)?, 1.0)?;
    let wb = g.ws(&seeded_uniform((1, 512), 7, DType::F32, &dev)?, 1.0)?;
    let fa = g.synthesis().forward(&wa, &NoiseInput::Zero)?;
    let fm = g
        .synthesis()
        .forward(&mix_styles(&wa, &wb, 4)?, &NoiseInput::Zero)?;
    assert!(max_abs(&(fa - fm)?)? > 1e-4);
    Ok(())
}

#[test]
fn relight_output_shape_range_and_light_dependence() -> Result<()> {
    let dev = Device::Cpu;
    let cfg = tiny(32, 1.0 / 64.0);
    let vm = VarMap::new();
    let m = Relight::new(&cfg, VarBuilder::from_varmap(&vm, DType::F32, &dev))?;
    let f = seeded_uniform((2, 32, 32, 32), 8, DType::F32, &dev)?;
    let lights = |x: f64| [Highlight::new(x, 0.0), Highlight::new(0.0, x)];
    let omega_a = FlashGeometry::new(&lights(0.3), 32, DType::F32, &dev)?.omega;
    let omega_b = FlashGeometry::new(&lights(-0.3), 32, DType::F32, &dev)?.omega;
    let a = m.forward(&f, &omega_a)?;
    assert_eq!(a.dims4()?, (2, 3, 32, 32));
    // Equalised init keeps unit-scale activations through the 8 layers (gain √2 per lrelu):
    // the output is O(1), i.e. it starts in the scale of the encoded range [−1, 1], and finite.
    let std = a.sqr()?.mean_all()?.to_scalar::<f32>()?.sqrt();
    assert!(
        std.is_finite() && (0.05..5.0).contains(&std),
        "output rms {std}"
    );
    let b = m.forward(&f, &omega_b)?;
    assert!(
        max_abs(&(&a - &b)?)? > 1e-3,
        "different lights give different images"
    );
    // Per-texel: M commutes with spatial permutations (here a roll).
    let rolled = m.forward(&f.roll(5, 2)?, &omega_a.roll(5, 2)?)?;
    assert!(max_abs(&(rolled - a.roll(5, 2)?)?)? < 1e-6);
    assert!(m.forward(&f, &omega_a.narrow(1, 0, 2)?).is_err());
    Ok(())
}

#[test]
fn discriminator_accepts_any_batch_size() -> Result<()> {
    let dev = Device::Cpu;
    let cfg = tiny(32, 1.0 / 64.0);
    let vm = VarMap::new();
    let d = Discriminator::new(&cfg, VarBuilder::from_varmap(&vm, DType::F32, &dev))?;
    for b in [1, 2, 3, 4, 5, 6, 9] {
        let img = seeded_uniform((b, 3, 32, 32), b as u64, DType::F32, &dev)?;
        let omega = seeded_uniform((b, 3, 32, 32), 100 + b as u64, DType::F32, &dev)?;
        let logits = d.forward(&img, &omega)?;
        assert_eq!(logits.dims2()?, (b, 1));
        assert!(
            logits
                .flatten_all()?
                .to_vec1::<f32>()?
                .iter()
                .all(|v| v.is_finite())
        );
    }
    let img = seeded_uniform((2, 3, 16, 16), 1, DType::F32, &dev)?;
    assert!(
        d.forward(&img, &img).is_err(),
        "wrong resolution is rejected"
    );
    Ok(())
}

#[test]
fn minibatch_stddev_groups_like_stylegan2() -> Result<()> {
    use photomat_generator::discriminator::minibatch_stddev;
    let dev = Device::Cpu;
    // B = 8, group 4: groups {0,2,4,6} and {1,3,5,7} (sample n in group n mod 2).
    let x = seeded_uniform((8, 2, 3, 3), 9, DType::F64, &dev)?;
    let y = minibatch_stddev(&x, 4, 1)?;
    assert_eq!(y.dims4()?, (8, 3, 3, 3));
    let v = x.flatten_all()?.to_vec1::<f64>()?;
    let stat = |members: &[usize]| {
        let per = 18;
        let mut acc = 0.0;
        for k in 0..per {
            let vals: Vec<f64> = members.iter().map(|&n| v[n * per + k]).collect();
            let mean = vals.iter().sum::<f64>() / vals.len() as f64;
            let var = vals.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / vals.len() as f64;
            acc += (var + 1e-8).sqrt();
        }
        acc / per as f64
    };
    let got = y.narrow(1, 2, 1)?.mean((1, 2, 3))?.to_vec1::<f64>()?;
    let (s0, s1) = (stat(&[0, 2, 4, 6]), stat(&[1, 3, 5, 7]));
    for (n, g) in got.iter().enumerate() {
        let e = if n % 2 == 0 { s0 } else { s1 };
        assert!((g - e).abs() < 1e-12, "sample {n}: {g} vs {e}");
    }
    // B = 5: ⌈5/4⌉ = 2 groups {0,2,4}, {1,3}.
    let x5 = x.narrow(0, 0, 5)?;
    let got = minibatch_stddev(&x5, 4, 1)?
        .narrow(1, 2, 1)?
        .mean((1, 2, 3))?
        .to_vec1::<f64>()?;
    assert!((got[4] - stat(&[0, 2, 4])).abs() < 1e-12);
    assert!((got[3] - stat(&[1, 3])).abs() < 1e-12);
    Ok(())
}

/// StyleGAN2's `upfirdn2d` in one dimension, written from its definition: zero-stuff by
/// `up`, pad by `pads` (zeros), correlate with `taps · gain`, keep every `down`-th sample.
fn upfirdn_1d(x: &[f64], up: usize, down: usize, pads: (usize, usize), gain: f64) -> Vec<f64> {
    let taps = [1.0, 3.0, 3.0, 1.0].map(|t| t / 8.0 * gain);
    let mut stuffed = vec![0.0; x.len() * up];
    for (i, v) in x.iter().enumerate() {
        stuffed[i * up] = *v;
    }
    let mut padded = vec![0.0; pads.0];
    padded.extend(stuffed);
    padded.extend(vec![0.0; pads.1]);
    let full: Vec<f64> = (0..=padded.len() - 4)
        .map(|m| (0..4).map(|k| padded[m + k] * taps[k]).sum())
        .collect();
    full.into_iter().step_by(down).collect()
}

#[test]
fn fir_matches_stylegan2_upfirdn_and_preserves_constants() -> Result<()> {
    let dev = Device::Cpu;
    let n = 6;
    let x = [0.3, -1.2, 2.0, 0.7, -0.4, 1.1];
    let apply = |m: &Tensor| -> candle_core::Result<Vec<f64>> {
        m.matmul(&Tensor::new(&x, &dev)?.unsqueeze(1)?)?
            .squeeze(1)?
            .to_vec1::<f64>()
    };
    let cases = [
        (
            upsample_matrix(n, Padding::Zeros, DType::F64, &dev)?,
            upfirdn_1d(&x, 2, 1, (2, 1), 2.0),
        ),
        (
            downsample_matrix(n, Padding::Zeros, DType::F64, &dev)?,
            upfirdn_1d(&x, 1, 2, (1, 1), 1.0),
        ),
        (
            blur_matrix(n, Padding::Zeros, DType::F64, &dev)?,
            upfirdn_1d(&x, 1, 1, (2, 2), 1.0),
        ),
    ];
    for (m, expected) in cases {
        let got = apply(&m)?;
        assert_eq!(got.len(), expected.len());
        for (g, e) in got.iter().zip(&expected) {
            assert!((g - e).abs() < 1e-14, "{got:?} vs {expected:?}");
        }
    }
    // Filter sums: up rows sum to 1 and columns to 2 (gain), down rows to 1 (circular).
    let up = upsample_matrix(n, Padding::Circular, DType::F64, &dev)?;
    assert_eq!(up.sum(1)?.to_vec1::<f64>()?, vec![1.0; 2 * n]);
    assert_eq!(up.sum(0)?.to_vec1::<f64>()?, vec![2.0; n]);
    let down = downsample_matrix(n, Padding::Circular, DType::F64, &dev)?;
    assert_eq!(down.sum(1)?.to_vec1::<f64>()?, vec![1.0; n / 2]);
    // Constants stay constant: everywhere when circular, in the interior with zero padding.
    let c = Tensor::full(0.7f32, (2, 3, 8, 8), &dev)?;
    let up_c = upsample2d(&c, Padding::Circular)?;
    assert_eq!(up_c.dims4()?, (2, 3, 16, 16));
    assert!(max_abs(&(up_c - 0.7)?)? < 1e-6);
    let down_c = downsample2d(&c, Padding::Circular)?;
    assert_eq!(down_c.dims4()?, (2, 3, 4, 4));
    assert!(max_abs(&(down_c - 0.7)?)? < 1e-6);
    let up_z = upsample2d(&c, Padding::Zeros)?;
    assert!(max_abs(&(up_z.narrow(2, 1, 14)?.narrow(3, 1, 14)? - 0.7)?)? < 1e-6);
    assert!(
        max_abs(&(up_z.narrow(2, 0, 1)? - 0.7)?)? > 0.1,
        "zero padding darkens the border"
    );
    Ok(())
}

#[test]
fn generator_and_relight_gradients_reach_every_parameter() -> Result<()> {
    // A detached or unused parameter would get no (or a zero) gradient: every trainable
    // variable of G and M must receive a finite, non-zero one from an image loss.
    let dev = Device::Cpu;
    let cfg = tiny(32, 1.0 / 64.0);
    let vm = VarMap::new();
    let vb = VarBuilder::from_varmap(&vm, DType::F32, &dev);
    let g = Generator::new(&cfg, vb.pp("g"))?;
    let m = Relight::new(&cfg, vb.pp("m"))?;
    let z = seeded_uniform((2, 512), 11, DType::F32, &dev)?;
    let omega = seeded_uniform((2, 3, 32, 32), 12, DType::F32, &dev)?;
    let rgb = m.forward(&g.forward(&z, 1.0, &NoiseInput::Random)?, &omega)?;
    let grads = rgb.sqr()?.mean_all()?.backward()?;
    let names: Vec<String> = {
        let data = vm.data().lock().expect("lock");
        let mut n: Vec<String> = data.keys().cloned().collect();
        n.sort();
        n
    };
    let trainable = photomat_generator::trainable_vars(&vm);
    assert_eq!(trainable.len(), names.len() - 1, "only w_avg is a buffer");
    for name in names.iter().filter(|n| !photomat_generator::is_buffer(n)) {
        let var = vm.data().lock().expect("lock")[name].clone();
        let g = grads
            .get(var.as_tensor())
            .unwrap_or_else(|| panic!("{name} has no gradient"));
        let size = max_abs(g)?;
        assert!(
            size.is_finite() && size > 0.0,
            "{name}: gradient magnitude {size}"
        );
    }
    Ok(())
}
