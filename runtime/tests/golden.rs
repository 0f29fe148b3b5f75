//! Golden test: the runtime against an independent, straightforward f64 implementation of
//! SkinNet and LBS written here from the `.skf` tensors with naive loops.

mod common;

use glam::{Mat4, Vec3};
use skinfield_formats::pose_features;
use skinfield_formats::skf::{Net, SkfView};
use skinfield_runtime::{BoundMesh, FrameState, Kernel, Method, Scratch, SkinJob, SkinNetModel};

/// `[x̂, γ(x̂)]` in f64 straight from the definition in `formats::skf::ModelConfig`.
fn position_input(view: &SkfView<'_>, x: Vec3) -> Vec<f64> {
    let c = view.config();
    let xh: Vec<f64> = (0..3)
        .map(|k| {
            let (lo, hi) = (f64::from(c.bbox_min[k]), f64::from(c.bbox_max[k]));
            2.0 * (f64::from(x[k]) - lo) / (hi - lo) - 1.0
        })
        .collect();
    let mut v = xh.clone();
    for k in 0..c.pe_frequencies as i32 {
        let f = 2f64.powi(k) * std::f64::consts::PI;
        v.extend(xh.iter().map(|a| (f * a).sin()));
        v.extend(xh.iter().map(|a| (f * a).cos()));
    }
    v
}

/// SkinNet's weights of one point in f64: dense layers, skip concatenation, Softplus
/// `log(1 + exp(βx))/β`, softmax.
fn reference_weights(view: &SkfView<'_>, x: Vec3, theta: &[f32]) -> Vec<f64> {
    let c = view.config();
    let mut input = position_input(view, x);
    input.extend(theta.iter().map(|&t| f64::from(t)));
    let n = c.hidden_count as usize;
    let beta = f64::from(c.softplus_beta);
    let mut h = input.clone();
    for i in 0..=n {
        let (w, b) = view.layer(Net::Skin, i).unwrap();
        let inp: Vec<f64> = if i == c.skip_layer as usize && i > 0 {
            h.iter().chain(&input).copied().collect()
        } else {
            h.clone()
        };
        let (rows, cols) = (w.dims[0] as usize, w.dims[1] as usize);
        assert_eq!(cols, inp.len());
        h = (0..rows)
            .map(|o| {
                let s: f64 = (0..cols)
                    .map(|k| f64::from(w.get(o * cols + k).unwrap()) * inp[k])
                    .sum::<f64>()
                    + f64::from(b.get(o).unwrap());
                // ln(1 + e^{βs})/β, evaluated without overflow.
                if i < n {
                    (beta * s).max(0.0) / beta + (-(beta * s).abs()).exp().ln_1p() / beta
                } else {
                    s
                }
            })
            .collect();
    }
    let m = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let e: Vec<f64> = h.iter().map(|v| (v - m).exp()).collect();
    let s: f64 = e.iter().sum();
    e.iter().map(|v| v / s).collect()
}

fn check_config(bytes: &[u8], seed: u64, points: usize) {
    let view = SkfView::parse(bytes).unwrap();
    let mut model = SkinNetModel::from_skf(bytes).unwrap();
    let j = model.joint_count();
    let mut rng = common::rng(seed);
    let pts = common::random_points(points, &mut rng);
    let pose = common::random_pose(model.skeleton(), &mut rng, 0.7);
    let mut theta = vec![0.0; 3 * j];
    pose_features(model.skeleton(), &pose, view.config().up_axis, &mut theta).unwrap();
    let want: Vec<Vec<f64>> = pts
        .iter()
        .map(|p| reference_weights(&view, *p, &theta))
        .collect();
    // The weights must not be trivially one-hot or uniform, or the comparison proves little.
    let spread = want
        .iter()
        .map(|w| w.iter().copied().fold(0.0, f64::max))
        .sum::<f64>()
        / points as f64;
    assert!(
        spread > 1.5 / j as f64 && spread < 0.99,
        "degenerate fixture: mean max weight {spread}"
    );

    let mut mats = vec![Mat4::IDENTITY; j];
    model
        .skeleton()
        .skinning_matrices(&pose, &mut mats)
        .unwrap();
    for kernel in Kernel::ALL.into_iter().filter(|k| k.is_available()) {
        model.set_kernel(kernel).unwrap();
        let mut got = vec![0.0; points * j];
        model.weights_for(&pts, &pose, &mut got).unwrap();
        for (v, w) in want.iter().enumerate() {
            for (k, wk) in w.iter().enumerate() {
                let g = f64::from(got[v * j + k]);
                assert!(
                    (g - wk).abs() < 1e-5,
                    "{kernel:?} vertex {v} joint {k}: {g} vs {wk}"
                );
            }
        }
        // Skinned positions against LBS in f64 with the reference weights.
        let mesh = BoundMesh::bind(&model, &pts).unwrap();
        let mut frame = FrameState::new(&model);
        frame.set_pose(&model, &pose).unwrap();
        let mut out = vec![Vec3::ZERO; points];
        let mut job = SkinJob {
            model: &model,
            mesh: &mesh,
            frame: &frame,
            method: Method::Lbs,
            first_vertex: 0,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut out,
            out_normals: None,
            out_tangents: None,
            out_weights: None,
        };
        job.run(&mut Scratch::new(&model)).unwrap();
        for (v, (p, w)) in pts.iter().zip(&want).enumerate() {
            let mut x = [0f64; 3];
            for (m, wk) in mats.iter().zip(w) {
                let q = m.as_dmat4().transform_point3(p.as_dvec3());
                for c in 0..3 {
                    x[c] += wk * q[c];
                }
            }
            let d = (glam::DVec3::from_array(x) - out[v].as_dvec3()).length();
            assert!(d < 1e-4, "{kernel:?} vertex {v}: position off by {d}");
        }
    }
}

#[test]
fn vinecs_architecture_matches_f64_reference() {
    check_config(&common::vinecs_bytes(24, 11), 12, 70);
}

#[test]
fn odd_widths_match_f64_reference() {
    check_config(
        &common::random_model(common::odd_config(), 13)
            .to_bytes()
            .unwrap(),
        14,
        45,
    );
}

#[test]
fn config_without_skip_matches_f64_reference() {
    check_config(
        &common::random_model(common::no_skip_config(), 15)
            .to_bytes()
            .unwrap(),
        16,
        33,
    );
}
