//! End-to-end checks of the evaluation on the tiny synthetic capture: only what must hold.

use std::path::Path;

use glam::Vec3;
use skinfield_formats::StaticSkin;
use skinfield_formats::capture::{Capture, load_capture};
use skinfield_formats::skf::{ModelConfig, Net, SkfModel};

use super::*;
use crate::synth::{SynthConfig, synthesize};

pub(super) fn tiny_capture(dir: &Path) -> Capture {
    synthesize(dir, &SynthConfig::tiny()).unwrap();
    load_capture(dir).unwrap()
}

/// A SkinNet that gives every point the root joint alone (zero weights, output bias e^30 for
/// the root): every template it poses moves rigidly with the root, so its result is known.
/// Written to `path`; also returned.
pub(super) fn root_only_skf(capture: &Capture, path: &Path) -> SkfModel {
    let b = capture.template.bounds().unwrap();
    let mut config = ModelConfig::paper_architecture(
        capture.skeleton.len() as u32,
        b.min.to_array(),
        b.max.to_array(),
    );
    config.pe_frequencies = 2;
    config.hidden_count = 3;
    config.hidden = [8, 8, 8, 0, 0, 0, 0, 0];
    let mut model = SkfModel {
        config,
        skeleton: capture.skeleton.clone(),
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    let shapes: Vec<(usize, usize)> = config.layer_shapes(Net::Skin).collect();
    let last = shapes.len() - 1;
    for (i, (out, inp)) in shapes.into_iter().enumerate() {
        let mut bias = vec![0.0; out];
        if i == last {
            bias[0] = 30.0;
        }
        model.push_layer(Net::Skin, i, vec![0.0; out * inp], out, inp, bias);
    }
    std::fs::write(path, model.to_bytes().unwrap()).unwrap();
    model
}

const OPTIONS: EvalOptions = EvalOptions {
    samples: 2000,
    seed: 5,
};

/// Static weights giving every vertex to one joint, or spreading it evenly over all of them.
fn write_weights(capture: &Capture, path: &Path, only: Option<usize>) {
    let (v, j) = (capture.template.vertex_count(), capture.skeleton.len());
    let mut dense = vec![0.0f32; v * j];
    for row in dense.chunks_mut(j) {
        match only {
            Some(k) => row[k] = 1.0,
            None => row.fill(1.0 / j as f32),
        }
    }
    write_static_weights(
        path,
        &capture.skeleton,
        &StaticSkin::from_dense(&dense, j).unwrap(),
    )
    .unwrap();
}

#[test]
fn ground_truth_against_itself_is_zero_and_dqs_beats_uniform_weights() {
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let frames =
        evaluate_frames(&capture, &OPTIONS, |f| Ok(capture.evaluation_gt_mesh(f)?)).unwrap();
    assert_eq!(frames.len(), capture.test_frames.len());
    for f in &frames {
        assert!(f.m2s_cm < 1e-4 && f.s2m_cm < 1e-4, "{f:?}");
    }

    let uniform = dir.path().join("uniform.json");
    write_weights(&capture, &uniform, None);
    let uniform_row = evaluate(&capture, &Skinning::Static(uniform), &OPTIONS).unwrap();
    let dqs_row = evaluate(&capture, &Skinning::OracleDqs, &OPTIONS).unwrap();
    assert_eq!(uniform_row.method, "static");
    assert_eq!(dqs_row.method, "oracle-dqs");
    assert_eq!(dqs_row.frames, capture.test_frames.len());
    assert!(
        dqs_row.chamfer_cm < uniform_row.chamfer_cm,
        "{dqs_row:?} vs {uniform_row:?}"
    );
    // Without initial weights in the capture, `initial` falls back to bone heat and must run.
    assert!(capture.initial_weights.is_none());
    let initial = evaluate(&capture, &Skinning::Initial, &OPTIONS).unwrap();
    assert!(
        initial.method == "initial" && initial.chamfer_cm.is_finite() && initial.chamfer_cm > 0.0,
        "{initial:?}"
    );
    for r in [&uniform_row, &dqs_row] {
        assert!((r.chamfer_cm - r.m2s_cm - r.s2m_cm).abs() < 1e-9);
    }
}

#[test]
fn our_dqs_matches_the_ground_truth_deformers_dqs() {
    // Two implementations written apart (evaluation here, the synthetic deformer in `synth`)
    // must pose the same weights identically.
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let skin = capture.evaluation_true_weights().unwrap().unwrap();
    let t = &capture.template;
    for &frame in &capture.test_frames {
        let pose = &capture.poses[frame];
        let ours = pose_static(
            &capture.skeleton,
            &skin,
            &t.positions,
            pose,
            Blend::DualQuaternion,
        )
        .unwrap();
        let theirs =
            crate::synth::deform::dqs(&capture.skeleton, &skin, &t.positions, &t.normals, pose)
                .unwrap()
                .0;
        let worst = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "frame {frame}: {worst} m");
        let lbs_ours =
            pose_static(&capture.skeleton, &skin, &t.positions, pose, Blend::Linear).unwrap();
        let lbs_theirs =
            crate::synth::deform::lbs(&capture.skeleton, &skin, &t.positions, pose).unwrap();
        let worst = lbs_ours
            .iter()
            .zip(&lbs_theirs)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "frame {frame}: lbs {worst} m");
    }
}

