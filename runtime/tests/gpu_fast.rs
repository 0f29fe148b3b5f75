//! The fast path on the GPU = the CPU fast path (`FastFrame`, `FastSkinJob`, `TopKJob`) within
//! 1e-4 (quantised top-k weights within one unit, and summing exactly to one), on small meshes
//! (lavapipe runs ~1 GFLOP/s). Without an adapter the tests skip with a message, except under
//! `CI=true`, where they fail.

mod common;

use glam::Vec3;
use skinfield_formats::skf::SkfView;
use skinfield_runtime::RuntimeError;
use skinfield_runtime::gpu::{
    FastOutputs, GpuError, GpuFastOptions, GpuSkinner, TopKIndexFormat, TopKWeightFormat,
    headless_device,
};
use skinfield_runtime::{
    FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, Method, Scratch, SkinNetModel,
    TopKIndices, TopKJob, TopKWeights,
};

const TOL: f32 = 1e-4;

fn device() -> Option<(wgpu::Device, wgpu::Queue)> {
    match headless_device(wgpu::Limits::default()) {
        Ok((adapter, d, q)) => {
            let info = adapter.get_info();
            eprintln!(
                "GPU tests on {} ({:?}, {:?})",
                info.name, info.device_type, info.backend
            );
            Some((d, q))
        }
        Err(e) => {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "CI=true but no wgpu device ({e}): install mesa-vulkan-drivers (lavapipe)"
            );
            eprintln!("skipping GPU test: no wgpu device ({e})");
            None
        }
    }
}

struct Cpu {
    mesh: FastMesh,
    frame: FrameState,
    nodes: FastFrame,
    normals: Vec<Vec3>,
}

fn cpu(bytes: &[u8], options: &FastOptions, seed: u64) -> Cpu {
    let model = SkinNetModel::from_skf(bytes).unwrap();
    let (positions, normals, triangles) = common::ellipsoid(7, 10);
    let mesh = FastMesh::bind(&model, &positions, &triangles, options).unwrap();
    let pose = common::random_pose(model.skeleton(), &mut common::rng(seed), 0.7);
    let mut frame = FrameState::new(&model);
    frame.set_pose(&model, &pose).unwrap();
    let mut nodes = FastFrame::new(&mesh);
    nodes
        .update(&model, &mesh, &frame, &mut Scratch::new(&model))
        .unwrap();
    Cpu {
        mesh,
        frame,
        nodes,
        normals,
    }
}

fn close(what: &str, gpu: &[f32], cpu: &[f32]) {
    assert_eq!(gpu.len(), cpu.len(), "{what}");
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        assert!((g - c).abs() <= TOL, "{what}[{i}]: GPU {g} vs CPU {c}");
    }
}

