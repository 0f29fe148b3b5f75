//! GPU frame time of SkinNet (the paper's architecture, J = 24) plus LBS, on whatever adapter
//! wgpu finds (Mesa's lavapipe on a machine without a GPU).
//!
//! Each iteration uploads a frame, records and submits it, and waits for the queue, so the time
//! is the whole frame as an engine would see it. The reference in the same run is the runtime's
//! CPU path (`FrameState::set_pose` + one `SkinJob` over the whole mesh, one thread, the kernel
//! picked at run time). Vertex counts: `SKINFIELD_GPU_BENCH_VERTICES` (comma-separated, default
//! `10000,100000`).

use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::{Mat4, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::{ModelConfig, Net, SkfModel, SkfView};
use skinfield_formats::{Skeleton, Transform};
use skinfield_runtime::gpu::{GpuSkinner, headless_device};
use skinfield_runtime::{BoundMesh, FrameState, Method, Scratch, SkinJob, SkinNet};

fn vertex_counts() -> Vec<usize> {
    std::env::var("SKINFIELD_GPU_BENCH_VERTICES")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![10_000, 100_000])
}

fn bench_gpu(c: &mut Criterion) {
    let (adapter, device, queue) = match headless_device(wgpu::Limits::default()) {
        Ok(d) => d,
        Err(e) => {
            eprintln!("skipping GPU bench: {e} (install mesa-vulkan-drivers for lavapipe)");
            return;
        }
    };
    let info = adapter.get_info();
    eprintln!(
        "GPU bench on {} ({:?}, {:?})",
        info.name, info.device_type, info.backend
    );

    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let joints: usize = 24;
    let config = ModelConfig::paper_architecture(joints as u32, [-1.0; 3], [1.0; 3]);
    let names = (0..joints).map(|j| format!("j{j}")).collect();
    let parents = (0..joints).map(|j| j.checked_sub(1)).collect();
    let bind = (0..joints)
        .map(|_| Transform::from_translation(Vec3::new(0.0, 0.1, 0.0)))
        .collect();
    let skeleton = Skeleton::new(names, parents, bind, None, None, Mat4::IDENTITY).unwrap();
    let mut model = SkfModel {
        config,
        skeleton: skeleton.clone(),
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    for (l, (out, inp)) in config.layer_shapes(Net::Skin).enumerate() {
        let s = 2.0 / (inp as f32).sqrt();
        let w = (0..out * inp).map(|_| rng.random_range(-s..s)).collect();
        model.push_layer(Net::Skin, l, w, out, inp, vec![0.0; out]);
    }
    let bytes = model.to_bytes().unwrap();
    let view = SkfView::parse(&bytes).unwrap();
    let skinner = GpuSkinner::new(&device).unwrap();
    let gpu_model = skinner.bind_model(&device, &view).unwrap();
    let pose = skeleton
        .pose_from_angles(
            glam::Quat::from_rotation_y(0.3),
            Vec3::ZERO,
            &vec![0.2; skeleton.angle_count()],
        )
        .unwrap();
    let cpu_net = SkinNet::from_view(&view).unwrap();
    let mut cpu_frame = FrameState::new(&cpu_net);
    let mut scratch = Scratch::new(&cpu_net);

    let mut group = c.benchmark_group("skinnet_lbs_frame");
    group.sample_size(10);
    for n in vertex_counts() {
        let positions: Vec<Vec3> = (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
            })
            .collect();
        let normals = vec![Vec3::Y; n];
        let mesh = skinner
            .bind_mesh(&device, &queue, &gpu_model, &positions, &normals)
            .unwrap();
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        group.throughput(Throughput::Elements(n as u64));
        group.bench_function(BenchmarkId::new("gpu", n), |b| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let start = Instant::now();
                    // The pose goes through the CPU frame state, as the CPU path's does.
                    cpu_frame.set_pose(&cpu_net, &pose).unwrap();
                    skinner
                        .skin(&device, &queue, &mesh, &cpu_frame, Method::Lbs)
                        .unwrap();
                    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
                    total += start.elapsed();
                }
                total
            });
        });
        let cpu_mesh = BoundMesh::bind(&cpu_net, &positions).unwrap();
        let (mut out_p, mut out_n) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
        group.bench_function(BenchmarkId::new("cpu_runtime_1_thread", n), |b| {
            b.iter(|| {
                cpu_frame.set_pose(&cpu_net, &pose).unwrap();
                SkinJob {
                    model: &cpu_net,
                    mesh: &cpu_mesh,
                    frame: &cpu_frame,
                    method: Method::Lbs,
                    first_vertex: 0,
                    rest_normals: Some(&normals),
                    rest_tangents: None,
                    out_positions: &mut out_p,
                    out_normals: Some(&mut out_n),
                    out_tangents: None,
                    out_weights: None,
                }
                .run(&mut scratch)
                .unwrap();
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench_gpu);
criterion_main!(benches);
