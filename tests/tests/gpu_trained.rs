//! A *trained* SkinNet on the GPU: train briefly on the tiny synthetic capture (warm start and
//! silhouette iterations, so the weights are no longer their random initialisation), export the
//! `.skf`, and skin the capture's full template in its held-out test poses on the GPU and with
//! the runtime's CPU path. Weights, positions and normals agree within 1e-4, LBS and DQS.
//!
//! Runs on any wgpu adapter, Mesa's lavapipe included. Without one the test skips with a
//! message, except under `CI=true`, where it fails.

use glam::Vec3;
use skinfield_formats::skf::SkfView;
use skinfield_runtime::gpu::{GpuSkinner, SkinnedVertex, headless_device};
use skinfield_runtime::{BoundMesh, FrameState, Method, Scratch, SkinJob, SkinNet};
use skinfield_tests::tiny_trained_model;

const TOL: f32 = 1e-4;

#[test]
fn trained_model_on_the_gpu_equals_the_cpu_path() {
    let (adapter, device, queue) = match headless_device(wgpu::Limits::default()) {
        Ok(d) => d,
        Err(e) => {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "CI=true but no wgpu device ({e}): install mesa-vulkan-drivers (lavapipe)"
            );
            eprintln!("skipping GPU test: {e}; install mesa-vulkan-drivers for lavapipe");
            return;
        }
    };
    eprintln!("GPU test on {}", adapter.get_info().name);

    let dir = tempfile::tempdir().unwrap();
    // Exported as `trainer train` does: with its candidate joints (CAND), which the GPU's
    // masked softmax must honour like the CPU path.
    let (capture, model) = tiny_trained_model(dir.path(), 20, 5);
    assert!(model.candidates.is_some());
    let bytes = model.to_bytes().unwrap();
    let view = SkfView::parse(&bytes).unwrap();
    let cpu_net = SkinNet::from_view(&view).unwrap();

    let template = &capture.template;
    let (positions, normals) = (&template.positions, &template.normals);
    let n = positions.len();
    let j = capture.skeleton.len();
    let skinner = GpuSkinner::new(&device).unwrap();
    let model = skinner.bind_model(&device, &view).unwrap();
    let mesh = skinner
        .bind_mesh(&device, &queue, &model, positions, normals)
        .unwrap();
    let cpu_mesh = BoundMesh::bind(&cpu_net, positions).unwrap();
    let mut cpu_frame = FrameState::new(&cpu_net);
    let mut scratch = Scratch::new(&cpu_net);
    let (mut cpu_p, mut cpu_n) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
    let mut cpu_w = vec![0.0; n * j];
    let mut worst = 0.0f32;
    for &f in &capture.test_frames {
        let pose = &capture.poses[f];
        cpu_frame.set_pose(&cpu_net, pose).unwrap();
        for method in [Method::Lbs, Method::Dqs] {
            skinner
                .skin(&device, &queue, &mesh, &cpu_frame, method)
                .unwrap();
            let weights = mesh.read_weights(&device, &queue).unwrap();
            let out: Vec<SkinnedVertex> = mesh.read_vertices(&device, &queue).unwrap();
            SkinJob {
                model: &cpu_net,
                mesh: &cpu_mesh,
                frame: &cpu_frame,
                method,
                first_vertex: 0,
                rest_normals: Some(normals),
                rest_tangents: None,
                out_positions: &mut cpu_p,
                out_normals: Some(&mut cpu_n),
                out_tangents: None,
                out_weights: Some(&mut cpu_w),
            }
            .run(&mut scratch)
            .unwrap();
            for (k, (g, c)) in weights.iter().zip(&cpu_w).enumerate() {
                assert!(
                    (g - c).abs() <= TOL,
                    "frame {f} {method:?} weight {k}: {g} vs {c}"
                );
            }
            for v in 0..n {
                for (what, g, c) in [
                    ("position", &out[v].position[..3], cpu_p[v]),
                    ("normal", &out[v].normal[..3], cpu_n[v]),
                ] {
                    let d = (Vec3::from_slice(g) - c).abs().max_element();
                    worst = worst.max(d);
                    assert!(
                        d <= TOL,
                        "frame {f} {method:?} {what} of vertex {v}: {g:?} vs {c}"
                    );
                }
            }
        }
    }
    // The model is trained, not uniform: its weights differ from the uniform blend somewhere.
    let spread = cpu_w
        .chunks(j)
        .map(|w| w.iter().fold(0.0f32, |m, &x| m.max(x)))
        .fold(0.0f32, f32::max);
    assert!(spread > 0.5, "max weight {spread}: the model did not train");
    eprintln!(
        "{n} vertices, {} test poses: worst GPU − CPU {worst:.2e}",
        capture.test_frames.len()
    );
}
