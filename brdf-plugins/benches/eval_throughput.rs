//! Single-thread BRDF evaluation throughput of the built-in models at 256² f32, in texels/s:
//! the baseline that later work (fused kernels, GPU, allocators) improves on.
//!
//! Run (docs/benchmarks/brdf-eval.md, "BRDF evaluation throughput", records the numbers):
//!
//! ```text
//! RAYON_NUM_THREADS=1 cargo bench -p photomat-brdfs --bench eval_throughput
//! ```
//!
//! Per built-in configuration (`coated`, `ggx`, `lambert`, `height(ggx)`), in the group
//! `eval_256`:
//! - `baseline/<model>`: one element-wise multiply of two (1, 3, 256, 256) tensors — the cost of
//!   a single candle op over an RGB image, measured in the same process right before the model
//!   so results can be reported as ratios that partly cancel machine and load differences;
//! - `forward_default/<model>`: [`render_radiance`] (flash geometry + `eval` + 1/d² falloff)
//!   with every map at its spec default;
//! - `forward_random/<model>`: the same with maps drawn uniformly over each spec's range;
//! - `eval_random/<model>`: `DifferentiableBrdf::eval` alone on the random maps, with the
//!   flash directions precomputed (the model's share of `forward_random`);
//! - `forward_backward/<model>`: forward on random maps held in candle `Var`s, then the
//!   gradient of the summed radiance w.r.t. every map.
//!
//! `flash_geometry` measures the per-texel ω and 1/d² that every forward includes.
//!
//! Threads: candle 0.11.1 is *not* single-threaded here. Its CPU element-wise kernels
//! (`unary_map_vec_par`, `binary_map_vec_par`) split tensors of ≥ 65,536 elements over a
//! spinning "barrier pool" of `CANDLE_NUM_THREADS`, else `RAYON_NUM_THREADS`, else
//! physical-core threads — and a 256² map has exactly 65,536 texels per channel. So the
//! documented command sets `RAYON_NUM_THREADS=1` (this bench sets it itself when unset and
//! prints the thread counts it runs with; leave `CANDLE_NUM_THREADS` unset or 1). Channel
//! reductions (`sum_keepdim(1)`), `affine`, `powf` and the `roll`/`cat` copies are sequential
//! whatever the setting.

use std::hint::black_box;
use std::time::Duration;

use candle_core::{DType, Device, Tensor, Var};
use criterion::{BenchmarkId, Criterion, Throughput};
use photomat_core::testing::{random_maps, rng};
use photomat_core::{FlashGeometry, Highlight, MaterialMaps, lookup, render_radiance};

// Linking pitfall (see `photomat_core::registry`): name the plugin crate so the registry sees its models.
use photomat_brdfs::builtin_configurations;

/// Map resolution: 256² texels, the paper's smallest model size.
const SIZE: usize = 256;
/// Off-centre flash, so that no symmetry makes the work atypical.
const LIGHT: Highlight = Highlight { x: 0.1, y: -0.1 };

fn eval_throughput(c: &mut Criterion) {
    let device = Device::Cpu;
    let mut rng = rng(2023);
    let mut group = c.benchmark_group("eval_256");
    group.throughput(Throughput::Elements((SIZE * SIZE) as u64));

    group.bench_function("flash_geometry", |b| {
        b.iter(|| FlashGeometry::new(black_box(&[LIGHT]), SIZE, DType::F32, &device).unwrap())
    });

    let geometry = FlashGeometry::new(&[LIGHT], SIZE, DType::F32, &device).unwrap();
    let omega = &geometry.omega;
    let a = Tensor::ones((1, 3, SIZE, SIZE), DType::F32, &device).unwrap();
    let a2 = (&a * 0.5).unwrap();
    // Every built-in model and adapter configuration, as the estimator would name them.
    for spec in &builtin_configurations().unwrap() {
        let spec = spec.as_str();
        let brdf = lookup(spec).unwrap_or_else(|e| panic!("{e}"));
        let defaults = MaterialMaps::defaults(brdf.params(), 1, SIZE, DType::F32, &device).unwrap();
        // Uniform over each spec's range; normals tilted by at most ≈ 27°.
        let random = random_maps(&brdf, &mut rng, SIZE, 0.0, DType::F32).unwrap();
        let vars: Vec<(String, Var)> = random
            .iter()
            .map(|(name, t)| (name.to_string(), Var::from_tensor(t).unwrap()))
            .collect();
        let var_maps = vars.iter().fold(MaterialMaps::new(), |m, (name, v)| {
            m.with(name.clone(), v.as_tensor().clone())
        });

        group.bench_function(BenchmarkId::new("baseline", spec), |b| {
            b.iter(|| black_box(&a).mul(black_box(&a2)).unwrap())
        });
        group.bench_function(BenchmarkId::new("forward_default", spec), |b| {
            b.iter(|| render_radiance(brdf.as_ref(), black_box(&defaults), &[LIGHT]).unwrap())
        });
        group.bench_function(BenchmarkId::new("forward_random", spec), |b| {
            b.iter(|| render_radiance(brdf.as_ref(), black_box(&random), &[LIGHT]).unwrap())
        });
        group.bench_function(BenchmarkId::new("eval_random", spec), |b| {
            b.iter(|| brdf.eval(omega, omega, black_box(&random)).unwrap())
        });
        group.bench_function(BenchmarkId::new("forward_backward", spec), |b| {
            b.iter(|| {
                let radiance = render_radiance(brdf.as_ref(), &var_maps, &[LIGHT]).unwrap();
                let grads = radiance.sum_all().unwrap().backward().unwrap();
                for (name, var) in &vars {
                    let g = grads.get(var.as_tensor());
                    assert!(g.is_some(), "{spec}: no gradient w.r.t. '{name}'");
                    black_box(g);
                }
            })
        });
    }
    group.finish();
}

fn main() {
    if std::env::var_os("RAYON_NUM_THREADS").is_none() {
        // SAFETY: main has not started any thread yet (candle's pools are created lazily on
        // the first large tensor op), so nothing reads the environment concurrently.
        unsafe { std::env::set_var("RAYON_NUM_THREADS", "1") };
    }
    // candle's element-wise pool follows CANDLE_NUM_THREADS when set, else RAYON_NUM_THREADS.
    let rayon = std::env::var("RAYON_NUM_THREADS").unwrap_or_default();
    let elementwise = std::env::var("CANDLE_NUM_THREADS").unwrap_or_else(|_| rayon.clone());
    eprintln!(
        "eval_throughput: {SIZE}² f32, threads: rayon {rayon}, candle element-wise {elementwise}"
    );
    let mut criterion = Criterion::default()
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    eval_throughput(&mut criterion);
    criterion.final_summary();
}
