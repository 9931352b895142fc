//! One Adam step over the maps of a 1024² capture (diffuse, specular, roughness, height:
//! 8 channels, 8 Mi f32 values) and over a CPU-sized GAN's parameters (4 Mi values in 64
//! tensors): the fused in-place update against the composed candle ops that
//! [`photomat_kernels::with_reference_ops`] selects (docs/benchmarks/conv-kernels.md, "Fused
//! Adam").

use candle_core::{DType, Device, Tensor, Var};
use criterion::{Criterion, criterion_group, criterion_main};
use photomat_core::rng::pseudo_random;
use photomat_train::adam::{Adam, AdamConfig};

/// Variables of `sizes` elements each, with a loss whose gradient is a fixed random tensor
/// per variable (`Σ θ ⊙ r`), so that every step differentiates the same graph.
fn setup(sizes: &[usize]) -> (Adam, Vec<(Var, Tensor)>) {
    let dev = Device::Cpu;
    let pairs: Vec<(Var, Tensor)> = sizes
        .iter()
        .enumerate()
        .map(|(i, &n)| {
            let theta =
                Var::from_tensor(&pseudo_random(n, i as u64, DType::F32, &dev).unwrap()).unwrap();
            let r = pseudo_random(n, 1000 + i as u64, DType::F32, &dev).unwrap();
            (theta, r)
        })
        .collect();
    let named = pairs
        .iter()
        .enumerate()
        .map(|(i, (v, _))| (format!("p{i}"), v.clone()))
        .collect();
    (Adam::new(named, AdamConfig::kingma(1e-3)).unwrap(), pairs)
}

fn bench_case(c: &mut Criterion, name: &str, sizes: &[usize]) {
    let (mut adam, pairs) = setup(sizes);
    let loss = |pairs: &[(Var, Tensor)]| {
        pairs
            .iter()
            .map(|(v, r)| (v.as_tensor() * r).unwrap().sum_all().unwrap())
            .reduce(|a, b| (a + b).unwrap())
            .unwrap()
    };
    let grads = loss(&pairs).backward().unwrap();
    let mut group = c.benchmark_group(name);
    group.sample_size(20);
    group.bench_function("fused", |b| b.iter(|| adam.step(&grads).unwrap()));
    group.bench_function("composed", |b| {
        b.iter(|| photomat_kernels::with_reference_ops(|| adam.step(&grads).unwrap()))
    });
    group.finish();
}

fn adam(c: &mut Criterion) {
    bench_case(
        c,
        "adam_capture_1024",
        &[3 << 20, 3 << 20, 1 << 20, 1 << 20],
    );
    bench_case(c, "adam_gan_64x64k", &[1 << 16; 64]);
}

criterion_group!(benches, adam);
criterion_main!(benches);
