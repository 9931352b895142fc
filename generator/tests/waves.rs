//! The periodic waves of a spatial G (`photomat_generator::waves`): each wave is `sin` and `cos`
//! of whole cycles per sample side against the closed form, faded out towards each grid's
//! Nyquist frequency; rounding passes the gradient straight through; with waves a sample stays
//! periodic at its own side, shifts with its field by cells that hold whole periods, and
//! saves and loads.

mod tiny_spatial;
use tiny_spatial::{tiny_spatial_config, with_spatial};

use anyhow::Result;
use candle_core::{DType, Device, IndexOp, Tensor, Var};
use candle_nn::VarMap;
use photomat_generator::model_files::read_gan_manifest;
use photomat_generator::waves::PeriodicWaves;
use photomat_generator::{
    GanModel, Generator, GeneratorConfig, NoiseInput, seeded_uniform, seeded_var_builder,
};

/// The tiny spatial G (cell of 8 texels) without noise inputs, with two waves.
fn config_with_waves() -> GeneratorConfig {
    let config = GeneratorConfig {
        noise_inputs: false,
        ..tiny_spatial_config()
    };
    with_spatial(config, |s| {
        s.texel_size = Some(2.0 / 64.0);
        s.waves = 2;
    })
}

/// A seeded G with waves whose wave vectors are fixed at `cycles_per_cell` (x, y) per wave
/// whatever w (the wave-vector layer's weight zeroed, its bias set).
fn generator_with_waves(cycles_per_cell: &[[f32; 2]; 2]) -> Result<(Generator, VarMap)> {
    let vars = VarMap::new();
    let g = Generator::new(
        &config_with_waves(),
        seeded_var_builder(&vars, 3, DType::F32, &Device::Cpu),
    )?;
    let data = vars.data().lock().expect("lock");
    let weight = &data["synthesis.waves.affine.weight"];
    weight.set(&weight.zeros_like()?)?;
    let bias: Vec<f32> = cycles_per_cell.iter().flatten().copied().collect();
    data["synthesis.waves.affine.bias"].set(&Tensor::new(bias, &Device::Cpu)?)?;
    drop(data);
    Ok((g, vars))
}

fn max_abs(t: &Tensor) -> Result<f32> {
    Ok(t.abs()?.max_all()?.to_scalar::<f32>()?)
}

#[test]
fn wave_features_are_sin_and_cos_of_whole_cycles_faded_towards_nyquist() -> Result<()> {
    let s = 16;
    // (3, 0): 3/16 cycles per texel, full amplitude; (5, -1): 5/16 along x, faded to
    // (0.5 − 5/16)/0.25 = 0.75; (9, 0): beyond the grid's Nyquist frequency, 0.
    let cycles = Tensor::new(&[[[3f64, 0.], [5., -1.], [9., 0.]]], &Device::Cpu)?;
    let f = PeriodicWaves::features(&cycles, s)?;
    assert_eq!(f.dims4()?, (1, 6, s, s));
    let f: Vec<Vec<Vec<f64>>> = f.i(0)?.to_vec3()?;
    let amplitude = [1.0, 0.75, 0.0];
    let cyc = [[3.0, 0.0], [5.0, -1.0], [9.0, 0.0]];
    for (n, (&[mx, my], a)) in cyc.iter().zip(amplitude).enumerate() {
        let u = |i: usize| (i as f64 + 0.5) / s as f64;
        for (y, (sin_row, cos_row)) in f[n].iter().zip(&f[3 + n]).enumerate() {
            for (x, (&sin, &cos)) in sin_row.iter().zip(cos_row).enumerate() {
                let phase = std::f64::consts::TAU * (mx * u(x) + my * u(y));
                approx::assert_abs_diff_eq!(sin, a * phase.sin(), epsilon = 1e-12);
                approx::assert_abs_diff_eq!(cos, a * phase.cos(), epsilon = 1e-12);
            }
        }
    }
    Ok(())
}

#[test]
fn rounding_to_whole_cycles_passes_the_gradient_straight_through() -> Result<()> {
    let k = Var::new(&[[[0.1f64, -0.27]]], &Device::Cpu)?;
    let side = 40;
    let cycles = PeriodicWaves::cycles_per_side(k.as_tensor(), side)?;
    // Forward: round(k·side) = round(4, −10.8) = (4, −11).
    assert_eq!(cycles.flatten_all()?.to_vec1::<f64>()?, vec![4.0, -11.0]);
    // Backward: the gradient of k·side, whatever the rounding did.
    let weights = Tensor::new(&[[[2f64, 3.]]], &Device::Cpu)?;
    let grads = (cycles * &weights)?.sum_all()?.backward()?;
    let g = grads.get(&k).expect("gradient of k").flatten_all()?;
    assert_eq!(g.to_vec1::<f64>()?, vec![2.0 * 40.0, 3.0 * 40.0]);
    Ok(())
}

