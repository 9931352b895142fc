//! Checkpoints: save → load gives identical outputs; another architecture is refused with the
//! mismatching tensor named.

use anyhow::Result;
use candle_core::{DType, Device, Tensor};
use candle_nn::{VarBuilder, VarMap};
use photomat_generator::{
    Discriminator, Generator, GeneratorConfig, NoiseInput, Relight, load_checkpoint,
    save_checkpoint, seeded_uniform,
};

struct Models {
    vars: VarMap,
    g: Generator,
    m: Relight,
    d: Discriminator,
}

fn build(cfg: &GeneratorConfig) -> Result<Models> {
    let vars = VarMap::new();
    let vb = VarBuilder::from_varmap(&vars, DType::F32, &Device::Cpu);
    Ok(Models {
        g: Generator::new(cfg, vb.pp("g"))?,
        m: Relight::new(cfg, vb.pp("m"))?,
        d: Discriminator::new(cfg, vb.pp("d"))?,
        vars,
    })
}

/// F, M(F, ω) and D(M(F, ω), ω) for fixed inputs, all flattened.
fn outputs(models: &Models) -> Result<Vec<f32>> {
    let dev = Device::Cpu;
    let z = seeded_uniform((2, 512), 3, DType::F32, &dev)?;
    let omega = seeded_uniform((2, 3, 32, 32), 4, DType::F32, &dev)?;
    let f = models.g.forward(&z, 0.7, &NoiseInput::Zero)?;
    let rgb = models.m.forward(&f, &omega)?;
    let logits = models.d.forward(&rgb, &omega)?;
    let parts = [f.flatten_all()?, rgb.flatten_all()?, logits.flatten_all()?];
    Ok(Tensor::cat(&parts, 0)?.to_vec1::<f32>()?)
}

fn config(channel_multiplier: f64) -> GeneratorConfig {
    GeneratorConfig {
        resolution: 32,
        channel_multiplier,
        ..Default::default()
    }
}

#[test]
fn checkpoint_roundtrip_gives_identical_outputs() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("gan.safetensors");
    let a = build(&config(1.0 / 64.0))?;
    // A non-zero w_avg, so that the buffer is part of what must round-trip (ψ = 0.7 uses it).
    a.g.mapping()
        .update_w_avg(&seeded_uniform((4, 512), 5, DType::F32, &Device::Cpu)?)?;
    save_checkpoint(&a.vars, &path)?;
    let b = build(&config(1.0 / 64.0))?;
    let (before, fresh) = (outputs(&a)?, outputs(&b)?);
    assert_ne!(before, fresh, "fresh weights differ before loading");
    load_checkpoint(&b.vars, &path)?;
    assert_eq!(outputs(&b)?, before);
    Ok(())
}

#[test]
fn checkpoint_of_another_architecture_is_refused_with_the_mismatch_named() -> Result<()> {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("gan.safetensors");
    save_checkpoint(&build(&config(1.0 / 64.0))?.vars, &path)?;

    // Wider channels: same names, other shapes.
    let wider = build(&config(1.0 / 32.0))?;
    let before = outputs(&wider)?;
    let err = load_checkpoint(&wider.vars, &path)
        .expect_err("shapes differ")
        .to_string();
    assert!(
        err.contains("does not match the model's architecture"),
        "{err}"
    );
    assert!(
        err.contains(
            "tensor `d.b16.conv0.bias` has shape [8] in the checkpoint, the model expects [16]"
        ),
        "{err}"
    );
    assert_eq!(
        outputs(&wider)?,
        before,
        "a refused checkpoint changes nothing"
    );

    // Another resolution: tensors missing and unexpected, named.
    let bigger = build(&GeneratorConfig {
        resolution: 64,
        ..config(1.0 / 64.0)
    })?;
    let err = load_checkpoint(&bigger.vars, &path)
        .expect_err("blocks differ")
        .to_string();
    // Sorted by name: D's new 64² block comes first (4 channels at 64², multiplier 1/64).
    assert!(
        err.contains("tensor `d.b64.conv0.bias` [4] is missing"),
        "{err}"
    );
    Ok(())
}
