//! GPU path = the runtime's CPU path (`SkinJob`) and = an independent f64 CPU forward of SkinNet
//! and LBS/DQS written here from the `.skf` tensors, within 1e-4.
//!
//! Runs on any wgpu adapter, Mesa's lavapipe included. Without an adapter the tests skip with a
//! message, except under `CI=true`, where they fail so they can never silently skip.

use glam::{DMat3, DMat4, DQuat, DVec3, Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::{Candidates, ModelConfig, Net, SkfModel, SkfView};
use skinfield_formats::{Pose, Skeleton, Transform, UpAxis, pose_feature_count, pose_features};
use skinfield_runtime::RuntimeError;
use skinfield_runtime::gpu::{GpuError, GpuSkinner, SkinnedVertex, WeightFormat, headless_device};
use skinfield_runtime::{BoundMesh, FrameState, Method, Scratch, SkinJob, SkinNet};

const TOL: f64 = 1e-4;

/// A device (and whether its adapter runs `unpack2x16float`), or `None` to skip.
fn device_with(limits: wgpu::Limits) -> Option<(wgpu::Device, wgpu::Queue, bool)> {
    let (adapter, device, queue) = match headless_device(limits) {
        Ok(d) => d,
        Err(e) => {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "CI=true but no wgpu device ({e}): install mesa-vulkan-drivers (lavapipe)"
            );
            eprintln!(
                "skipping GPU test: no wgpu device ({e}); install mesa-vulkan-drivers for lavapipe"
            );
            return None;
        }
    };
    let info = adapter.get_info();
    eprintln!(
        "GPU tests on {} ({:?}, {:?})",
        info.name, info.device_type, info.backend
    );
    let unpack = adapter
        .get_downlevel_capabilities()
        .flags
        .contains(wgpu::DownlevelFlags::SHADER_F16_IN_F32);
    Some((device, queue, unpack))
}

fn device() -> Option<(wgpu::Device, wgpu::Queue, bool)> {
    device_with(wgpu::Limits::default())
}

/// A random tree skeleton with bind transforms and a random pose of it.
fn skeleton_and_pose(joints: usize, rng: &mut ChaCha8Rng) -> (Skeleton, Pose) {
    let names = (0..joints).map(|j| format!("j{j}")).collect();
    let parents: Vec<Option<usize>> = (0..joints)
        .map(|j| {
            if j == 0 {
                None
            } else {
                Some(rng.random_range(0..j))
            }
        })
        .collect();
    let rot = |rng: &mut ChaCha8Rng, a: f32| {
        let axis = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        Quat::from_axis_angle(
            axis.try_normalize().unwrap_or(Vec3::Y),
            rng.random_range(-a..a),
        )
    };
    let bind: Vec<Transform> = (0..joints)
        .map(|j| {
            let t = if j == 0 {
                Vec3::new(0.0, 0.1, 0.0)
            } else {
                Vec3::new(
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                    rng.random_range(-0.3..0.3),
                )
            };
            Transform::from_rotation_translation(rot(rng, 0.5), t)
        })
        .collect();
    let skeleton = Skeleton::new(names, parents, bind.clone(), None, None, Mat4::IDENTITY).unwrap();
    let locals = bind
        .iter()
        .enumerate()
        .map(|(j, b)| {
            let mut t = *b;
            // Large rotations, so that some joints' quaternions land in opposite hemispheres.
            t.rotation = (b.rotation * rot(rng, 2.5)).normalize();
            if j == 0 {
                t.translation += Vec3::new(0.2, -0.1, 0.3);
            }
            t
        })
        .collect();
    (skeleton, Pose { locals })
}

/// A `.skf` with random SkinNet weights of the shapes `config` implies (He-like scale so the
/// activations stay O(1) through the layers).
fn random_model(config: ModelConfig, seed: u64) -> (Vec<u8>, Skeleton, Pose) {
    let (model, skeleton, pose) = random_skf_model(config, seed);
    (model.to_bytes().unwrap(), skeleton, pose)
}

