//! One SkinNet training step — forward, a loss on the skinned positions, backward, Adam — with
//! the fused op against candle's graph (with the fused Softplus, the step before the fused op
//! existed), side by side in the same run, on one and two threads; and the MLP part alone
//! (forward + backward) against the runtime's inference forward of the same network.
//!
//! `cargo bench -p skinfield-benches --bench skinnet_step`: 4 frames × 2,500 rows, J = 24, the
//! paper's architecture. Throughputs are printed by criterion as `elem/s`, where an element is
//! one floating-point operation of the measured work, so `Gelem/s` reads as GFLOP/s.
//! `fused_forward_backward_pose_per_row/2t` feeds the same poses per row (`[F, V, 3J]`, the
//! input of pose locality's training step) against `fused_forward_backward/2t`.
//! `skinnet_pose_locality_4x2500` compares pose locality's input written out as rows through a
//! full output layer with the same input kept as [`LocalPoses`] and the output layer over the
//! candidates, at 24 and 163 joints.

use std::sync::Arc;

use candle_core::{Device, Tensor};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::{ModelConfig, Net};
use skinfield_runtime::{BoundMesh, FrameState, Scratch, SkinNetModel, WeightsJob};
use skinfield_trainer::losses::lbs::{lbs, rest_homogeneous, skinning_tensor};
use skinfield_trainer::optim::{Adam, AdamConfig};
use skinfield_trainer::skinnet::export::to_skf_model;
use skinfield_trainer::skinnet::{
    Activation, Backend, LocalPoses, TrainableSkinNet, position_inputs_tensor,
};

const JOINTS: u32 = 24;
const FRAMES: usize = 4;
const POINTS: usize = 2500;

/// Floating-point operations of one forward pass over `rows` rows with `vertices` distinct
/// positions and `frames` poses, as the fused op executes it: the position and pose parts of the
/// input layers once per vertex and once per frame, the rest per row.
fn forward_flops(config: &ModelConfig, frames: usize, vertices: usize) -> f64 {
    let rows = (frames * vertices) as f64;
    let (p, q) = (config.position_width(), config.pose_width());
    let skip = config.skip_layer as usize;
    config
        .layer_shapes(Net::Skin)
        .enumerate()
        .map(|(i, (out, inp))| {
            let out = out as f64;
            if i == 0 || (i == skip && i > 0) {
                let hidden = (inp - p - q) as f64;
                2.0 * out * (rows * hidden + vertices as f64 * p as f64 + frames as f64 * q as f64)
            } else {
                2.0 * out * inp as f64 * rows
            }
        })
        .sum()
}

/// The floating-point operations a pose per row ([F, V, Q], pose locality's training input)
/// adds to [`forward_flops`]: the pose parts of the input layers per row instead of per frame.
fn pose_per_row_extra_flops(config: &ModelConfig, frames: usize, vertices: usize) -> f64 {
    let q = config.pose_width() as f64;
    let skip = config.skip_layer as usize;
    let extra_rows = (frames * vertices - frames) as f64;
    config
        .layer_shapes(Net::Skin)
        .enumerate()
        .filter(|&(i, _)| i == 0 || (i == skip && i > 0))
        .map(|(_, (out, _))| 2.0 * out as f64 * q * extra_rows)
        .sum()
}

struct Inputs {
    config: ModelConfig,
    points: Vec<Vec3>,
    encoded: Tensor,
    poses: Tensor,
    skinning: Tensor,
    rest: Tensor,
    target: Tensor,
}

