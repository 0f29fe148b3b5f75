//! Retargeting between skeletons: onto itself it is the identity; onto a renamed, turned,
//! scaled copy with another rest pose every mapped bone points where the source's does (in
//! the target's frame) and the hips move by the source's displacement, turned and scaled; bad
//! maps and poses are typed errors.

use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::{Pose, Retarget, RetargetError, Skeleton, Transform};

/// (name, parent, rest offset from the parent) of a small humanoid.
const JOINTS: [(&str, Option<usize>, [f32; 3]); 16] = [
    ("hips", None, [0.0, 0.9, 0.0]),
    ("spine", Some(0), [0.0, 0.15, 0.0]),
    ("chest", Some(1), [0.0, 0.2, 0.0]),
    ("neck", Some(2), [0.0, 0.2, 0.0]),
    ("head", Some(3), [0.0, 0.1, 0.0]),
    ("l_shoulder", Some(2), [0.18, 0.15, 0.0]),
    ("l_elbow", Some(5), [0.28, 0.0, 0.0]),
    ("l_wrist", Some(6), [0.25, 0.0, 0.0]),
    ("r_shoulder", Some(2), [-0.18, 0.15, 0.0]),
    ("r_elbow", Some(8), [-0.28, 0.0, 0.0]),
    ("r_wrist", Some(9), [-0.25, 0.0, 0.0]),
    ("l_hip", Some(0), [0.1, -0.05, 0.0]),
    ("l_knee", Some(11), [0.0, -0.42, 0.0]),
    ("l_ankle", Some(12), [0.0, -0.4, 0.0]),
    ("r_hip", Some(0), [-0.1, -0.05, 0.0]),
    ("r_knee", Some(14), [0.0, -0.42, 0.0]),
];

/// The humanoid with names prefixed by `prefix`, offsets scaled by `scale`, above `base`, and
/// the rest rotation `l_shoulder_rest` at the left shoulder (an A-pose against a T-pose).
fn humanoid(prefix: &str, scale: f32, base: Mat4, l_shoulder_rest: Quat) -> Skeleton {
    let names = JOINTS.iter().map(|j| format!("{prefix}{}", j.0)).collect();
    let parents = JOINTS.iter().map(|j| j.1).collect();
    let bind = JOINTS
        .iter()
        .map(|j| {
            let rotation = if j.0 == "l_shoulder" {
                l_shoulder_rest
            } else {
                Quat::IDENTITY
            };
            Transform::from_rotation_translation(rotation, Vec3::from(j.2) * scale)
        })
        .collect();
    Skeleton::new(names, parents, bind, None, None, base).unwrap()
}

fn identity_map(prefix: &str) -> Vec<(String, String)> {
    JOINTS
        .iter()
        .map(|j| (format!("{prefix}{}", j.0), j.0.to_owned()))
        .collect()
}

/// A random pose: every joint turned by up to 60° about a random axis, the hips moved by up
/// to 0.3 in each axis.
fn random_pose(skeleton: &Skeleton, rng: &mut ChaCha8Rng) -> Pose {
    let mut pose = skeleton.bind_pose();
    for (j, local) in pose.locals.iter_mut().enumerate() {
        let axis = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize();
        let angle = rng.random_range(-1.05..1.05);
        local.rotation = (local.rotation * Quat::from_axis_angle(axis, angle)).normalize();
        if j == 0 {
            local.translation += Vec3::new(
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
            );
        }
    }
    pose
}

fn world(skeleton: &Skeleton, pose: &Pose) -> Vec<Mat4> {
    let mut out = vec![Mat4::IDENTITY; skeleton.len()];
    skeleton.world_matrices(pose, &mut out).unwrap();
    out
}

fn position(m: &Mat4) -> Vec3 {
    m.w_axis.truncate()
}

/// The unit vector from joint `j` to its child `c` in world space.
fn bone(world: &[Mat4], j: usize, c: usize) -> Vec3 {
    (position(&world[c]) - position(&world[j])).normalize()
}