#[test]
fn a_skinnet_that_outputs_one_joint_scores_like_those_static_weights() {
    // A SkinNet whose weights are all zero and whose output bias favours the root by e^30 gives
    // (to 1e-13) the root alone for every point and pose, whatever the runtime's kernels do
    // inside; its `ours` row must equal the `static` row of root-only weights.
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let skf = dir.path().join("root.skf");
    let model = root_only_skf(&capture, &skf);
    let root_only = dir.path().join("root.json");
    write_weights(&capture, &root_only, Some(0));

    let ours = evaluate(&capture, &Skinning::Skf(skf.clone()), &OPTIONS).unwrap();
    let fixed = evaluate(&capture, &Skinning::Static(root_only), &OPTIONS).unwrap();
    assert_eq!(ours.method, "ours");
    assert!(
        (ours.chamfer_cm - fixed.chamfer_cm).abs() < 1e-4,
        "{ours:?} vs {fixed:?}"
    );
    assert!(ours.chamfer_cm > 0.0);

    // A model on other joint names is refused, naming the file.
    let mut other = model.clone();
    let mut names: Vec<String> = capture.skeleton.names().to_vec();
    names[1] = "renamed".into();
    other.skeleton = skinfield_formats::Skeleton::new(
        names,
        capture.skeleton.parents().to_vec(),
        capture.skeleton.bind_local().to_vec(),
        Some(capture.skeleton.inverse_bind().to_vec()),
        None,
        capture.skeleton.base(),
    )
    .unwrap();
    let bad = dir.path().join("other.skf");
    std::fs::write(&bad, other.to_bytes().unwrap()).unwrap();
    let e = evaluate(&capture, &Skinning::Skf(bad), &OPTIONS)
        .unwrap_err()
        .to_string();
    assert!(e.contains("other.skf") && e.contains("renamed"), "{e}");
}

#[test]
fn missing_inputs_are_typed_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut capture = tiny_capture(dir.path());
    let e = evaluate(
        &capture,
        &Skinning::Static(dir.path().join("absent.json")),
        &OPTIONS,
    )
    .unwrap_err();
    assert!(e.to_string().contains("absent.json"), "{e}");
    capture.test_frames.clear();
    let e = evaluate(&capture, &Skinning::Oracle, &OPTIONS).unwrap_err();
    assert!(matches!(e, EvalError::NoTestFrames(_)), "{e}");
    capture.manifest.evaluation = None;
    let e = evaluate(&capture, &Skinning::Oracle, &OPTIONS).unwrap_err();
    assert!(matches!(e, EvalError::NoTrueWeights(_)), "{e}");
}

#[test]
fn skinning_arguments_parse() {
    assert_eq!("initial".parse(), Ok(Skinning::Initial));
    assert_eq!("oracle".parse(), Ok(Skinning::Oracle));
    assert_eq!("oracle-dqs".parse(), Ok(Skinning::OracleDqs));
    assert_eq!(
        "static:a/b.json".parse(),
        Ok(Skinning::Static("a/b.json".into()))
    );
    assert_eq!("skf:m.skf".parse(), Ok(Skinning::Skf("m.skf".into())));
    for bad in ["", "static:", "skf", "ours", "lbs:x"] {
        assert!(bad.parse::<Skinning>().is_err(), "{bad}");
    }
    let names: Vec<&str> = [
        Skinning::Initial,
        Skinning::Static("f".into()),
        Skinning::Skf("f".into()),
        Skinning::Oracle,
        Skinning::OracleDqs,
    ]
    .iter()
    .map(Skinning::method_name)
    .collect();
    assert_eq!(names, ["initial", "static", "ours", "oracle", "oracle-dqs"]);
}