/// [`random_model`] before serialisation.
fn random_skf_model(config: ModelConfig, seed: u64) -> (SkfModel, Skeleton, Pose) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (skeleton, pose) = skeleton_and_pose(config.joint_count as usize, &mut rng);
    let mut model = SkfModel {
        config,
        skeleton: skeleton.clone(),
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    let shapes: Vec<_> = config.layer_shapes(Net::Skin).collect();
    for (l, &(out, inp)) in shapes.iter().enumerate() {
        let scale = 2.0 / (inp as f32).sqrt();
        let w = (0..out * inp)
            .map(|_| rng.random_range(-scale..scale))
            .collect();
        let b = (0..out).map(|_| rng.random_range(-0.3..0.3)).collect();
        model.push_layer(Net::Skin, l, w, out, inp, b);
    }
    (model, skeleton, pose)
}

/// Positions inside (and slightly outside) the configuration's box, random unit normals.
fn random_mesh(config: &ModelConfig, n: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let positions = (0..n)
        .map(|_| {
            Vec3::from_array(core::array::from_fn(|k| {
                let (lo, hi) = (config.bbox_min[k], config.bbox_max[k]);
                let pad = 0.05 * (hi - lo);
                rng.random_range(lo - pad..hi + pad)
            }))
        })
        .collect();
    let normals = (0..n)
        .map(|_| {
            let v = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            v.try_normalize().unwrap_or(Vec3::Z)
        })
        .collect();
    (positions, normals)
}

fn softplus(x: f64, beta: f64) -> f64 {
    x.max(0.0) + (-(beta * x).abs()).exp().ln_1p() / beta
}

/// Straightforward f64 SkinNet: full input vector, every layer a dense product.
struct Reference {
    config: ModelConfig,
    /// Per layer: weight `[out][in]`, bias.
    layers: Vec<(Vec<Vec<f64>>, Vec<f64>)>,
}

impl Reference {
    fn new(view: &SkfView<'_>) -> Self {
        let config = *view.config();
        let layers = (0..=config.hidden_widths().len())
            .map(|l| {
                let (w, b) = view.layer(Net::Skin, l).unwrap();
                let (out, inp) = (w.dims[0] as usize, w.dims[1] as usize);
                let rows = (0..out)
                    .map(|o| {
                        (0..inp)
                            .map(|i| f64::from(w.get(o * inp + i).unwrap()))
                            .collect()
                    })
                    .collect();
                (
                    rows,
                    (0..out).map(|o| f64::from(b.get(o).unwrap())).collect(),
                )
            })
            .collect();
        Self { config, layers }
    }

    fn weights(&self, x: Vec3, features: &[f32]) -> Vec<f64> {
        let c = &self.config;
        let mut input = Vec::new();
        let xh: Vec<f64> = (0..3)
            .map(|k| {
                let (lo, hi) = (f64::from(c.bbox_min[k]), f64::from(c.bbox_max[k]));
                2.0 * (f64::from(x[k]) - lo) / (hi - lo) - 1.0
            })
            .collect();
        input.extend(&xh);
        for f in 0..c.pe_frequencies {
            let s = 2f64.powi(f as i32) * std::f64::consts::PI;
            input.extend(xh.iter().map(|v| (s * v).sin()));
            input.extend(xh.iter().map(|v| (s * v).cos()));
        }
        input.extend(features.iter().map(|&f| f64::from(f)));
        let n = self.layers.len() - 1;
        let beta = f64::from(c.softplus_beta);
        let mut h = input.clone();
        for (l, (w, b)) in self.layers.iter().enumerate() {
            let x_in: Vec<f64> = if l == c.skip_layer as usize && l > 0 {
                h.iter().chain(&input).copied().collect()
            } else {
                h
            };
            h = w
                .iter()
                .zip(b)
                .map(|(row, b)| {
                    assert_eq!(row.len(), x_in.len());
                    let z = b + row.iter().zip(&x_in).map(|(w, x)| w * x).sum::<f64>();
                    if l < n { softplus(z, beta) } else { z }
                })
                .collect();
        }
        let m = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let e: Vec<f64> = h.iter().map(|z| (z - m).exp()).collect();
        let s: f64 = e.iter().sum();
        e.iter().map(|v| v / s).collect()
    }
}

