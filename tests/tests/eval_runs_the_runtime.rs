//! `trainer eval` scores what ships: for a *trained* model exported as `trainer train` does, the
//! posed vertices of its `skf:` row are exactly those of the runtime's `SkinJob` run the way an
//! engine runs it (bind the mesh, pose a frame, skin), on every held-out test frame.

use glam::Vec3;
use skinfield_runtime::{BoundMesh, FrameState, Method, Scratch, SkinJob, SkinNetModel};
use skinfield_tests::tiny_trained_model;
use skinfield_trainer::eval::{PreparedSkinning, Skinning};

#[test]
fn the_skf_row_poses_exactly_as_the_runtimes_skin_job() {
    let dir = tempfile::tempdir().unwrap();
    let (capture, model) = tiny_trained_model(dir.path(), 10, 3);
    let path = dir.path().join("model.skf");
    std::fs::write(&path, model.to_bytes().unwrap()).unwrap();

    let row = PreparedSkinning::new(&capture, &Skinning::Skf(path.clone())).unwrap();
    let model = SkinNetModel::from_skf(&std::fs::read(&path).unwrap()).unwrap();
    let rest = &capture.template.positions;
    let mesh = BoundMesh::bind(&model, rest).unwrap();
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let mut engine = vec![Vec3::ZERO; rest.len()];
    assert!(!capture.test_frames.is_empty());
    for &f in &capture.test_frames {
        frame.set_pose(&model, &capture.poses[f]).unwrap();
        SkinJob {
            model: &model,
            mesh: &mesh,
            frame: &frame,
            method: Method::Lbs,
            first_vertex: 0,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut engine,
            out_normals: None,
            out_tangents: None,
            out_weights: None,
        }
        .run(&mut scratch)
        .unwrap();
        let scored = row.pose_frame(&capture, f).unwrap();
        assert_eq!(scored, engine, "test frame {f}");
        // And the model moved the mesh: the comparison is not between two rest poses.
        let moved = scored
            .iter()
            .zip(rest)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f32::max);
        assert!(moved > 1e-3, "frame {f} barely moved ({moved})");
    }
}