#[test]
fn per_vertex_error_of_the_truth_is_zero_and_render_writes_camera_sized_images() {
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let frame = capture.test_frames[0];
    let truth = capture.evaluation_gt_mesh(frame).unwrap();
    assert!(
        per_vertex_m2s(&capture, frame, &truth)
            .unwrap()
            .iter()
            .all(|&e| e < 1e-6)
    );
    let shifted: Vec<Vec3> = truth
        .iter()
        .map(|p| *p + Vec3::new(0.0, 0.0, 0.01))
        .collect();
    let e = per_vertex_m2s(&capture, frame, &shifted).unwrap();
    // A 1 cm shift moves no vertex further than 1 cm from the surface it came from.
    assert!(e.iter().all(|&d| d <= 0.01 + 1e-6) && e.iter().any(|&d| d > 0.001));

    let cam = &capture.rig.cameras[0];
    let image = capture.load_image(0, frame).unwrap();
    let over = render::overlay(cam, &image.rgb, &truth, &capture.template.triangles).unwrap();
    assert_eq!(over.len(), (cam.width * cam.height) as usize);
    assert_ne!(over, image.rgb);
}

#[test]
fn worst_vertex_and_relative_figures_follow_a_known_shift() {
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    // The ground truth moved by 1 cm: every vertex is exactly 1 cm from its true position.
    let shift = Vec3::new(0.0, 0.006, 0.008);
    let shifted = |f: usize| -> Result<Vec<Vec3>, EvalError> {
        Ok(capture
            .evaluation_gt_mesh(f)?
            .iter()
            .map(|p| *p + shift)
            .collect())
    };
    let frames = evaluate_frames(&capture, &OPTIONS, shifted).unwrap();
    for f in &frames {
        let worst = f.max_vertex_cm.unwrap();
        assert!((worst - 1.0).abs() < 1e-4, "{f:?}");
        // Every shifted vertex is at most 1 cm from its true position, which is on the
        // surface; the nearest surface point may be closer.
        assert!(
            f.max_off_surface_cm > 0.0 && f.max_off_surface_cm <= 1.0 + 1e-4,
            "{f:?}"
        );
    }
    // The truth itself: nothing off the surface.
    let exact =
        evaluate_frames(&capture, &OPTIONS, |f| Ok(capture.evaluation_gt_mesh(f)?)).unwrap();
    assert!(
        exact.iter().all(|f| f.max_off_surface_cm < 1e-4),
        "{exact:?}"
    );
    // One vertex spiked 5 m along x: it is at least as far from the surface as from the
    // truth's bounding box, and both worst-vertex figures see it.
    let spike = Vec3::new(5.0, 0.0, 0.0);
    let spiked = evaluate_frames(&capture, &OPTIONS, |f| {
        let mut p = capture.evaluation_gt_mesh(f)?;
        p[0] += spike;
        Ok(p)
    })
    .unwrap();
    for (f, &frame) in spiked.iter().zip(&capture.test_frames) {
        let truth = capture.evaluation_gt_mesh(frame).unwrap();
        let lo = truth.iter().fold(Vec3::splat(f32::MAX), |a, b| a.min(*b));
        let hi = truth.iter().fold(Vec3::splat(f32::MIN), |a, b| a.max(*b));
        let p = truth[0] + spike;
        let to_box = f64::from((p - p.clamp(lo, hi)).length()) * 100.0;
        assert!(f.max_off_surface_cm >= to_box - 1e-3, "{f:?} {to_box}");
        assert!(f.max_off_surface_cm <= 500.0 + 1e-3, "{f:?}");
        assert!((f.max_vertex_cm.unwrap() - 500.0).abs() < 1e-3, "{f:?}");
    }
    // The size is the rest template's bounding-box diagonal, from its extreme coordinates.
    let p = &capture.template.positions;
    let lo = p.iter().fold(Vec3::splat(f32::MAX), |a, b| a.min(*b));
    let hi = p.iter().fold(Vec3::splat(f32::MIN), |a, b| a.max(*b));
    let size = character_size(&capture.template);
    assert!(
        (size - f64::from((hi - lo).length())).abs() < 1e-6,
        "{size}"
    );
    let row = average("shifted", &frames, size);
    // Percent of the size: Chamfer (cm → model units ÷ 100) / size × 100.
    assert!((row.chamfer_pct - row.chamfer_cm / 100.0 / size * 100.0).abs() < 1e-9);
    assert!((row.max_vertex_cm.unwrap() - 1.0).abs() < 1e-4);
    assert!((row.max_vertex_pct.unwrap() - 1.0 / size).abs() < 1e-4);
    assert_eq!(row.per_frame.len(), capture.test_frames.len());
    assert!(
        row.per_frame
            .iter()
            .zip(&capture.test_frames)
            .all(|(r, &f)| r.frame == f)
    );

    // The method rows carry the per-frame worst vertex; the truth's own weights under DQS are
    // closer to the truth than uniform weights on every frame.
    let uniform = dir.path().join("uniform.json");
    write_weights(&capture, &uniform, None);
    let uniform_row = evaluate(&capture, &Skinning::Static(uniform), &OPTIONS).unwrap();
    let dqs_row = evaluate(&capture, &Skinning::OracleDqs, &OPTIONS).unwrap();
    let check = worst_vertex_check(&dqs_row, &uniform_row).unwrap();
    assert!(check.passed(), "{check:?}");
    assert!(!worst_vertex_check(&uniform_row, &dqs_row).unwrap().passed());
    let check = off_surface_check(&dqs_row, &uniform_row).unwrap();
    assert!(check.passed(), "{check:?}");
    assert!(!off_surface_check(&uniform_row, &dqs_row).unwrap().passed());

    // A posed mesh with other vertices has no vertex correspondence: no worst vertex.
    let mut triangles = capture.template.triangles.clone();
    triangles.truncate(triangles.len() / 2);
    let frames = evaluate_mesh_frames(&capture, &triangles, &OPTIONS, |f| {
        let mut p = capture.evaluation_gt_mesh(f)?;
        p.push(Vec3::ZERO);
        Ok(p)
    })
    .unwrap();
    assert!(frames.iter().all(|f| f.max_vertex_cm.is_none()));
    assert_eq!(average("other", &frames, size).max_vertex_cm, None);
    // The off-surface figure needs no correspondence: only the extra vertex at the origin is
    // off the surface, by no more than its distance to the nearest true vertex.
    for (f, &frame) in frames.iter().zip(&capture.test_frames) {
        let truth = capture.evaluation_gt_mesh(frame).unwrap();
        let nearest = truth.iter().map(|p| p.length()).fold(f32::MAX, f32::min);
        assert!(
            f.max_off_surface_cm <= f64::from(nearest) * 100.0 + 1e-3,
            "{f:?}"
        );
    }
    assert!(average("other", &frames, size).max_off_surface_cm.is_some());
}