#[test]
fn onto_itself_it_is_the_identity() {
    let skeleton = humanoid("", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    let retarget = Retarget::new(&skeleton, &skeleton, &identity_map("")).unwrap();
    assert!(retarget.frame().angle_between(Quat::IDENTITY) < 1e-4);
    assert!((retarget.scale() - 1.0).abs() < 1e-6);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..20 {
        let pose = random_pose(&skeleton, &mut rng);
        let out = retarget.apply(&pose).unwrap();
        for (a, b) in world(&skeleton, &pose).iter().zip(&world(&skeleton, &out)) {
            assert!(a.abs_diff_eq(*b, 1e-5), "{a} against {b}");
        }
    }
}

#[test]
fn a_turned_scaled_copy_recovers_its_frame_and_scale_and_moves_the_hips_with_the_source() {
    let source = humanoid("", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    // Facing the other way (a half turn, which a power iteration started at the identity
    // cannot find) and twice as large.
    let turn = Quat::from_rotation_y(std::f32::consts::PI);
    let target = humanoid("t_", 2.0, Mat4::from_quat(turn), Quat::IDENTITY);
    let retarget = Retarget::new(&source, &target, &identity_map("t_")).unwrap();
    assert!(
        retarget.frame().angle_between(turn) < 1e-4,
        "{:?}",
        retarget.frame()
    );
    assert!((retarget.scale() - 2.0).abs() < 1e-5);
    let source_rest = world(&source, &source.bind_pose());
    let target_rest = world(&target, &target.bind_pose());
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..20 {
        let pose = random_pose(&source, &mut rng);
        let (s, t) = (
            world(&source, &pose),
            world(&target, &retarget.apply(&pose).unwrap()),
        );
        // Same shape, turned and scaled: every joint where the source's is.
        for j in 0..source.len() {
            let expect = position(&target_rest[0])
                + turn * (position(&s[j]) - position(&source_rest[0])) * 2.0;
            assert!(
                position(&t[j]).abs_diff_eq(expect, 1e-4),
                "joint {j}: {} against {expect}",
                position(&t[j])
            );
        }
    }
}

#[test]
fn in_place_the_hips_keep_their_height_changes_and_drop_their_travel() {
    let source = humanoid("", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    let target = humanoid("t_", 2.0, Mat4::IDENTITY, Quat::IDENTITY);
    let travelling = Retarget::new(&source, &target, &identity_map("t_")).unwrap();
    let in_place = travelling.clone().in_place(Vec3::Y);
    let rest = position(&world(&target, &target.bind_pose())[0]);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    for _ in 0..10 {
        let pose = random_pose(&source, &mut rng);
        let moved = position(&world(&target, &travelling.apply(&pose).unwrap())[0]);
        let kept = position(&world(&target, &in_place.apply(&pose).unwrap())[0]);
        assert!((kept.y - moved.y).abs() < 1e-5);
        assert!((kept.x - rest.x).abs() < 1e-5 && (kept.z - rest.z).abs() < 1e-5);
        assert!((moved - kept).length() > 1e-3, "the source travelled");
    }
}

#[test]
fn another_rest_pose_still_points_every_mapped_bone_the_sources_way() {
    let source = humanoid("", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    // The target's left arm hangs 40° lower at rest (an A-pose), it is turned a quarter and
    // 1.3 times as large; its wrists and heads are not mapped (they follow their parents).
    let a_pose = Quat::from_rotation_z(-40f32.to_radians());
    let target = humanoid(
        "t_",
        1.3,
        Mat4::from_quat(Quat::from_rotation_y(0.5 * std::f32::consts::PI)),
        a_pose,
    );
    let map: Vec<(String, String)> = identity_map("t_")
        .into_iter()
        .filter(|(_, s)| !matches!(s.as_str(), "l_wrist" | "r_wrist" | "head"))
        .collect();
    let retarget = Retarget::new(&source, &target, &map).unwrap();
    let g = retarget.frame();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    // (joint, child) pairs whose joint's aim is the child: chains with a mapped child.
    let bones = [(1, 2), (3, 4), (5, 6), (8, 9), (11, 12), (12, 13), (14, 15)];
    let aimed_at_mapped = [(1, 2), (5, 6), (8, 9), (11, 12), (12, 13), (14, 15)];
    for _ in 0..20 {
        let pose = random_pose(&source, &mut rng);
        let (s, t) = (
            world(&source, &pose),
            world(&target, &retarget.apply(&pose).unwrap()),
        );
        for (j, c) in aimed_at_mapped {
            let (got, want) = (bone(&t, j, c), g * bone(&s, j, c));
            assert!(
                got.angle_between(want) < 1e-3,
                "bone {j}→{c}: {got} against {want}"
            );
        }
        // Bone lengths are the target's own.
        let rest = world(&target, &target.bind_pose());
        for (j, c) in bones {
            let len = |w: &[Mat4]| (position(&w[c]) - position(&w[j])).length();
            assert!((len(&t) - len(&rest)).abs() < 1e-4);
        }
    }
    // The source's rest pose puts the target's left arm straight out as the source's is.
    let t = world(&target, &retarget.apply(&source.bind_pose()).unwrap());
    assert!(bone(&t, 5, 6).angle_between(g * Vec3::X) < 1e-3);
}

#[test]
fn bad_maps_and_poses_are_typed_errors() {
    let source = humanoid("", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    let target = humanoid("t_", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    let pair = |t: &str, s: &str| (t.to_owned(), s.to_owned());
    assert_eq!(
        Retarget::new(&source, &target, &[]).unwrap_err(),
        RetargetError::EmptyMap
    );
    assert_eq!(
        Retarget::new(&source, &target, &[pair("t_hips", "pelvis")]).unwrap_err(),
        RetargetError::UnknownSourceJoint("pelvis".into())
    );
    assert_eq!(
        Retarget::new(&source, &target, &[pair("hips", "hips")]).unwrap_err(),
        RetargetError::UnknownTargetJoint("hips".into())
    );
    assert_eq!(
        Retarget::new(
            &source,
            &target,
            &[pair("t_hips", "hips"), pair("t_hips", "spine")]
        )
        .unwrap_err(),
        RetargetError::DuplicateTargetJoint("t_hips".into())
    );
    let retarget = Retarget::new(&source, &target, &identity_map("t_")).unwrap();
    let mut short = source.bind_pose();
    short.locals.pop();
    assert!(matches!(
        retarget.apply(&short),
        Err(RetargetError::SourcePose(_))
    ));
    let mut nan = source.bind_pose();
    nan.locals[3].rotation = Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0);
    assert!(matches!(
        retarget.apply(&nan),
        Err(RetargetError::SourcePose(_))
    ));
    // A source joint may drive several target joints.
    assert!(
        Retarget::new(
            &source,
            &target,
            &[pair("t_hips", "hips"), pair("t_spine", "hips")]
        )
        .is_ok()
    );
}

/// `skeleton` with joint `j`'s bind scale set to `scale`.
fn with_bind_scale(skeleton: &Skeleton, j: usize, scale: Vec3) -> Skeleton {
    let mut bind = skeleton.bind_local().to_vec();
    bind[j].scale = scale;
    Skeleton::new(
        skeleton.names().to_vec(),
        skeleton.parents().to_vec(),
        bind,
        None,
        None,
        skeleton.base(),
    )
    .unwrap()
}

#[test]
fn unequal_or_mirrored_scales_are_refused_and_uniform_ones_retarget() {
    let source = humanoid("", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    let target = humanoid("t_", 1.0, Mat4::IDENTITY, Quat::IDENTITY);
    let map = identity_map("t_");
    // A uniform scale (a rig modelled in centimetres, scaled at its hips) is a similarity.
    let uniform = with_bind_scale(&target, 0, Vec3::splat(0.01));
    assert!(Retarget::new(&source, &uniform, &map).is_ok());
    // The target's chest squashed: it and everything above it (the neck first) has no rotation.
    let squashed = with_bind_scale(&target, 2, Vec3::new(1.0, 2.0, 1.0));
    match Retarget::new(&source, &squashed, &map).unwrap_err() {
        RetargetError::NonUniformScale {
            skeleton,
            joint,
            scale,
            posed,
        } => {
            assert_eq!(
                (skeleton, joint.as_str(), posed),
                ("target", "t_chest", false)
            );
            assert!((scale[1] - 2.0).abs() < 1e-5, "{scale:?}");
        }
        e => panic!("{e}"),
    }
    // A mirrored source hip, driving a target joint.
    let mirrored = with_bind_scale(&source, 11, Vec3::new(-1.0, 1.0, 1.0));
    let err = Retarget::new(&mirrored, &target, &map).unwrap_err();
    assert!(
        matches!(&err, RetargetError::NonUniformScale { skeleton: "source", joint, .. } if joint == "l_hip"),
        "{err}"
    );
    // An unmapped source joint may scale as it likes: it drives nothing.
    let only_hips = [("t_hips".to_owned(), "hips".to_owned())];
    assert!(Retarget::new(&mirrored, &target, &only_hips).is_ok());
    // A source pose whose spine stretches along one axis.
    let retarget = Retarget::new(&source, &target, &map).unwrap();
    let mut stretched = source.bind_pose();
    stretched.locals[1].scale = Vec3::new(1.0, 1.0, 3.0);
    let err = retarget.apply(&stretched).unwrap_err();
    assert!(
        matches!(&err, RetargetError::NonUniformScale { skeleton: "source", joint, posed: true, .. } if joint == "spine"),
        "{err}"
    );
    assert!(err.to_string().contains("a pose to retarget"), "{err}");
}