fn inputs() -> Inputs {
    let config = ModelConfig::paper_architecture(JOINTS, [-1.0; 3], [1.0; 3]);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut unit = || rng.random_range(-1.0f32..1.0);
    let points: Vec<Vec3> = (0..POINTS)
        .map(|_| Vec3::new(unit(), unit(), unit()))
        .collect();
    let encoded = position_inputs_tensor(&config, &points, &Device::Cpu).unwrap();
    let q = config.pose_width();
    let pose_rows: Vec<f32> = (0..FRAMES * q).map(|_| unit()).collect();
    let poses = Tensor::from_vec(pose_rows, (FRAMES, q), &Device::Cpu).unwrap();
    let mats: Vec<Vec<Mat4>> = (0..FRAMES)
        .map(|_| {
            (0..JOINTS)
                .map(|_| {
                    Mat4::from_rotation_translation(
                        Quat::from_euler(glam::EulerRot::XYZ, unit(), unit(), unit()),
                        Vec3::new(unit(), unit(), unit()) * 0.1,
                    )
                })
                .collect()
        })
        .collect();
    let skinning = skinning_tensor(&mats, &Device::Cpu).unwrap();
    let rest = rest_homogeneous(&points, &Device::Cpu).unwrap();
    let target: Vec<f32> = (0..FRAMES * POINTS * 3).map(|_| unit()).collect();
    let target = Tensor::from_vec(target, (FRAMES, POINTS, 3), &Device::Cpu).unwrap();
    Inputs {
        config,
        points,
        encoded,
        poses,
        skinning,
        rest,
        target,
    }
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

fn step(c: &mut Criterion) {
    let x = inputs();
    let mut group = c.benchmark_group("skinnet_train_step_4x2500");
    group.sample_size(10);
    for threads in [1, 2] {
        let pool = pool(threads);
        for (name, backend) in [
            ("fused", Backend::Fused),
            ("candle", Backend::Candle(Activation::SoftplusOp)),
        ] {
            let (net, varmap) = TrainableSkinNet::seeded(x.config, 7, 1.0).unwrap();
            let net = net.with_backend(backend);
            let mut opt = Adam::from_varmap(&varmap, AdamConfig::default()).unwrap();
            group.bench_function(format!("{name}/{threads}t"), |b| {
                b.iter(|| {
                    pool.install(|| {
                        let w = net.forward(&x.encoded, &x.poses).unwrap();
                        let posed = lbs(&w, &x.skinning, &x.rest).unwrap();
                        let loss = (posed - &x.target)
                            .unwrap()
                            .sqr()
                            .unwrap()
                            .sum(2)
                            .unwrap()
                            .sqrt()
                            .unwrap()
                            .mean_all()
                            .unwrap();
                        opt.backward_step(&loss).unwrap();
                    });
                });
            });
        }
    }
    group.finish();
}

fn mlp(c: &mut Criterion) {
    let x = inputs();
    let forward = forward_flops(&x.config, FRAMES, POINTS);
    let mut group = c.benchmark_group("skinnet_mlp_4x2500");
    group.sample_size(10);
    let (net, _varmap) = TrainableSkinNet::seeded(x.config, 7, 1.0).unwrap();
    for threads in [1, 2] {
        let pool = pool(threads);
        // Forward + backward of the fused op alone: the backward executes twice the forward's
        // products (∂W and ∂H per layer; the first layer needs no ∂H, which this count ignores).
        group.throughput(Throughput::Elements((3.0 * forward) as u64));
        group.bench_function(format!("fused_forward_backward/{threads}t"), |b| {
            b.iter(|| {
                pool.install(|| {
                    let w = net.forward(&x.encoded, &x.poses).unwrap();
                    w.sum_all().unwrap().backward().unwrap()
                })
            });
        });
        group.throughput(Throughput::Elements(forward as u64));
        group.bench_function(format!("fused_forward/{threads}t"), |b| {
            b.iter(|| pool.install(|| net.forward(&x.encoded, &x.poses).unwrap()));
        });
    }
    // Pose locality's input: the same poses given per row, as the training step feeds them.
    let q = x.config.pose_width();
    let per_row = x
        .poses
        .unsqueeze(1)
        .unwrap()
        .broadcast_as((FRAMES, POINTS, q))
        .unwrap()
        .contiguous()
        .unwrap();
    let with_rows = forward + pose_per_row_extra_flops(&x.config, FRAMES, POINTS);
    let pool2 = pool(2);
    group.throughput(Throughput::Elements((3.0 * with_rows) as u64));
    group.bench_function("fused_forward_backward_pose_per_row/2t", |b| {
        b.iter(|| {
            pool2.install(|| {
                let w = net.forward(&x.encoded, &per_row).unwrap();
                w.sum_all().unwrap().backward().unwrap()
            })
        });
    });
    // The runtime's inference kernels on the same network: FRAMES frames of POINTS vertices.
    // (The network's cost does not depend on the pose values, so any FRAMES poses do.)
    let mut r = skinfield_benches::rng(3);
    let skeleton = skinfield_benches::skeleton(JOINTS as usize, &mut r);
    let bytes = to_skf_model(&net, &skeleton).unwrap().to_bytes().unwrap();
    let model = SkinNetModel::from_skf(&bytes).unwrap();
    let mesh = BoundMesh::bind(&model, &x.points).unwrap();
    let frames: Vec<FrameState> = (0..FRAMES)
        .map(|_| {
            let mut f = FrameState::new(&model);
            let pose = skinfield_benches::random_pose(model.skeleton(), &mut r, 0.6);
            f.set_pose(&model, &pose).unwrap();
            f
        })
        .collect();
    let mut scratch = Scratch::new(&model);
    let mut out = vec![0.0f32; POINTS * JOINTS as usize];
    group.throughput(Throughput::Elements(forward as u64));
    group.bench_function("runtime_forward/1t", |b| {
        b.iter(|| {
            for f in &frames {
                WeightsJob {
                    model: &model,
                    mesh: &mesh,
                    frame: f,
                    first_vertex: 0,
                    out_weights: &mut out,
                }
                .run(&mut scratch)
                .unwrap();
            }
        });
    });
    group.finish();
}

/// Pose locality's input (a pose per row: the frame's features for 3 to 8 candidate joints per
/// vertex, 5.5 on average (the built-in character's lists hold 5.9), a donor's for the rest,
/// drawn from 64 donor poses) through the fused op's forward
/// and backward, masked to the candidates as in training, two ways: `dense_rows` writes it out
/// as `[F, V, 3J]` rows through a full output layer (`with_structure(false)`: the training step
/// before 2026-12-07), `structured` as the [`LocalPoses`] structure with the output layer over
/// the candidates, where each pays (the default). The donors are drawn inside the loop for
/// both, as the training step does every iteration. At the built-in character's 24 joints, the
/// Female_Peasant's 65 and the MakeHuman body's 163.
fn local_poses(c: &mut Criterion) {
    let mut group = c.benchmark_group("skinnet_pose_locality_4x2500");
    group.sample_size(10);
    let pool2 = pool(2);
    for joints in [24u32, 65, 163] {
        let j = joints as usize;
        let config = ModelConfig::paper_architecture(joints, [-1.0; 3], [1.0; 3]);
        let q = config.pose_width();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let points: Vec<Vec3> = (0..POINTS)
            .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()))
            .collect();
        let encoded = position_inputs_tensor(&config, &points, &Device::Cpu).unwrap();
        let poses: Vec<f32> = (0..(FRAMES + 64) * q)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let (own, donors) = poses.split_at(FRAMES * q);
        let own: Vec<&[f32]> = own.chunks_exact(q).collect();
        let donors: Vec<&[f32]> = donors.chunks_exact(q).collect();
        let lists: Vec<Vec<u16>> = (0..POINTS)
            .map(|_| {
                let n = rng.random_range(3..=8);
                let mut l: Vec<u16> = (0..joints as u16).collect();
                for i in 0..n {
                    let k = rng.random_range(i..j);
                    l.swap(i, k);
                }
                let mut l = l[..n].to_vec();
                l.sort_unstable();
                l
            })
            .collect();
        let mut relevant = vec![false; POINTS * j];
        for (v, l) in lists.iter().enumerate() {
            for &i in l {
                relevant[v * j + i as usize] = true;
            }
        }
        let mask = Tensor::from_vec(
            skinfield_trainer::candidates::additive_mask(&lists, j),
            (POINTS, j),
            &Device::Cpu,
        )
        .unwrap();
        let (net, _varmap) = TrainableSkinNet::seeded(config, 7, 1.0).unwrap();
        let dense = net.clone().with_structure(false);
        let draw = |seed: u64| {
            LocalPoses::draw(
                &own,
                &donors,
                &relevant,
                j,
                &mut ChaCha8Rng::seed_from_u64(seed),
            )
            .unwrap()
        };
        group.bench_function(format!("dense_rows/J{joints}/2t"), |b| {
            b.iter(|| {
                pool2.install(|| {
                    let rows = Tensor::from_vec(draw(1).rows(), (FRAMES, POINTS, q), &Device::Cpu)
                        .unwrap();
                    let w = dense.forward_masked(&encoded, &rows, Some(&mask)).unwrap();
                    w.sum_all().unwrap().backward().unwrap()
                })
            });
        });
        group.bench_function(format!("structured/J{joints}/2t"), |b| {
            b.iter(|| {
                pool2.install(|| {
                    let local = Arc::new(draw(1));
                    let w = net.forward_local(&encoded, &local, Some(&mask)).unwrap();
                    w.sum_all().unwrap().backward().unwrap()
                })
            });
        });
    }
    group.finish();
}

criterion_group!(benches, step, mlp, local_poses);
criterion_main!(benches);
