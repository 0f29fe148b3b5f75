//! Resampled templates through evaluation, rendering and a trained model: SkinNet poses a mesh
//! of any resolution over the capture's canonical space, static weights refuse to.

use skinfield_formats::gltf_io::write_gltf_character;
use skinfield_runtime::resample::{Target, resample, transfer_skin};
use skinfield_runtime::{BoundMesh, FrameState, Scratch, SkinNetModel, WeightsJob};

use super::tests::{root_only_skf, tiny_capture};
use super::*;

const OPTIONS: EvalOptions = EvalOptions {
    samples: 4000,
    seed: 11,
};

#[test]
fn a_subdivided_template_scores_like_the_original_surface_and_a_coarse_one_does_not() {
    // Subdivision does not move the surface, so with a rigid (root-only) skinning the posed
    // subdivided mesh *is* the posed original surface: equal metrics up to the sampling noise
    // (different sample points on the same surface). A coarse simplification changes the surface.
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let skf = dir.path().join("root.skf");
    root_only_skf(&capture, &skf);
    let skinning = Skinning::Skf(skf);
    let n = capture.template.vertex_count();
    let original = evaluate(&capture, &skinning, &OPTIONS).unwrap();
    let fine = resample(&capture.template, Target::Vertices(3 * n))
        .unwrap()
        .template;
    let dense = evaluate_template(&capture, &fine, &skinning, &OPTIONS).unwrap();
    assert!(
        (dense.chamfer_cm - original.chamfer_cm).abs() < 0.02 * original.chamfer_cm,
        "{dense:?} vs {original:?}"
    );
    // The same through the file `trainer resample` writes and `trainer eval --template` reads.
    let file = dir.path().join("fine.glb");
    let skin = transfer_skin(
        &crate::train::data::initial_weights(&capture).unwrap(),
        &resample(&capture.template, Target::Vertices(3 * n))
            .unwrap()
            .source,
    )
    .unwrap();
    write_gltf_character(&file, &capture.skeleton, &fine, &skin, None).unwrap();
    let loaded = load_template(&file).unwrap();
    assert_eq!(loaded.triangles, fine.triangles);
    assert_eq!(loaded.positions, fine.positions);
    // A mesh with as many vertices as the template but another vertex order has no vertex
    // correspondence with the truth: no worst-vertex figure.
    assert!(original.max_vertex_cm.is_some());
    let mut shuffled = capture.template.clone();
    shuffled.positions.reverse();
    shuffled.normals.reverse();
    let last = (n - 1) as u32;
    for t in &mut shuffled.triangles {
        *t = t.map(|i| last - i);
    }
    let same = evaluate_template(&capture, &shuffled, &skinning, &OPTIONS).unwrap();
    assert_eq!(same.max_vertex_cm, None);
    assert!((same.chamfer_cm - original.chamfer_cm).abs() < 0.02 * original.chamfer_cm);
    let coarse = resample(&capture.template, Target::Vertices(60))
        .unwrap()
        .template;
    let rough = evaluate_template(&capture, &coarse, &skinning, &OPTIONS).unwrap();
    assert!(
        (rough.chamfer_cm - original.chamfer_cm).abs() > 0.05 * original.chamfer_cm,
        "{rough:?} vs {original:?}"
    );
}

#[test]
fn static_weights_refuse_another_template_naming_the_method() {
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let coarse = resample(&capture.template, Target::Vertices(500))
        .unwrap()
        .template;
    let e = evaluate_template(&capture, &coarse, &Skinning::Oracle, &OPTIONS).unwrap_err();
    assert!(matches!(
        e,
        EvalError::TemplateMismatch {
            method: "oracle",
            ..
        }
    ));
    assert!(e.to_string().contains("skf:FILE"), "{e}");
    let e = load_template(&dir.path().join("missing.glb")).unwrap_err();
    assert!(e.to_string().contains("missing.glb"), "{e}");
}

#[test]
fn a_trained_model_poses_resampled_templates_without_nan() {
    let dir = tempfile::tempdir().unwrap();
    let capture = tiny_capture(dir.path());
    let initial = crate::train::data::initial_weights(&capture).unwrap();
    let options = crate::train::data::DataOptions {
        train_vertices: 800,
        ..Default::default()
    };
    let data = crate::train::data::train_data(&capture, &initial, &options).unwrap();
    let config = crate::train::TrainConfig {
        iterations: 2,
        warm_start_iterations: 3,
        batch: 1,
        checkpoint_every: 0,
        seed: 1,
        ..Default::default()
    };
    let mut trainer = crate::train::Trainer::new(data, config, false).unwrap();
    trainer.run(&dir.path().join("work"), false).unwrap();
    let bytes = trainer.skf_model().unwrap().to_bytes().unwrap();
    let model = SkinNetModel::from_skf(&bytes).unwrap();
    let j = model.joint_count();
    let n = capture.template.vertex_count();
    for target in [n / 4, 2 * n] {
        let t = resample(&capture.template, Target::Vertices(target))
            .unwrap()
            .template;
        let mesh = BoundMesh::bind(&model, &t.positions).unwrap();
        let mut scratch = Scratch::new(&model);
        for &frame in &capture.test_frames {
            let mut state = FrameState::new(&model);
            state.set_pose(&model, &capture.poses[frame]).unwrap();
            let mut weights = vec![f32::NAN; t.vertex_count() * j];
            WeightsJob {
                model: &model,
                mesh: &mesh,
                frame: &state,
                first_vertex: 0,
                out_weights: &mut weights,
            }
            .run(&mut scratch)
            .unwrap();
            for row in weights.chunks_exact(j) {
                assert!(row.iter().all(|w| w.is_finite() && *w >= 0.0));
                assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-3);
            }
            let posed = posing::pose_dense_lbs(
                &capture.skeleton,
                &weights,
                &t.positions,
                &capture.poses[frame],
            )
            .unwrap();
            assert!(posed.iter().all(|p| p.is_finite()), "frame {frame}");
        }
    }
}
