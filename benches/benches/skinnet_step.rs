//! One SkinNet training step (forward, loss, backward, Adam) with the fused Softplus op against
//! the composite candle version, measured side by side in the same run.
//!
//! `cargo bench --bench skinnet_step`: 4 poses × 1024 canonical points, J = 24, the paper's
//! architecture (≈ 0.49 MFLOP per point forward).

use candle_core::{Device, Tensor};
use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::ModelConfig;
use skinfield_trainer::optim::{Adam, AdamConfig};
use skinfield_trainer::skinnet::{Activation, SkinNet, encode_positions};

const JOINTS: u32 = 24;
const FRAMES: usize = 4;
const POINTS: usize = 1024;

fn step(c: &mut Criterion) {
    let config = ModelConfig::vinecs(JOINTS, [-1.0; 3], [1.0; 3]);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let pts: Vec<Vec3> = (0..POINTS)
        .map(|_| {
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        })
        .collect();
    let enc = encode_positions(&config, &pts, &Device::Cpu).unwrap();
    let poses: Vec<f32> = (0..FRAMES * 3 * JOINTS as usize)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let poses = Tensor::from_vec(poses, (FRAMES, 3 * JOINTS as usize), &Device::Cpu).unwrap();
    let target: Vec<f32> = (0..FRAMES * POINTS * JOINTS as usize)
        .map(|_| rng.random_range(0.0..1.0))
        .collect();
    let target = Tensor::from_vec(target, (FRAMES, POINTS, JOINTS as usize), &Device::Cpu).unwrap();
    let mut group = c.benchmark_group("skinnet_train_step_4x1024");
    group.sample_size(20);
    for (name, act) in [
        ("fused_softplus", Activation::Fused),
        ("composite_softplus", Activation::Composite),
    ] {
        let (net, varmap) = SkinNet::seeded(config, 7, 1.0).unwrap();
        let net = net.with_activation(act);
        let mut opt = Adam::from_varmap(&varmap, AdamConfig::default()).unwrap();
        group.bench_function(name, |b| {
            b.iter(|| {
                let w = net.forward(&enc, &poses).unwrap();
                let loss = (w - &target).unwrap().sqr().unwrap().mean_all().unwrap();
                opt.backward_step(&loss).unwrap();
            });
        });
    }
    group.finish();
}

criterion_group!(benches, step);
criterion_main!(benches);