fn lbs(w: &[f64], mats: &[DMat4], p: DVec3, n: DVec3) -> (DVec3, DVec3) {
    let m = w
        .iter()
        .zip(mats)
        .fold(DMat4::ZERO, |acc, (&w, m)| acc + *m * w);
    // Normals follow the transformed triangles: det(M) · M⁻ᵀ (the kernel uses cross products).
    let m3 = DMat3::from_mat4(m);
    (
        m.transform_point3(p),
        (m3.inverse().transpose() * m3.determinant() * n).normalize(),
    )
}

fn dqs(w: &[f64], mats: &[DMat4], p: DVec3, n: DVec3) -> (DVec3, DVec3) {
    let dq: Vec<(DQuat, DQuat)> = mats
        .iter()
        .map(|m| {
            let r = DQuat::from_mat4(m).normalize();
            let t = m.w_axis.truncate();
            (r, DQuat::from_xyzw(t.x, t.y, t.z, 0.0) * r * 0.5)
        })
        .collect();
    let pivot = (0..w.len()).fold(0, |best, j| if w[j] > w[best] { j } else { best });
    let (mut br, mut bd) = (
        DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
    );
    for (j, (r, d)) in dq.iter().enumerate() {
        let s = if r.dot(dq[pivot].0) < 0.0 {
            -w[j]
        } else {
            w[j]
        };
        br += *r * s;
        bd += *d * s;
    }
    let len = br.length();
    let (br, bd) = (br * (1.0 / len), bd * (1.0 / len));
    let t = (bd * br.conjugate()) * 2.0;
    (br * p + DVec3::new(t.x, t.y, t.z), (br * n).normalize())
}

fn close(what: &str, v: usize, gpu: &[f32], cpu: &[f64]) {
    for (k, (&g, &c)) in gpu.iter().zip(cpu).enumerate() {
        assert!(
            (f64::from(g) - c).abs() <= TOL,
            "{what} of vertex {v}[{k}]: GPU {g} vs CPU {c}"
        );
    }
}