#[test]
fn bind_skins_are_the_weights_each_skinning_gives_at_the_bind_pose() {
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let bind =
        |s: &Skinning| PreparedSkinning::new(&capture, s).and_then(|p| p.bind_skin(&capture));
    // The root-only SkinNet (output bias e^30 for the root) gives every vertex the root alone.
    let skf = dir.path().join("root.skf");
    root_only_skf(&capture, &skf);
    let skin = bind(&Skinning::Skf(skf)).unwrap();
    assert_eq!(skin.vertex_count(), capture.template.vertex_count());
    let j = capture.skeleton.len();
    for (v, row) in skin.to_dense().chunks(j).enumerate() {
        assert!((row[0] - 1.0).abs() < 1e-6, "vertex {v}: {row:?}");
        assert!(row[1..].iter().all(|w| *w < 1e-6), "vertex {v}: {row:?}");
    }
    // Static weights are their own bind skin; the oracle is the capture's true weights.
    let oracle = bind(&Skinning::Oracle).unwrap();
    assert_eq!(
        oracle.to_dense(),
        capture
            .evaluation_true_weights()
            .unwrap()
            .unwrap()
            .to_dense()
    );
    // Per-frame fits have none.
    assert!(matches!(
        bind(&Skinning::BoundPose),
        Err(EvalError::NoBindWeights("bound-pose"))
    ));
}
