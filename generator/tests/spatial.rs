//! The spatial (fully convolutional) G: translation equivariance by whole cells, size scaling
//! (a field tiled 2×2 gives F tiled 2×2), sizes that are not a multiple of the cell refused,
//! seeded features at any size, M per texel at any size, and old model folders (the fixed-size
//! G with its learned constant) loading unchanged.

mod tiny_spatial;
use tiny_spatial::{tiny_spatial_config, with_spatial};

use std::path::Path;

use anyhow::Result;
use candle_core::{DType, Device, IndexOp, Tensor};
use candle_nn::VarMap;
use photomat_generator::model_files::read_gan_manifest;
use photomat_generator::synthesis::BaseInput;
use photomat_generator::{
    GanModel, Generator, GeneratorConfig, NoiseInput, seeded_uniform, seeded_var_builder,
};

/// The tiny spatial G with the texel of 16² patches of 64² photos: 2/64 world units.
fn spatial_config() -> GeneratorConfig {
    with_spatial(tiny_spatial_config(), |s| s.texel_size = Some(2.0 / 64.0))
}

/// A seeded spatial G whose noise strengths are 0.5 (they start at 0), so that the noise
/// images matter.
fn spatial_generator() -> Result<(Generator, VarMap)> {
    let vars = VarMap::new();
    let g = Generator::new(
        &spatial_config(),
        seeded_var_builder(&vars, 3, DType::F32, &Device::Cpu),
    )?;
    for (name, var) in vars.data().lock().expect("lock").iter() {
        if name.ends_with("noise_strength") {
            var.set(&Tensor::new(&[0.5f32], &Device::Cpu)?)?;
        }
    }
    Ok((g, vars))
}

/// Seeded field, noise and z for a batch of 2 at side `size`.
fn inputs(g: &Generator, size: usize) -> Result<(Tensor, Tensor, Vec<Tensor>)> {
    let dev = Device::Cpu;
    let z = seeded_uniform((2, 16), 1, DType::F32, &dev)?;
    let field = seeded_uniform(g.synthesis().field_shape(2, size)?, 2, DType::F32, &dev)?;
    let noise = g
        .synthesis()
        .noise_shapes_at(2, size)?
        .into_iter()
        .enumerate()
        .map(|(i, s)| seeded_uniform(s, 10 + i as u64, DType::F32, &dev))
        .collect::<candle_core::Result<_>>()?;
    Ok((z, field, noise))
}

fn max_abs(t: &Tensor) -> Result<f32> {
    Ok(t.abs()?.max_all()?.to_scalar::<f32>()?)
}

/// Rolls dims 2 and 3 of `x` by `(dy, dx)` × (side of `x` / `cells`).
fn roll_cells(x: &Tensor, (dy, dx): (usize, usize), cells: usize) -> Result<Tensor> {
    let s = x.dim(2)? / cells;
    Ok(x.roll((dy * s) as i32, 2)?.roll((dx * s) as i32, 3)?)
}

/// Tiles `x` 2×2 along dims 2 and 3.
fn tile2(x: &Tensor) -> Result<Tensor> {
    let row = Tensor::cat(&[x, x], 3)?;
    Ok(Tensor::cat(&[&row, &row], 2)?)
}

#[test]
fn spatial_generator_shifting_the_field_by_cells_shifts_features_by_cell_strides() -> Result<()> {
    let (g, _vars) = spatial_generator()?;
    let cfg = spatial_config();
    // 6 cells of 8 texels: a side that is not a power of two.
    let size = 48;
    let cells = size / cfg.cell_size();
    let (z, field, noise) = inputs(&g, size)?;
    let f = g.forward_field(&z, &field, 1.0, &NoiseInput::Given(&noise))?;
    assert_eq!(f.dims4()?, (2, 8, size, size));
    let shift = (1, 4);
    let rolled_noise = noise
        .iter()
        .map(|n| roll_cells(n, shift, cells))
        .collect::<Result<Vec<_>>>()?;
    let f_rolled = g.forward_field(
        &z,
        &roll_cells(&field, shift, cells)?,
        1.0,
        &NoiseInput::Given(&rolled_noise),
    )?;
    let expected = roll_cells(&f, shift, cells)?;
    // Exactly: every output texel reads the same values in the same order (the circular
    // im2col gathers by kernel position, and each FIR upsampling output is a sum of two taps,
    // which commutes exactly in floating point).
    let err = max_abs(&(f_rolled - &expected)?)?;
    assert_eq!(err, 0.0, "shift by {shift:?} cells");
    Ok(())
}

#[test]
fn spatial_generator_tiled_field_gives_tiled_features() -> Result<()> {
    let (g, _vars) = spatial_generator()?;
    let (z, field, noise) = inputs(&g, 32)?;
    let f = g.forward_field(&z, &field, 1.0, &NoiseInput::Given(&noise))?;
    let tiled_noise = noise.iter().map(tile2).collect::<Result<Vec<_>>>()?;
    let big = g.forward_field(&z, &tile2(&field)?, 1.0, &NoiseInput::Given(&tiled_noise))?;
    // A field 2× larger gives F 2× larger ...
    assert_eq!(big.dims4()?, (2, 8, 64, 64));
    // ... and a periodic field the same material, tiled: F is periodic at its own size.
    // Exactly, for the reason given in the shift test.
    assert_eq!(max_abs(&(big - tile2(&f)?)?)?, 0.0);
    Ok(())
}