/// Binds `config`'s random model and a random mesh of each size, skins one pose with LBS and
/// DQS and compares weights, positions and normals with the f64 reference.
fn check_model(
    (device, queue): (&wgpu::Device, &wgpu::Queue),
    skinner: &GpuSkinner,
    config: ModelConfig,
    sizes: &[usize],
    format: Option<WeightFormat>,
    seed: u64,
) {
    let (bytes, skeleton, pose) = random_model(config, seed);
    let view = SkfView::parse(&bytes).unwrap();
    let net = Reference::new(&view);
    let model = skinner.bind_model_as(device, &view, format).unwrap();
    let mut features = vec![0.0; pose_feature_count(skeleton.len())];
    pose_features(&skeleton, &pose, UpAxis::Y, &mut features).unwrap();
    let mut mats = vec![Mat4::IDENTITY; skeleton.len()];
    skeleton.skinning_matrices(&pose, &mut mats).unwrap();
    let dmats: Vec<DMat4> = mats.iter().map(Mat4::as_dmat4).collect();
    let cpu_net = SkinNet::from_view(&view).unwrap();
    let mut cpu_frame = FrameState::new(&cpu_net);
    cpu_frame.set_pose(&cpu_net, &pose).unwrap();
    let mut scratch = Scratch::new(&cpu_net);
    for (i, &n) in sizes.iter().enumerate() {
        let (positions, normals) = random_mesh(&config, n, seed + 100 + i as u64);
        let mesh = skinner
            .bind_mesh(device, queue, &model, &positions, &normals)
            .unwrap();
        let reference: Vec<Vec<f64>> = positions
            .iter()
            .map(|&p| net.weights(p, &features))
            .collect();
        let cpu_mesh = BoundMesh::bind(&cpu_net, &positions).unwrap();
        for mode in [Method::Lbs, Method::Dqs] {
            skinner
                .skin(device, queue, &mesh, &cpu_frame, mode)
                .unwrap();
            let weights = mesh.read_weights(device, queue).unwrap();
            let out: Vec<SkinnedVertex> = mesh.read_vertices(device, queue).unwrap();
            assert_eq!(
                (weights.len(), out.len()),
                (n * config.joint_count as usize, n)
            );
            // The runtime's CPU path on the same inputs.
            let (mut cpu_p, mut cpu_n) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
            let mut cpu_w = vec![0.0; weights.len()];
            SkinJob {
                model: &cpu_net,
                mesh: &cpu_mesh,
                frame: &cpu_frame,
                method: mode,
                first_vertex: 0,
                rest_normals: Some(&normals),
                rest_tangents: None,
                out_positions: &mut cpu_p,
                out_normals: Some(&mut cpu_n),
                out_tangents: None,
                out_weights: Some(&mut cpu_w),
            }
            .run(&mut scratch)
            .unwrap();
            let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
            close("weights vs CPU path", 0, &weights, &widen(&cpu_w));
            for v in 0..n {
                close(
                    &format!("{mode:?} position vs CPU path"),
                    v,
                    &out[v].position[..3],
                    &widen(&cpu_p[v].to_array()),
                );
                close(
                    &format!("{mode:?} normal vs CPU path"),
                    v,
                    &out[v].normal[..3],
                    &widen(&cpu_n[v].to_array()),
                );
                let w = &reference[v];
                close("weights", v, &weights[v * w.len()..(v + 1) * w.len()], w);
                let (p, nrm) = (positions[v].as_dvec3(), normals[v].as_dvec3());
                let (cp, cn) = match mode {
                    Method::Lbs => lbs(w, &dmats, p, nrm),
                    Method::Dqs => dqs(w, &dmats, p, nrm),
                };
                close(
                    &format!("{mode:?} position"),
                    v,
                    &out[v].position,
                    &[cp.x, cp.y, cp.z, 1.0],
                );
                close(
                    &format!("{mode:?} normal"),
                    v,
                    &out[v].normal,
                    &[cn.x, cn.y, cn.z, 0.0],
                );
            }
        }
    }
}

fn small_config() -> ModelConfig {
    let mut c = ModelConfig::paper_architecture(5, [-0.5, -0.2, -0.4], [0.6, 1.1, 0.3]);
    // Odd widths exercise the kernel's unpaired last column; skip connection into layer 2.
    c.pe_frequencies = 2;
    c.hidden_count = 4;
    c.hidden = [9, 7, 12, 5, 0, 0, 0, 0];
    c.skip_layer = 2;
    c
}

#[test]
fn small_model_matches_cpu_reference_at_tile_boundaries() {
    let Some((device, queue, unpack)) = device() else {
        return;
    };
    let skinner = GpuSkinner::new(&device).unwrap();
    check_model(
        (&device, &queue),
        &skinner,
        small_config(),
        &[1, 63, 64, 65],
        None,
        1,
    );
    if unpack {
        let skinner = GpuSkinner::with_unpack2x16float(&device, true).unwrap();
        check_model((&device, &queue), &skinner, small_config(), &[65], None, 1);
    } else {
        eprintln!("adapter lacks SHADER_F16_IN_F32: unpack2x16float variant not run");
    }
}