fn check(bytes: &[u8], options: &FastOptions, seed: u64) {
    let Some((device, queue)) = device() else {
        return;
    };
    let c = cpu(bytes, options, seed);
    let skinner = GpuSkinner::new(&device).unwrap();
    let view = SkfView::parse(bytes).unwrap();
    let model = skinner.bind_model(&device, &view).unwrap();
    let n = c.mesh.vertex_count();
    for (k, idx, wf) in [
        (4, TopKIndexFormat::U8, TopKWeightFormat::Unorm8),
        (8, TopKIndexFormat::U16, TopKWeightFormat::Unorm16),
        (4, TopKIndexFormat::U16, TopKWeightFormat::F32),
    ] {
        let gpu_options = GpuFastOptions {
            dqs_influences: k,
            top_k: Some((k, idx, wf)),
        };
        let mesh = skinner
            .bind_fast_mesh(&device, &queue, &model, &c.mesh, &c.normals, &gpu_options)
            .unwrap();
        for method in [Method::Lbs, Method::Dqs] {
            skinner
                .skin_fast(
                    &device,
                    &queue,
                    &mesh,
                    &c.frame,
                    FastOutputs {
                        skinning: Some(method),
                        top_k: true,
                    },
                )
                .unwrap();
            close(
                "node weights",
                &mesh.read_node_weights(&device, &queue).unwrap(),
                c.nodes.node_weights(),
            );
            let out = mesh.read_vertices(&device, &queue).unwrap();
            let (mut p, mut nn) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
            FastSkinJob {
                mesh: &c.mesh,
                frame: &c.frame,
                nodes: &c.nodes,
                method,
                influences: k,
                first_vertex: 0,
                rest_normals: Some(&c.normals),
                rest_tangents: None,
                out_positions: &mut p,
                out_normals: Some(&mut nn),
                out_tangents: None,
                out_weights: None,
            }
            .run()
            .unwrap();
            for v in 0..n {
                close(
                    &format!("{method:?} position {v}"),
                    &out[v].position[..3],
                    &p[v].to_array(),
                );
                close(
                    &format!("{method:?} normal {v}"),
                    &out[v].normal[..3],
                    &nn[v].to_array(),
                );
            }
        }
        // Top-k: the same joints, weights within one unit and summing exactly to one.
        let (gi, gw) = mesh.read_top_k(&device, &queue).unwrap();
        let mut ci16 = vec![0u16; n * k];
        let mut ci8 = vec![0u8; n * k];
        let (mut w8, mut w16, mut w32) = (vec![0u8; n * k], vec![0u16; n * k], vec![0f32; n * k]);
        let indices = match idx {
            TopKIndexFormat::U8 => TopKIndices::U8(&mut ci8),
            TopKIndexFormat::U16 => TopKIndices::U16(&mut ci16),
        };
        let weights = match wf {
            TopKWeightFormat::Unorm8 => TopKWeights::Unorm8(&mut w8),
            TopKWeightFormat::Unorm16 => TopKWeights::Unorm16(&mut w16),
            TopKWeightFormat::F32 => TopKWeights::F32(&mut w32),
        };
        TopKJob {
            mesh: &c.mesh,
            frame: &c.frame,
            nodes: &c.nodes,
            influences: k,
            first_vertex: 0,
            out_indices: indices,
            out_weights: weights,
        }
        .run()
        .unwrap();
        let cpu_idx: Vec<u32> = match idx {
            TopKIndexFormat::U8 => ci8.iter().map(|&x| u32::from(x)).collect(),
            TopKIndexFormat::U16 => ci16.iter().map(|&x| u32::from(x)).collect(),
        };
        let gpu_idx: Vec<u32> = match idx {
            TopKIndexFormat::U8 => gi.iter().map(|&x| u32::from(x)).collect(),
            TopKIndexFormat::U16 => bytemuck::pod_collect_to_vec::<u8, u16>(&gi)
                .iter()
                .map(|&x| u32::from(x))
                .collect(),
        };
        assert_eq!(gpu_idx, cpu_idx, "top-{k} joints ({idx:?})");
        let (gpu_w, cpu_w, one): (Vec<f64>, Vec<f64>, f64) = match wf {
            TopKWeightFormat::Unorm8 => (
                gi_to(&gw, |b| f64::from(b[0]), 1),
                w8.iter().map(|&x| f64::from(x)).collect(),
                255.0,
            ),
            TopKWeightFormat::Unorm16 => (
                gi_to(&gw, |b| f64::from(u16::from_le_bytes([b[0], b[1]])), 2),
                w16.iter().map(|&x| f64::from(x)).collect(),
                65535.0,
            ),
            TopKWeightFormat::F32 => (
                gi_to(
                    &gw,
                    |b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                    4,
                ),
                w32.iter().map(|&x| f64::from(x)).collect(),
                1.0,
            ),
        };
        let unit = if wf == TopKWeightFormat::F32 {
            f64::from(TOL)
        } else {
            1.0
        };
        for v in 0..n {
            let g = &gpu_w[v * k..(v + 1) * k];
            assert_eq!(g.iter().sum::<f64>(), one, "vertex {v} sums to one");
            for (a, b) in g.iter().zip(&cpu_w[v * k..(v + 1) * k]) {
                assert!((a - b).abs() <= unit, "vertex {v}: GPU {g:?} vs CPU");
            }
        }
    }
}

