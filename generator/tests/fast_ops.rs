//! G, M and D on photomat-kernels' ops (im2col + gemm convolutions, sparse separable FIR,
//! fused bias + LeakyReLU) compute the same values and parameter gradients as on plain candle
//! ops ([`photomat_kernels::with_reference_ops`], the implementation before the kernels were
//! used), for the same seeded weights, in f64: in zero-padded and tileable mode, for G + M
//! and for D, and for M alone (photomat-kernels' fused per-texel MLP) on texel counts that
//! are not multiples of its row block.

mod common;

use anyhow::Result;
use candle_core::{DType, Device, Tensor};
use candle_nn::{Init, VarMap};
use common::{compare, config, perturb, seeded_noise, value_and_grads};
use photomat_generator::{
    Discriminator, Generator, NoiseInput, Relight, seeded_uniform, seeded_var_builder,
};
use photomat_kernels::with_reference_ops;

#[test]
fn generator_and_relight_on_kernels_equal_plain_candle() -> Result<()> {
    let dev = Device::Cpu;
    for tileable in [false, true] {
        let cfg = config(tileable);
        let vars = VarMap::new();
        let vb = seeded_var_builder(&vars, 3, DType::F64, &dev);
        let g = Generator::new(&cfg, vb.pp("g"))?;
        let m = Relight::new(&cfg, vb.pp("m"))?;
        perturb(&vars)?;
        let z = seeded_uniform((2, cfg.latent_dim), 1, DType::F64, &dev)?;
        let noise = seeded_noise(&g, 2)?;
        let omega = seeded_uniform((2, 3, 32, 32), 2, DType::F64, &dev)?;
        let weights = seeded_uniform((2, 3, 32, 32), 3, DType::F64, &dev)?;
        let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
            let f = g.forward(&z, 0.7, &NoiseInput::Given(&noise))?;
            let rgb = m.forward(&f, &omega)?;
            // Both F and M's output enter the loss, so G's gradients do not only come
            // through M.
            let loss = ((rgb * &weights)?.sum_all()? + f.sqr()?.mean_all()?)?;
            value_and_grads(&loss, &vars)
        };
        let fast = run()?;
        let reference = with_reference_ops(run)?;
        assert!(fast.1.len() > 30, "every layer has gradients");
        // f64: the two paths sum the same products in other orders (gemm blocking, sparse vs
        // dense FIR with exact zeros); through ~12 layers the rounding stays ≲ 1e-13 relative.
        compare(&format!("G+M tileable={tileable}"), fast, reference, 1e-9)?;
    }
    Ok(())
}

#[test]
fn discriminator_on_kernels_equals_plain_candle() -> Result<()> {
    let dev = Device::Cpu;
    let cfg = config(false);
    let vars = VarMap::new();
    let d = Discriminator::new(&cfg, seeded_var_builder(&vars, 4, DType::F64, &dev))?;
    perturb(&vars)?;
    let image = seeded_uniform((3, 3, 32, 32), 5, DType::F64, &dev)?;
    let omega = seeded_uniform((3, 3, 32, 32), 6, DType::F64, &dev)?;
    let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
        let logits = d.forward(&image, &omega)?;
        let loss = (logits.sqr()? + logits)?.sum_all()?;
        value_and_grads(&loss, &vars)
    };
    let fast = run()?;
    let reference = with_reference_ops(run)?;
    // Same argument as for G: other summation orders only.
    compare("D", fast, reference, 1e-9)
}

#[test]
fn relight_mlp_fused_equals_plain_candle_on_odd_sizes() -> Result<()> {
    let dev = Device::Cpu;
    let cfg = config(false);
    let c = cfg.feature_channels;
    // 17·23 = 391 texels per image (one full 256-row block and a partial one), batch 3; and a
    // single texel.
    for (b, h, w) in [(3, 17, 23), (1, 1, 1)] {
        let vars = VarMap::new();
        let vb = seeded_var_builder(&vars, 11, DType::F64, &dev);
        let m = Relight::new(&cfg, vb.pp("m"))?;
        perturb(&vars)?;
        // F and ω as variables too, so that their gradients are compared.
        let uniform = Init::Uniform { lo: -1.0, up: 1.0 };
        let f = vb.get_with_hints((b, c, h, w), "in.features", uniform)?;
        let omega = vb.get_with_hints((b, 3, h, w), "in.omega", uniform)?;
        let weights = seeded_uniform((b, 3, h, w), 12, DType::F64, &dev)?;
        let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
            let rgb = m.forward(&f, &omega)?;
            // The row form too, on the same texels in row order.
            let rows = Tensor::cat(&[&f, &omega], 1)?
                .permute((0, 2, 3, 1))?
                .contiguous()?
                .reshape((b * h * w, c + 3))?;
            let rgb_rows = m.forward_rows(&rows)?;
            let loss = ((rgb * &weights)?.sum_all()? + rgb_rows.sqr()?.mean_all()?)?;
            value_and_grads(&loss, &vars)
        };
        let fast = run()?;
        let reference = with_reference_ops(run)?;
        assert_eq!(
            fast.1.len(),
            2 + 2 * cfg.relight_layers,
            "F, ω, every weight and bias"
        );
        // f64, the same products summed in other orders through 8 layers: ≲ 1e-13 relative.
        compare(&format!("M {b}x{h}x{w}"), fast, reference, 1e-9)?;
    }
    Ok(())
}

#[test]
fn relight_mlp_with_phong_lobes_reads_them_and_fused_equals_plain_candle() -> Result<()> {
    let dev = Device::Cpu;
    let mut cfg = config(false);
    cfg.relight_lobes = vec![4.0, 64.0, 1024.0];
    let c = cfg.feature_channels;
    let vars = VarMap::new();
    let vb = seeded_var_builder(&vars, 13, DType::F64, &dev);
    let m = Relight::new(&cfg, vb.pp("m"))?;
    perturb(&vars)?;
    let highlights = [
        photomat_core::Highlight::new(0.1, -0.2),
        photomat_core::Highlight::new(-0.3, 0.05),
    ];
    let omega =
        photomat_core::FlashGeometry::with_side(&highlights, 12, 0.5, DType::F64, &dev)?.omega;
    // The light input is ω then ω_z^s per exponent, in order.
    let light = m.light_input(&omega)?;
    assert_eq!(light.dims4()?, (2, 3 + 3, 12, 12));
    let z = omega.narrow(1, 2, 1)?;
    for (i, s) in cfg.relight_lobes.iter().enumerate() {
        let got = light.narrow(1, 3 + i, 1)?.flatten_all()?.to_vec1::<f64>()?;
        let want = z.flatten_all()?.to_vec1::<f64>()?;
        for (g, w) in got.iter().zip(&want) {
            assert!(
                (g - w.powf(*s)).abs() < 1e-12,
                "lobe {s}: {g} vs {}",
                w.powf(*s)
            );
        }
    }
    let f = seeded_uniform((2, c, 12, 12), 14, DType::F64, &dev)?;
    let weights = seeded_uniform((2, 3, 12, 12), 15, DType::F64, &dev)?;
    let run = || -> Result<(f64, Vec<(String, Tensor)>)> {
        let loss = (m.forward(&f, &omega)? * &weights)?.sum_all()?;
        value_and_grads(&loss, &vars)
    };
    let fast = run()?;
    let reference = with_reference_ops(run)?;
    assert_eq!(
        fast.1.len(),
        2 * cfg.relight_layers,
        "every weight and bias"
    );
    compare("M with lobes", fast, reference, 1e-9)
}