/// A model with candidate joints (`CAND`): the GPU's masked softmax equals the CPU path's,
/// weight for weight and vertex for vertex, and every non-candidate weighs exactly zero.
#[test]
fn candidate_joints_mask_the_gpu_softmax_like_the_cpu_path() {
    let Some((device, queue, _)) = device() else {
        return;
    };
    let skinner = GpuSkinner::new(&device).unwrap();
    let config = small_config();
    let joints = config.joint_count as usize;
    let (mut model, skeleton, pose) = random_skf_model(config, 7);
    // 40 random anchors in the box, each with 1–3 random ascending candidates.
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let (positions, _) = random_mesh(&config, 40, 9);
    let k = 3;
    let lists: Vec<Vec<u16>> = positions
        .iter()
        .map(|_| {
            let mut l: Vec<u16> = (0..joints as u16)
                .filter(|_| rng.random_bool(0.4))
                .collect();
            l.truncate(k);
            if l.is_empty() {
                l.push(rng.random_range(0..joints as u16));
            }
            l
        })
        .collect();
    model.candidates = Some(Candidates {
        positions: positions.iter().map(|p| p.to_array()).collect(),
        lists: lists.clone(),
        k,
    });
    let bytes = model.to_bytes().unwrap();
    let view = SkfView::parse(&bytes).unwrap();
    let gpu_model = skinner.bind_model(&device, &view).unwrap();
    let cpu_net = SkinNet::from_view(&view).unwrap();
    let mut frame = FrameState::new(&cpu_net);
    frame.set_pose(&cpu_net, &pose).unwrap();
    let mut features = vec![0.0; pose_feature_count(skeleton.len())];
    pose_features(&skeleton, &pose, UpAxis::Y, &mut features).unwrap();
    let mut mats = vec![Mat4::IDENTITY; skeleton.len()];
    skeleton.skinning_matrices(&pose, &mut mats).unwrap();
    // The mesh: the anchors themselves (each takes its own list) and 25 other points.
    let (mut mesh_positions, mut normals) = random_mesh(&config, 25, 10);
    mesh_positions.extend(&positions);
    normals.extend(std::iter::repeat_n(Vec3::Y, positions.len()));
    let n = mesh_positions.len();
    let mesh = skinner
        .bind_mesh(&device, &queue, &gpu_model, &mesh_positions, &normals)
        .unwrap();
    skinner
        .skin(&device, &queue, &mesh, &frame, Method::Lbs)
        .unwrap();
    let weights = mesh.read_weights(&device, &queue).unwrap();
    let out: Vec<SkinnedVertex> = mesh.read_vertices(&device, &queue).unwrap();
    let cpu_mesh = BoundMesh::bind(&cpu_net, &mesh_positions).unwrap();
    let (mut cpu_p, mut cpu_w) = (vec![Vec3::ZERO; n], vec![0.0; n * joints]);
    SkinJob {
        model: &cpu_net,
        mesh: &cpu_mesh,
        frame: &frame,
        method: Method::Lbs,
        first_vertex: 0,
        rest_normals: None,
        rest_tangents: None,
        out_positions: &mut cpu_p,
        out_normals: None,
        out_tangents: None,
        out_weights: Some(&mut cpu_w),
    }
    .run(&mut Scratch::new(&cpu_net))
    .unwrap();
    let widen = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
    close("masked weights vs CPU path", 0, &weights, &widen(&cpu_w));
    for v in 0..n {
        close(
            "masked LBS position vs CPU path",
            v,
            &out[v].position[..3],
            &widen(&cpu_p[v].to_array()),
        );
    }
    for (a, list) in lists.iter().enumerate() {
        let row = &weights[(25 + a) * joints..(26 + a) * joints];
        for (j, &w) in row.iter().enumerate() {
            if !list.contains(&(j as u16)) {
                assert_eq!(w, 0.0, "anchor {a}, joint {j} is not a candidate");
            }
        }
        assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }
}

#[test]
fn f32_weight_storage_and_no_skip_model_match() {
    let Some((device, queue, _)) = device() else {
        return;
    };
    let skinner = GpuSkinner::new(&device).unwrap();
    let mut c = ModelConfig::paper_architecture(7, [-1.0; 3], [1.0; 3]);
    c.pe_frequencies = 3;
    c.hidden_count = 3;
    c.hidden = [33, 64, 17, 0, 0, 0, 0, 0];
    c.skip_layer = 0;
    check_model(
        (&device, &queue),
        &skinner,
        c,
        &[17, 40],
        Some(WeightFormat::F32),
        2,
    );
    check_model(
        (&device, &queue),
        &skinner,
        c,
        &[17],
        Some(WeightFormat::F16),
        2,
    );
}