#[test]
fn generator_with_waves_is_periodic_at_its_side_at_every_size() -> Result<()> {
    // ¼ and ¾ of a cycle per 8-texel cell: 1 and 3 cycles per 32 texels, 2 and 6 per 64.
    let (g, _vars) = generator_with_waves(&[[0.25, 0.0], [0.75, -0.25]])?;
    let dev = Device::Cpu;
    let z = seeded_uniform((2, 16), 1, DType::F32, &dev)?;
    let field = seeded_uniform(g.synthesis().field_shape(2, 32)?, 2, DType::F32, &dev)?;
    let f = g.forward_field(&z, &field, 1.0, &NoiseInput::Zero)?;
    let tile2 = |x: &Tensor| -> Result<Tensor> {
        let row = Tensor::cat(&[x, x], 3)?;
        Ok(Tensor::cat(&[&row, &row], 2)?)
    };
    let big = g.forward_field(&z, &tile2(&field)?, 1.0, &NoiseInput::Zero)?;
    // Every grid of the 64² sample sees each wave at the same texel centres as the 32² one.
    let err = max_abs(&(big - tile2(&f)?)?)?;
    assert!(
        err <= 1e-5,
        "2×2 tiled field differs from the tiled F by {err}"
    );
    // The waves matter: without them F differs.
    let vars = VarMap::new();
    let plain_cfg = with_spatial(config_with_waves(), |s| s.waves = 0);
    let plain = Generator::new(&plain_cfg, seeded_var_builder(&vars, 3, DType::F32, &dev))?;
    let without = plain.forward_field(&z, &field, 1.0, &NoiseInput::Zero)?;
    assert!(max_abs(&(f - without)?)? > 1e-2);
    Ok(())
}

#[test]
fn generator_with_waves_shifts_with_its_field_by_cells_of_whole_periods() -> Result<()> {
    // One cycle per 8-texel cell along x, half a cycle along y: a lattice that a shift of
    // (2, 1) cells moves by whole periods.
    let (g, _vars) = generator_with_waves(&[[1.0, 0.5], [0.0, 0.5]])?;
    let dev = Device::Cpu;
    let (size, cell) = (48, 8);
    let cells = size / cell;
    let z = seeded_uniform((2, 16), 1, DType::F32, &dev)?;
    let field = seeded_uniform(g.synthesis().field_shape(2, size)?, 2, DType::F32, &dev)?;
    let f = g.forward_field(&z, &field, 1.0, &NoiseInput::Zero)?;
    let (dy, dx) = (2, 1);
    let rolled_field = field.roll(dy as i32, 2)?.roll(dx as i32, 3)?;
    let f_rolled = g.forward_field(&z, &rolled_field, 1.0, &NoiseInput::Zero)?;
    let expected = f.roll((dy * cell) as i32, 2)?.roll((dx * cell) as i32, 3)?;
    assert_eq!(f_rolled.dims4()?, (2, 8, cells * cell, cells * cell));
    let err = max_abs(&(f_rolled - expected)?)?;
    assert!(
        err <= 1e-5,
        "shift by ({dy}, {dx}) cells: F differs by {err}"
    );
    Ok(())
}

#[test]
fn model_with_waves_saves_and_loads() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let model = GanModel::new(&config_with_waves(), 5, &Device::Cpu)?;
    model.save(dir.path(), serde_json::Value::Null)?;
    assert_eq!(
        read_gan_manifest(dir.path())?.architecture,
        config_with_waves()
    );
    let loaded = GanModel::load(dir.path(), &Device::Cpu)?;
    assert_eq!(
        loaded
            .generator()
            .synthesis()
            .periodic_waves()
            .map(|w| w.waves()),
        Some(2)
    );
    let (a, b) = (
        model.features_for_seeds_at(&[3], 1.0, 48)?,
        loaded.features_for_seeds_at(&[3], 1.0, 48)?,
    );
    assert_eq!(max_abs(&(a - b)?)?, 0.0);
    Ok(())
}