fn gi_to(bytes: &[u8], f: impl Fn(&[u8]) -> f64, size: usize) -> Vec<f64> {
    bytes.chunks_exact(size).map(f).collect()
}

#[test]
fn fast_path_matches_the_cpu_with_the_papers_architecture() {
    check(
        &common::vinecs_bytes(24, 31),
        &FastOptions {
            nodes: 24,
            ..FastOptions::DEFAULT
        },
        32,
    );
}

#[test]
fn fast_path_matches_the_cpu_without_base_and_with_odd_widths() {
    let bytes = common::random_model(common::odd_config(), 33)
        .to_bytes()
        .unwrap();
    check(
        &bytes,
        &FastOptions {
            nodes: 10,
            neighbours: 3,
            base_influences: 0,
            ..FastOptions::DEFAULT
        },
        34,
    );
}

#[test]
fn fast_bad_inputs_are_typed_errors() {
    let Some((device, queue)) = device() else {
        return;
    };
    let bytes = common::vinecs_bytes(6, 35);
    let c = cpu(&bytes, &FastOptions::DEFAULT, 36);
    let skinner = GpuSkinner::new(&device).unwrap();
    let model = skinner
        .bind_model(&device, &SkfView::parse(&bytes).unwrap())
        .unwrap();
    let bind = |normals: &[Vec3], o: GpuFastOptions| {
        skinner
            .bind_fast_mesh(&device, &queue, &model, &c.mesh, normals, &o)
            .err()
    };
    let d = GpuFastOptions::default();
    assert!(matches!(
        bind(&c.normals[1..], d),
        Some(GpuError::Input(RuntimeError::BufferLength {
            field: "normals",
            ..
        }))
    ));
    let mut nan = c.normals.clone();
    nan[3].x = f32::NAN;
    assert!(matches!(
        bind(&nan, d),
        Some(GpuError::Input(RuntimeError::NonFinite {
            field: "normals",
            index: 3
        }))
    ));
    for (o, field) in [
        (
            GpuFastOptions {
                dqs_influences: 0,
                ..d
            },
            "dqs_influences",
        ),
        (
            GpuFastOptions {
                dqs_influences: 9,
                ..d
            },
            "dqs_influences",
        ),
        (
            GpuFastOptions {
                top_k: Some((3, TopKIndexFormat::U8, TopKWeightFormat::F32)),
                ..d
            },
            "top_k influences",
        ),
    ] {
        assert!(
            matches!(bind(&c.normals, o), Some(GpuError::Setting { field: f, .. }) if f == field),
            "{field}"
        );
    }
    // A model with other joints than the mesh's.
    let other = skinner
        .bind_model(
            &device,
            &SkfView::parse(&common::vinecs_bytes(7, 37)).unwrap(),
        )
        .unwrap();
    assert!(matches!(
        skinner.bind_fast_mesh(&device, &queue, &other, &c.mesh, &c.normals, &d),
        Err(GpuError::Input(RuntimeError::BufferLength {
            field: "fast mesh joints",
            len: 6,
            expected: 7
        }))
    ));
    // Top-k output from a mesh bound without a layout.
    let mesh = skinner
        .bind_fast_mesh(
            &device,
            &queue,
            &model,
            &c.mesh,
            &c.normals,
            &GpuFastOptions { top_k: None, ..d },
        )
        .unwrap();
    let mut encoder = device.create_command_encoder(&Default::default());
    assert!(matches!(
        skinner.encode_fast(
            &mut encoder,
            &mesh,
            FastOutputs {
                skinning: None,
                top_k: true
            }
        ),
        Err(GpuError::Setting { .. })
    ));
    // A frame of a model with another joint count.
    let other = SkinNetModel::from_skf(&common::vinecs_bytes(5, 37)).unwrap();
    let mut frame = FrameState::new(&other);
    frame
        .set_pose(&other, &other.skeleton().bind_pose())
        .unwrap();
    assert!(matches!(
        skinner.upload_fast_frame(&queue, &mesh, &frame),
        Err(GpuError::Input(RuntimeError::BufferLength {
            field: "skinning matrices",
            ..
        }))
    ));
}