#[test]
fn paper_architecture_matches_cpu_reference() {
    let Some((device, queue, _)) = device() else {
        return;
    };
    let skinner = GpuSkinner::new(&device).unwrap();
    let c = ModelConfig::paper_architecture(24, [-0.9, -1.0, -0.3], [0.9, 0.8, 0.35]);
    check_model((&device, &queue), &skinner, c, &[65, 2000], None, 3);
}

#[test]
fn dispatches_split_in_2d_beyond_the_per_dimension_limit() {
    // A device limited to 16 workgroups per dimension forces the big dispatches of this test
    // into two dimensions (300 vertices: 99 position-term groups → 16 × 7, 19 SkinNet tiles
    // → 16 × 2).
    let limits = wgpu::Limits {
        max_compute_workgroups_per_dimension: 16,
        ..wgpu::Limits::default()
    };
    let Some((device, queue, _)) = device_with(limits) else {
        return;
    };
    let skinner = GpuSkinner::new(&device).unwrap();
    check_model((&device, &queue), &skinner, small_config(), &[300], None, 4);
}

#[test]
fn bad_inputs_are_typed_errors() {
    let Some((device, queue, _)) = device() else {
        return;
    };
    let skinner = GpuSkinner::new(&device).unwrap();
    let mut wide = small_config();
    wide.hidden[1] = 300;
    let (bytes, _, _) = random_model(wide, 5);
    let err = skinner
        .bind_model(&device, &SkfView::parse(&bytes).unwrap())
        .err()
        .unwrap();
    assert!(
        matches!(
            err,
            GpuError::Unsupported {
                what: "hidden width",
                value: 300,
                max: 256
            }
        ),
        "{err}"
    );

    let (bytes, skeleton, _) = random_model(small_config(), 6);
    let view = SkfView::parse(&bytes).unwrap();
    let model = skinner.bind_model(&device, &view).unwrap();
    assert!(matches!(
        skinner.bind_mesh(&device, &queue, &model, &[], &[]),
        Err(GpuError::Input(RuntimeError::VertexCount(0)))
    ));
    let p = [Vec3::ZERO, Vec3::ONE];
    assert!(matches!(
        skinner.bind_mesh(&device, &queue, &model, &p, &p[..1]),
        Err(GpuError::Input(RuntimeError::BufferLength {
            field: "normals",
            len: 1,
            expected: 2
        }))
    ));
    let bad = [Vec3::ZERO, Vec3::new(0.0, f32::NAN, 0.0)];
    assert!(matches!(
        skinner.bind_mesh(&device, &queue, &model, &bad, &p),
        Err(GpuError::Input(RuntimeError::NonFinite {
            field: "positions",
            index: 1
        }))
    ));
    let mesh = skinner.bind_mesh(&device, &queue, &model, &p, &p).unwrap();
    let mats = vec![Mat4::IDENTITY; skeleton.len()];
    let feats = vec![0.0; pose_feature_count(skeleton.len())];
    assert!(matches!(
        skinner.upload_raw(&queue, &mesh, &mats[1..], &feats),
        Err(GpuError::Input(RuntimeError::BufferLength {
            field: "skinning matrices",
            ..
        }))
    ));
    assert!(matches!(
        skinner.upload_raw(&queue, &mesh, &mats, &feats[1..]),
        Err(GpuError::Input(RuntimeError::BufferLength {
            field: "pose features",
            ..
        }))
    ));
    skinner.upload_raw(&queue, &mesh, &mats, &feats).unwrap();
    // A frame state that was never posed (or whose last pose failed) is refused.
    let cpu_net = SkinNet::from_view(&view).unwrap();
    let frame = FrameState::new(&cpu_net);
    assert!(matches!(
        skinner.upload_frame(&queue, &mesh, &frame),
        Err(GpuError::Input(RuntimeError::NoPose))
    ));
}