#[test]
fn spatial_generator_refuses_sides_that_are_not_cell_multiples() -> Result<()> {
    let (g, _vars) = spatial_generator()?;
    let cfg = spatial_config();
    assert_eq!(cfg.cell_size(), 8);
    assert_eq!(cfg.cells_for(40)?, 5);
    for bad in [0, 12, 33] {
        let err = g
            .synthesis()
            .noise_shapes_at(1, bad)
            .unwrap_err()
            .to_string();
        assert!(err.contains("multiples of its cell of 8"), "{bad}: {err}");
    }
    // The fixed-size G makes R only, and says what would make other sizes.
    let fixed = GeneratorConfig {
        spatial: None,
        ..spatial_config()
    };
    assert_eq!(fixed.cells_for(32)?, 4);
    let err = fixed.cells_for(64).unwrap_err().to_string();
    assert!(err.contains("spatial generator"), "{err}");
    // A spatial G without the circular padding is refused at construction.
    let flat = GeneratorConfig {
        tileable: false,
        ..spatial_config()
    };
    let err = flat.validate().unwrap_err().to_string();
    assert!(err.contains("tileable"), "{err}");
    Ok(())
}

#[test]
fn spatial_model_features_are_seeded_at_any_size() -> Result<()> {
    let model = GanModel::new(&spatial_config(), 5, &Device::Cpu)?;
    let native = model.features_for_seeds(&[1, 2], 1.0)?;
    let at_native = model.features_for_seeds_at(&[1, 2], 1.0, 32)?;
    assert_eq!(max_abs(&(native - &at_native)?)?, 0.0);
    let big = model.features_for_seeds_at(&[1, 2], 1.0, 72)?;
    assert_eq!(big.dims4()?, (2, 8, 72, 72));
    // Deterministic per seed: seed 2 alone gives row 1 of the batch.
    let again = model.features_for_seeds_at(&[2], 1.0, 72)?;
    assert_eq!(max_abs(&(big.i(1)? - again.i(0)?)?)?, 0.0);
    assert!(max_abs(&(big.i(0)? - big.i(1)?)?)? > 0.0);
    let err = model
        .features_for_seeds_at(&[1], 1.0, 36)
        .unwrap_err()
        .to_string();
    assert!(err.contains("36"), "{err}");

    // M is per texel: relighting a 72² material equals relighting any window of it.
    let omega = seeded_uniform((2, 3, 72, 72), 9, DType::F32, &Device::Cpu)?;
    let whole = model.relight().forward(&big, &omega)?;
    let window = |t: &Tensor| -> candle_core::Result<Tensor> {
        t.narrow(2, 8, 40)?.narrow(3, 24, 40)?.contiguous()
    };
    let part = model.relight().forward(&window(&big)?, &window(&omega)?)?;
    let err = max_abs(&(window(&whole)? - part)?)?;
    assert!(err <= 1e-6, "M differs on a window by {err}");
    Ok(())
}

#[test]
fn spatial_model_saves_and_loads_with_its_local_input() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let model = GanModel::new(&spatial_config(), 5, &Device::Cpu)?;
    model.save(dir.path(), serde_json::Value::Null)?;
    let manifest = read_gan_manifest(dir.path())?;
    assert_eq!(manifest.architecture, spatial_config());
    let loaded = GanModel::load(dir.path(), &Device::Cpu)?;
    assert!(matches!(
        loaded.generator().synthesis().base_input(),
        BaseInput::Local(_)
    ));
    let (a, b) = (
        model.features_for_seeds_at(&[3], 1.0, 48)?,
        loaded.features_for_seeds_at(&[3], 1.0, 48)?,
    );
    assert_eq!(max_abs(&(a - b)?)?, 0.0);
    Ok(())
}

#[test]
fn fixed_size_gan_json_loads_as_the_fixed_size_generator_and_saves_unchanged() -> Result<()> {
    // The manifest of the 32² fixed-size model bundled before the spatial one, as written by
    // that release: no `spatial`, no `relight_lobes`.
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/fixed-size-32");
    let manifest = read_gan_manifest(&fixture)?;
    assert_eq!(manifest.architecture.spatial, None);
    assert!(manifest.architecture.relight_lobes.is_empty());
    // Re-serialised, the manifest is the file's JSON: no new field is written for it.
    let text = std::fs::read_to_string(fixture.join("gan.json"))?;
    let original: serde_json::Value = serde_json::from_str(&text)?;
    assert_eq!(serde_json::to_value(&manifest)?, original);
    // It builds, saves and loads as the fixed-size G with its learned constant.
    let dir = tempfile::tempdir()?;
    GanModel::new(&manifest.architecture, 1, &Device::Cpu)?
        .save(dir.path(), manifest.provenance.clone())?;
    let model = GanModel::load(dir.path(), &Device::Cpu)?;
    assert!(matches!(
        model.generator().synthesis().base_input(),
        BaseInput::Constant(_)
    ));
    let f = model.features_for_seeds(&[0], 1.0)?;
    assert_eq!(f.dims4()?, (1, 32, 32, 32));
    Ok(())
}
