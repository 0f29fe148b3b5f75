use std::collections::BTreeMap;
use std::path::Path;

use glam::{Mat4, Quat, Vec3};
use skinfield_formats::capture::{Capture, NO_LABEL, load_capture};

use crate::losses::silhouette::outline::Outline;

use super::body::Part;
use super::character::{bind_positions, joint};
use super::deform::{DeformParts, SKIRT_CLEARANCE, dqs, lbs};
use super::*;

fn small() -> SynthConfig {
    SynthConfig {
        grid: 48,
        target_vertices: 3000,
        ..SynthConfig::tiny()
    }
}

/// Every file under `dir` (relative path → bytes).
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

#[test]
fn same_seed_same_bytes_other_seed_other_bytes() {
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    synthesize(a.path(), &SynthConfig::tiny()).unwrap();
    synthesize(b.path(), &SynthConfig::tiny()).unwrap();
    synthesize(
        c.path(),
        &SynthConfig {
            seed: 1,
            ..SynthConfig::tiny()
        },
    )
    .unwrap();
    let (ta, tb, tc) = (tree(a.path()), tree(b.path()), tree(c.path()));
    assert!(ta.len() > 10, "{:?}", ta.keys());
    assert_eq!(ta.keys().collect::<Vec<_>>(), tb.keys().collect::<Vec<_>>());
    for (k, v) in &ta {
        assert!(
            tb[k] == *v,
            "{k} differs between two runs with the same seed"
        );
    }
    assert_ne!(ta["motion.json"], tc["motion.json"]);
    assert_ne!(ta["template.json"], tc["template.json"]);
}

#[test]
fn synthetic_capture_loads_back_with_everything_in_place() {
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig::tiny();
    let summary = synthesize(dir.path(), &config).unwrap();
    let character = build_character(&config).unwrap();
    let cap = load_capture(dir.path()).unwrap();
    assert_eq!(cap.template, character.template);
    assert_eq!(cap.skeleton, character.skeleton);
    assert_eq!(cap.rig.cameras.len(), 2);
    assert_eq!((cap.train_frames.len(), cap.test_frames.len()), (5, 3));
    assert_eq!(
        (summary.train_frames, summary.test_frames, summary.vertices),
        (5, 3, cap.template.vertex_count())
    );
    assert!(
        cap.initial_weights.is_none(),
        "the trainer computes its own initial weights"
    );
    let truth = cap.evaluation_true_weights().unwrap().unwrap();
    assert_eq!(
        (truth.offsets(), truth.joints()),
        (
            character.deformer.skin().offsets(),
            character.deformer.skin().joints()
        )
    );
    assert!(
        truth
            .weights()
            .iter()
            .zip(character.deformer.skin().weights())
            .all(|(a, b)| (a - b).abs() < 1e-6)
    );
    for &f in &cap.test_frames {
        let gt = cap.evaluation_gt_mesh(f).unwrap();
        let (want, _) = character.deformer.deform(&cap.poses[f]).unwrap();
        assert_eq!(gt, want);
    }
    // The canonical frame is the bind pose, whose ground truth is the template itself.
    let canonical = cap.canonical_frame();
    assert_eq!(canonical, cap.frame_count() - 1);
    assert_eq!(
        cap.evaluation_gt_mesh(canonical).unwrap(),
        cap.template.positions
    );
    // Label images: a part wherever the subject fully covers a pixel, none where it is absent,
    // and both parts seen.
    for cam in 0..2 {
        let labels = cap.load_labels(cam, canonical).unwrap().unwrap();
        let mask = cap.load_mask(cam, canonical).unwrap();
        for (l, c) in labels.labels.iter().zip(&mask.coverage) {
            assert!(
                (*c < 1.0 || *l != NO_LABEL) && (*c > 0.0 || *l == NO_LABEL),
                "label {l} at coverage {c}"
            );
        }
        assert!((0..2).all(|part| labels.labels.contains(&part)));
    }
    // Images carry the subject where the mask says so, and the background elsewhere. The mask
    // holds coverage from 4 × 4 samples and the image one sample per pixel, so only fully
    // covered and fully empty pixels must agree.
    for cam in 0..2 {
        let img = cap.load_image(cam, 0).unwrap();
        let mask = cap.load_mask(cam, 0).unwrap();
        let inside = mask.coverage.iter().filter(|&&c| c >= 1.0).count();
        assert!(inside > 60, "{inside} subject pixels");
        let partial = mask
            .coverage
            .iter()
            .filter(|&&c| c > 0.0 && c < 1.0)
            .count();
        assert!(
            partial > 20,
            "only {partial} pixels of partial coverage: not anti-aliased"
        );
        let mut lit = 0;
        for (px, &c) in img.rgb.iter().zip(&mask.coverage) {
            let bg = (*px - output::BACKGROUND).abs().max_element() < 0.01;
            if c >= 1.0 {
                lit += usize::from(!bg);
            } else if c == 0.0 {
                assert!(bg, "pixel {px} outside the mask is not background");
            }
        }
        // Dark shoes in shadow may come close to the background; the subject as a whole does not.
        assert!(
            lit * 10 > inside * 9,
            "{lit} of {inside} subject pixels differ from the background"
        );
    }
}

fn posed(character: &Character, set: &[(usize, usize, f32)]) -> skinfield_formats::Pose {
    let s = &character.skeleton;
    let mut offsets = Vec::new();
    let mut k = 0;
    for d in s.dofs() {
        offsets.push(k);
        k += d.count();
    }
    let mut angles = vec![0.0; k];
    for &(j, axis, v) in set {
        angles[offsets[j] + axis] = v;
    }
    s.pose_from_angles(Quat::IDENTITY, Vec3::ZERO, &angles)
        .unwrap()
}

#[test]
fn dqs_keeps_a_twisted_forearm_round_where_lbs_collapses() {
    let s = character::build_skeleton().unwrap();
    // Rings of points around the left forearm (axis y = 1.39, z = 0) at and beside the twist
    // joint (x = 0.575), skinned with the true-weight rule, then twisted by 1.5 rad.
    let (mut positions, mut normals) = (Vec::new(), Vec::new());
    for x in [0.55f32, 0.575, 0.60] {
        for k in 0..32 {
            let a = std::f32::consts::TAU * k as f32 / 32.0;
            let n = Vec3::new(0.0, a.cos(), a.sin());
            positions.push(Vec3::new(x, 1.39, 0.0) + n * 0.037);
            normals.push(n);
        }
    }
    let skin = weights::true_weights(&s, &positions, &[]).unwrap();
    let mut angles = vec![0.0; s.angle_count()];
    let forearm = s.dofs()[..joint::L_FOREARM]
        .iter()
        .map(|d| d.count())
        .sum::<usize>();
    angles[forearm] = 1.5;
    let pose = s
        .pose_from_angles(Quat::IDENTITY, Vec3::ZERO, &angles)
        .unwrap();
    let (d, _) = dqs(&s, &skin, &positions, &normals, &pose).unwrap();
    let l = lbs(&s, &skin, &positions, &pose).unwrap();
    let radius = |p: Vec3| Vec3::new(0.0, p.y - 1.39, p.z).length();
    // At the twist joint the weights are split about evenly: LBS averages a point and its
    // 1.5 rad rotation, shrinking the radius towards cos(0.75) ≈ 0.73; DQS rotates it.
    let mid = 32..64;
    let rd = d[mid.clone()].iter().map(|p| radius(*p)).sum::<f32>() / 32.0 / 0.037;
    let rl = l[mid].iter().map(|p| radius(*p)).sum::<f32>() / 32.0 / 0.037;
    assert!((rd - 1.0).abs() < 0.01, "DQS radius ratio {rd}");
    assert!(rl < 0.85, "LBS radius ratio {rl} (candy wrapper expected)");
    assert!(d.iter().all(|p| (radius(*p) / 0.037 - 1.0).abs() < 0.01));
}

#[test]
fn bulge_and_skirt_push_out_move_the_surface_beyond_dqs() {
    let ch = build_character(&small()).unwrap();
    // Elbow flexed 2 rad: skin near the elbow moves outwards, the head does not.
    let pose = posed(&ch, &[(joint::L_ELBOW, 0, -2.0)]);
    let (base, base_n) = ch
        .deformer
        .deform_with(&pose, DeformParts::DQS_ONLY)
        .unwrap();
    let (bulged, _) = ch
        .deformer
        .deform_with(
            &pose,
            DeformParts {
                bulge: true,
                skirt: false,
            },
        )
        .unwrap();
    let elbow = bind_positions(&ch.skeleton)[joint::L_ELBOW];
    let mut near_max = 0.0f32;
    for v in 0..base.len() {
        let d = bulged[v] - base[v];
        let dist = (ch.template.positions[v] - elbow).length();
        if dist < 0.05 {
            near_max = near_max.max(d.length());
            assert!(d.dot(base_n[v]) >= -1e-6, "bulge must go outwards");
        }
        if dist > 0.4 {
            assert!(
                d.length() < 1e-6,
                "vertex {v} far from the elbow moved by {}",
                d.length()
            );
        }
    }
    assert!(near_max > 0.01, "bulge at the elbow only {near_max} m");

    // Vertices marked rigid (here: those within 5 cm of the elbow) do not bulge; the rest bulge
    // as before.
    let rigid: Vec<bool> = ch
        .template
        .positions
        .iter()
        .map(|p| (*p - elbow).length() < 0.05)
        .collect();
    let hard = ch.deformer.clone().with_rigid_vertices(rigid.clone());
    let only_bulge = DeformParts {
        bulge: true,
        skirt: false,
    };
    let (hard_bulged, _) = hard.deform_with(&pose, only_bulge).unwrap();
    for v in 0..base.len() {
        let want = if rigid[v] { base[v] } else { bulged[v] };
        assert!(
            (hard_bulged[v] - want).length() < 1e-6,
            "vertex {v} (rigid: {})",
            rigid[v]
        );
    }

    // Left thigh kicked forward: the skirt is pushed off the leg, and ends outside every leg.
    let pose = posed(&ch, &[(joint::L_HIP, 0, -1.3)]);
    let (base, _) = ch
        .deformer
        .deform_with(&pose, DeformParts::DQS_ONLY)
        .unwrap();
    let (pushed, _) = ch
        .deformer
        .deform_with(
            &pose,
            DeformParts {
                bulge: false,
                skirt: true,
            },
        )
        .unwrap();
    let mut world = vec![Mat4::IDENTITY; ch.skeleton.len()];
    ch.skeleton.world_matrices(&pose, &mut world).unwrap();
    let (hip, knee) = (
        world[joint::L_HIP].w_axis.truncate(),
        world[joint::L_KNEE].w_axis.truncate(),
    );
    let mut moved = 0.0f32;
    let mut inside_before = 0;
    for v in (0..base.len()).filter(|&v| ch.parts[v] == Part::Skirt) {
        moved = moved.max((pushed[v] - base[v]).length());
        let (d0, t0) = super::character::segment_distance(base[v], hip, knee);
        let r = 0.078 + (0.054 - 0.078) * t0 + SKIRT_CLEARANCE;
        inside_before += usize::from(d0 < r - 1e-3);
        let (d, t) = super::character::segment_distance(pushed[v], hip, knee);
        let r = 0.078 + (0.054 - 0.078) * t + SKIRT_CLEARANCE;
        assert!(
            d >= r - 1e-3,
            "skirt vertex {v} inside the thigh ({d} < {r})"
        );
    }
    assert!(
        inside_before > 5,
        "DQS alone lets the thigh pierce the skirt ({inside_before} vertices)"
    );
    assert!(moved > 0.02, "push-out moved the skirt by only {moved} m");
    // Other vertices are untouched by the skirt stage.
    for v in (0..base.len()).filter(|&v| ch.parts[v] != Part::Skirt) {
        assert!((pushed[v] - base[v]).length() < 1e-6);
    }
}

#[test]
fn witch_gltf_capture_loads_back_and_its_ground_truth_is_not_lbs() {
    let Some(data) = skinfield_formats::shared_data::shared_data_dir() else {
        return;
    };
    let source = GltfSource {
        character: data.join("quaternius-witch/Witch.gltf"),
        motion: None,
        joint_map: None,
        in_place: false,
        train_clips: vec!["Walk".into()],
        test_clips: vec!["Kick_Left".into()],
    };
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig {
        train_frames_per_clip: 2,
        test_frames_per_clip: 2,
        ..SynthConfig::tiny()
    };
    let summary = synthesize_gltf(dir.path(), &config, &source).unwrap();
    let cap = load_capture(dir.path()).unwrap();
    assert_eq!((summary.joints, cap.template.vertex_count()), (62, 13884));
    assert_eq!(
        (cap.train_frames.clone(), cap.test_frames.clone()),
        (vec![0, 1], vec![2, 3])
    );
    let mask = cap.load_mask(0, 2).unwrap();
    assert!(
        mask.inside.iter().filter(|&&m| m).count() > 50,
        "the witch is in view"
    );
    // The ground truth (DQS + bulge with the artist weights) differs from LBS with the same
    // weights on a kick, so static LBS cannot reproduce it.
    let weights = cap.evaluation_true_weights().unwrap().unwrap();
    let gt = cap.evaluation_gt_mesh(2).unwrap();
    let l = lbs(
        &cap.skeleton,
        &weights,
        &cap.template.positions,
        &cap.poses[2],
    )
    .unwrap();
    let max = gt
        .iter()
        .zip(&l)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0f32, f32::max);
    let height = cap.template.bounds().unwrap().size().y;
    assert!(
        max > 0.005 * height,
        "GT vs LBS differ by at most {max} (height {height})"
    );
    // Clips from a separate motion file bind by joint name: the same file gives the same poses.
    let by_name = GltfSource {
        motion: Some(source.character.clone()),
        ..source.clone()
    };
    let dir2 = tempfile::tempdir().unwrap();
    synthesize_gltf(dir2.path(), &config, &by_name).unwrap();
    let cap2 = load_capture(dir2.path()).unwrap();
    for (a, b) in cap.poses.iter().zip(&cap2.poses) {
        for (j, (x, y)) in a.locals.iter().zip(&b.locals).enumerate() {
            assert!(
                (x.translation - y.translation).length() < 1e-5
                    && x.rotation.dot(y.rotation).abs() > 1.0 - 1e-6,
                "{j} {} {x:?} {y:?}",
                cap.skeleton.names()[j]
            );
        }
    }
    // Clip names are checked.
    let bad = GltfSource {
        test_clips: vec!["Walk".into()],
        ..source.clone()
    };
    assert!(matches!(
        synthesize_gltf(dir.path(), &config, &bad),
        Err(SynthError::Config {
            field: "test_clips",
            ..
        })
    ));
    let bad = GltfSource {
        test_clips: vec!["Moonwalk".into()],
        ..source.clone()
    };
    assert!(matches!(
        synthesize_gltf(dir.path(), &config, &bad),
        Err(SynthError::Config {
            field: "test_clips",
            ..
        })
    ));
    // Held-out phases test on the training clips: naming test clips as well is refused.
    let held_out = SynthConfig {
        test_motions: TestMotions::HeldOutPhases,
        ..config
    };
    assert!(matches!(
        synthesize_gltf(dir.path(), &held_out, &source),
        Err(SynthError::Config {
            field: "test_clips",
            ..
        })
    ));
}

/// A capture of the shared character `character` moved by `motion` (both under `data`)
/// through the joint map `map` of `joint-maps/`, `frames` (training, test) per clip, and the map.
fn retargeted_capture(
    data: &Path,
    (character, motion, map): (&str, &str, &str),
    (train, test): (&str, &str),
    frames: (usize, usize),
    in_place: bool,
) -> (tempfile::TempDir, Capture, JointMap) {
    let map = JointMap::read(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("joint-maps")
            .join(map),
    )
    .unwrap();
    let source = GltfSource {
        character: data.join(character),
        motion: Some(data.join(motion)),
        joint_map: Some(map.clone()),
        in_place,
        train_clips: vec![train.into()],
        test_clips: vec![test.into()],
    };
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig {
        train_frames_per_clip: frames.0,
        test_frames_per_clip: frames.1,
        ..SynthConfig::tiny()
    };
    synthesize_gltf(dir.path(), &config, &source).unwrap();
    let cap = load_capture(dir.path()).unwrap();
    let first_test = frames.0;
    let inside = cap.load_mask(0, first_test).unwrap().inside;
    assert!(
        inside.iter().filter(|&&m| m).count() > 50,
        "{character} in view"
    );
    (dir, cap, map)
}

/// Forward kinematics of `pose`.
fn world_of(skeleton: &skinfield_formats::Skeleton, pose: &skinfield_formats::Pose) -> Vec<Mat4> {
    let mut w = vec![Mat4::IDENTITY; skeleton.len()];
    skeleton.world_matrices(pose, &mut w).unwrap();
    w
}

/// The world position of the joint named `name`.
fn joint_at(skeleton: &skinfield_formats::Skeleton, world: &[Mat4], name: &str) -> Vec3 {
    world[skeleton.find(name).unwrap()].w_axis.truncate()
}

/// A bone as the names of the joints at its two ends.
type Bone<'a> = (&'a str, &'a str);

/// Every bone of the target points within 1° of its source bone turned by `frame`.
fn assert_bones_follow(
    (target, target_world): (&skinfield_formats::Skeleton, &[Mat4]),
    (source, source_world): (&skinfield_formats::Skeleton, &[Mat4]),
    frame: Quat,
    bones: &[(Bone<'_>, Bone<'_>)],
    what: &str,
) {
    for &((ta, tb), (sa, sb)) in bones {
        let got =
            (joint_at(target, target_world, tb) - joint_at(target, target_world, ta)).normalize();
        let want = frame
            * (joint_at(source, source_world, sb) - joint_at(source, source_world, sa)).normalize();
        assert!(
            got.angle_between(want) < 1f32.to_radians(),
            "{what}, {ta}: {got} against {want}"
        );
    }
}

#[test]
fn a_motion_from_another_rig_is_retargeted_through_a_joint_map() {
    let Some(data) = skinfield_formats::shared_data::shared_data_dir() else {
        return;
    };
    // The peasant has no clips; the Witch's drive it (other names, proportions, rest pose).
    let (dir, cap, map) = retargeted_capture(
        &data,
        (
            "quaternius-female-peasant/Female_Peasant.gltf",
            "quaternius-witch/Witch.gltf",
            "quaternius-to-ue-mannequin.json",
        ),
        ("Walk", "Wave"),
        (2, 2),
        false,
    );
    assert_eq!(
        (cap.skeleton.len(), cap.template.vertex_count()),
        (65, 10184)
    );
    // Each frame's mapped bones point where the Witch's do at the same clip time, in the
    // peasant's frame: the retargeting, checked end to end on the two real rigs.
    let witch = data.join("quaternius-witch/Witch.gltf");
    let doc = skinfield_formats::gltf_io::load_gltf(&witch).unwrap();
    let skin = doc.largest_skin().unwrap();
    let frame = skinfield_formats::Retarget::new(&skin.skeleton, &cap.skeleton, &map.pairs)
        .unwrap()
        .frame();
    let bones = [
        (("spine_01", "spine_02"), ("Abdomen", "Torso")),
        (("upperarm_l", "lowerarm_l"), ("UpperArm.L", "LowerArm.L")),
        (("lowerarm_r", "hand_r"), ("LowerArm.R", "Wrist.R")),
        (("thigh_l", "calf_l"), ("UpperLeg.L", "LowerLeg.L")),
        (("thigh_r", "calf_r"), ("UpperLeg.R", "LowerLeg.R")),
    ];
    for (k, (clip, i)) in [("Walk", 0), ("Walk", 1), ("Wave", 0), ("Wave", 1)]
        .into_iter()
        .enumerate()
    {
        let clip = doc.clip(clip).unwrap();
        let t = clip.duration_s * (i as f32 + 0.5) / 2.0;
        assert_bones_follow(
            (&cap.skeleton, &world_of(&cap.skeleton, &cap.poses[k])),
            (
                &skin.skeleton,
                &world_of(&skin.skeleton, &clip.sample(skin, t)),
            ),
            frame,
            &bones,
            &format!("frame {k}"),
        );
    }
    // A map without a motion file, and one naming a joint neither rig has, are refused with
    // the map's origin in the message.
    let source = GltfSource {
        character: data.join("quaternius-female-peasant/Female_Peasant.gltf"),
        motion: None,
        joint_map: Some(map.clone()),
        in_place: false,
        train_clips: vec!["Walk".into()],
        test_clips: vec!["Wave".into()],
    };
    let config = SynthConfig::tiny();
    let e = synthesize_gltf(dir.path(), &config, &source).unwrap_err();
    assert!(
        matches!(&e, SynthError::JointMap { path, .. } if *path == map.origin),
        "{e}"
    );
    let mut wrong = map.clone();
    wrong.pairs.push(("tail".into(), "Hips".into()));
    let e = synthesize_gltf(
        dir.path(),
        &config,
        &GltfSource {
            motion: Some(witch),
            joint_map: Some(wrong),
            ..source
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("quaternius-to-ue-mannequin.json") && e.contains("`tail`"),
        "{e}"
    );
}

#[test]
fn bvh_motion_capture_drives_the_makehuman_body_in_place() {
    let Some(data) = skinfield_formats::shared_data::shared_data_dir() else {
        return;
    };
    let (dir, cap, map) = retargeted_capture(
        &data,
        ("makehuman-hm08", "mocap-cmu", "cmu-bvh-to-makehuman.json"),
        ("131_01", "jumping_jacks"),
        (3, 2),
        true,
    );
    assert_eq!(
        (cap.skeleton.len(), cap.template.vertex_count()),
        (163, 13380)
    );
    let rest = joint_at(
        &cap.skeleton,
        &world_of(&cap.skeleton, &cap.skeleton.bind_pose()),
        "root",
    );
    let options = skinfield_formats::bvh::BvhOptions {
        unit_scale: skinfield_formats::bvh::CMU_UNIT_TO_METRES,
    };
    let walk =
        skinfield_formats::bvh::load_bvh_with(data.join("mocap-cmu/131_01.bvh"), &options).unwrap();
    let frame = skinfield_formats::Retarget::new(&walk.skeleton, &cap.skeleton, &map.pairs)
        .unwrap()
        .frame();
    for i in 0..3 {
        let w = world_of(&cap.skeleton, &cap.poses[i]);
        // In place: the hips never leave the spot above their rest position.
        let hips = joint_at(&cap.skeleton, &w, "root");
        assert!(
            (hips.x - rest.x).abs() < 1e-4 && (hips.z - rest.z).abs() < 1e-4,
            "frame {i}: hips at {hips}, rest {rest}"
        );
        // The arms and legs point where the actor's did at that frame.
        let t = walk.duration_s() * (i as f32 + 0.5) / 3.0;
        let k = (t / walk.frame_time) as usize;
        assert_bones_follow(
            (&cap.skeleton, &w),
            (&walk.skeleton, &world_of(&walk.skeleton, &walk.poses[k])),
            frame,
            &[
                (
                    ("upperarm01.L", "lowerarm01.L"),
                    ("LeftShoulder", "LeftElbow"),
                ),
                (("upperleg01.R", "lowerleg01.R"), ("RightHip", "RightKnee")),
                (("lowerleg01.L", "foot.L"), ("LeftKnee", "LeftAnkle")),
            ],
            &format!("frame {i}"),
        );
    }
    // BVH motion needs a joint map; in place needs one too.
    let source = GltfSource {
        character: data.join("makehuman-hm08"),
        motion: Some(data.join("mocap-cmu")),
        joint_map: None,
        in_place: false,
        train_clips: vec!["131_01".into()],
        test_clips: vec!["jumping_jacks".into()],
    };
    for (bad, field) in [
        (source.clone(), "joint_map"),
        (
            GltfSource {
                motion: Some(data.join("quaternius-witch/Witch.gltf")),
                in_place: true,
                ..source
            },
            "in_place",
        ),
    ] {
        let e = synthesize_gltf(dir.path(), &SynthConfig::tiny(), &bad).unwrap_err();
        assert!(
            matches!(e, SynthError::Config { field: f, .. } if f == field),
            "{e}"
        );
    }
}

/// Every vertex of `positions` projects inside every camera's image, `margin` pixels from the
/// border; returns the largest fraction of the image side the projections span in any camera.
fn assert_in_view(
    rig: &skinfield_formats::CameraRig,
    positions: &[Vec3],
    margin: f32,
    what: &str,
) -> f32 {
    let mut span = 0.0f32;
    for c in &rig.cameras {
        let (mut lo, mut hi) = (glam::Vec2::splat(f32::MAX), glam::Vec2::splat(f32::MIN));
        for (v, &p) in positions.iter().enumerate() {
            let px = c
                .project(p)
                .unwrap_or_else(|| panic!("{what}: vertex {v} is behind {}", c.name));
            assert!(
                px.x >= margin
                    && px.y >= margin
                    && px.x <= c.width as f32 - margin
                    && px.y <= c.height as f32 - margin,
                "{what}: vertex {v} at {px} in {}",
                c.name
            );
            lo = lo.min(px);
            hi = hi.max(px);
        }
        let size = glam::Vec2::new(c.width as f32, c.height as f32);
        span = span.max(((hi - lo) / size).max_element());
    }
    span
}

#[test]
fn the_built_in_rig_frames_every_frame_of_both_test_choices() {
    let config = SynthConfig::tiny();
    let ch = build_character(&config).unwrap();
    let rig = rig::camera_rig(12, 256, 256, config.seed);
    for test in [TestMotions::Novel, TestMotions::HeldOutPhases] {
        for f in motion::library(&ch.skeleton, 16, 8, test, config.seed).unwrap() {
            let (positions, _) = ch.deformer.deform(&f.pose).unwrap();
            assert_in_view(&rig, &positions, 2.0, motion::CLIPS[f.clip].0);
        }
    }
}

/// Every mask of a capture keeps its border free, and in some camera the subject spans at
/// least `min_span` of the image side: framed, and not a speck.
fn assert_masks_framed(cap: &skinfield_formats::capture::Capture, min_span: f32) {
    for f in 0..cap.poses.len() {
        let mut span = 0.0f32;
        for (c, cam) in cap.rig.cameras.iter().enumerate() {
            let mask = cap.load_mask(c, f).unwrap();
            let (w, h) = (cam.width as usize, cam.height as usize);
            let (mut x0, mut x1, mut y0, mut y1) = (w, 0, h, 0);
            for y in 0..h {
                for x in 0..w {
                    if mask.coverage[y * w + x] > 0.0 {
                        assert!(
                            x > 0 && y > 0 && x + 1 < w && y + 1 < h,
                            "frame {f}, camera {c}: the subject touches the border"
                        );
                        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
                    }
                }
            }
            assert!(x1 >= x0, "frame {f}, camera {c}: empty mask");
            span = span.max(((x1 - x0) as f32 / w as f32).max((y1 - y0) as f32 / h as f32));
        }
        assert!(
            span >= min_span,
            "frame {f}: the subject spans only {span} of the image"
        );
    }
}

#[test]
fn fox_capture_frames_the_quadruped() {
    let Some(data) = skinfield_formats::shared_data::shared_data_dir() else {
        return;
    };
    // The Fox is 79 units tall and 155 long: a rig for a 1.8 m human stood inside it.
    let source = GltfSource {
        character: data.join("khronos-fox/Fox.glb"),
        motion: None,
        joint_map: None,
        in_place: false,
        train_clips: vec!["Survey".into(), "Walk".into()],
        test_clips: vec!["Run".into()],
    };
    let dir = tempfile::tempdir().unwrap();
    let config = SynthConfig {
        cameras: 6,
        width: 64,
        height: 64,
        train_frames_per_clip: 2,
        test_frames_per_clip: 3,
        ..SynthConfig::tiny()
    };
    synthesize_gltf(dir.path(), &config, &source).unwrap();
    let cap = load_capture(dir.path()).unwrap();
    let size = cap.template.bounds().unwrap().size();
    assert!(
        size.max_element() > 100.0,
        "the Fox is in its own units: {size}"
    );
    assert_masks_framed(&cap, 0.5);
    for &f in &cap.test_frames {
        let gt = cap.evaluation_gt_mesh(f).unwrap();
        let span = assert_in_view(&cap.rig, &gt, 1.0, "fox");
        assert!(span > 0.5, "frame {f}: the fox spans {span} of the image");
    }
}

#[test]
fn gltf_held_out_phases_test_the_training_clip_between_its_frames() {
    let Some(data) = skinfield_formats::shared_data::shared_data_dir() else {
        return;
    };
    let path = data.join("khronos-cesiumman/CesiumMan.glb");
    let source = GltfSource {
        character: path.clone(),
        motion: None,
        joint_map: None,
        in_place: false,
        train_clips: vec!["animation_0".into()],
        test_clips: Vec::new(),
    };
    let config = SynthConfig {
        train_frames_per_clip: 4,
        test_frames_per_clip: 2,
        test_motions: TestMotions::HeldOutPhases,
        ..SynthConfig::tiny()
    };
    let dir = tempfile::tempdir().unwrap();
    let summary = synthesize_gltf(dir.path(), &config, &source).unwrap();
    assert_eq!((summary.train_frames, summary.test_frames), (4, 2));
    let cap = load_capture(dir.path()).unwrap();
    let names: Vec<(&str, &str)> = cap
        .manifest
        .clips
        .iter()
        .map(|c| (c.name.as_str(), c.split.as_str()))
        .collect();
    assert_eq!(
        names,
        [
            ("animation_0", "train"),
            ("animation_0_heldout", "test"),
            ("canonical", "canonical")
        ]
    );
    // Training frames at (i + ½)/4 of the clip; held-out ones at 1/4 and 3/4, midway between
    // training frames 0–1 and 2–3: poses of the clip that training never sees.
    let doc = skinfield_formats::gltf_io::load_gltf(&path).unwrap();
    let skin = doc.largest_skin().unwrap();
    let clip = doc.clip("animation_0").unwrap();
    let at = |phase: f32| clip.sample(skin, clip.duration_s * phase);
    let want = [
        at(0.125),
        at(0.375),
        at(0.625),
        at(0.875),
        at(0.25),
        at(0.75),
    ];
    // Then the canonical frame, in the bind pose.
    assert_eq!(cap.poses.len(), want.len() + 1);
    assert_eq!(cap.manifest.canonical_frame, Some(want.len()));
    assert_eq!(cap.poses[want.len()], cap.skeleton.bind_pose());
    for (f, (got, want)) in cap.poses.iter().zip(&want).enumerate() {
        assert_eq!(got, want, "frame {f}");
    }
    for &t in &cap.test_frames {
        assert!(
            cap.train_frames
                .iter()
                .all(|&f| cap.poses[f] != cap.poses[t])
        );
    }
    // Test clips are refused with held-out phases, and too many test frames per clip too.
    let named = GltfSource {
        test_clips: vec!["animation_0".into()],
        ..source.clone()
    };
    assert!(matches!(
        synthesize_gltf(dir.path(), &config, &named),
        Err(SynthError::Config {
            field: "test_clips",
            ..
        })
    ));
    let too_many = SynthConfig {
        test_frames_per_clip: 5,
        ..config
    };
    assert!(matches!(
        synthesize_gltf(dir.path(), &too_many, &source),
        Err(SynthError::Config {
            field: "test_frames_per_clip",
            ..
        })
    ));
}

#[test]
fn every_invalid_config_field_is_named() {
    let with = |change: fn(&mut SynthConfig)| {
        let mut c = SynthConfig::tiny();
        change(&mut c);
        c
    };
    let cases = [
        (
            "train_frames_per_clip",
            with(|c| c.train_frames_per_clip = 0),
        ),
        ("cameras", with(|c| c.cameras = 0)),
        ("cameras", with(|c| c.cameras = 257)),
        ("width/height", with(|c| c.width = 4)),
        ("grid", with(|c| c.grid = 601)),
        ("target_vertices", with(|c| c.target_vertices = 10)),
        ("shadow_map", with(|c| c.shadow_map = 8)),
        ("label_noise", with(|c| c.label_noise = 1.5)),
        ("mask_offset_px", with(|c| c.mask_offset_px = 17.0)),
        ("mask_offset_px", with(|c| c.mask_offset_px = f32::NAN)),
        (
            "test_frames_per_clip",
            with(|c| {
                c.test_motions = TestMotions::HeldOutPhases;
                c.train_frames_per_clip = 2;
                c.test_frames_per_clip = 3;
            }),
        ),
    ];
    assert!(SynthConfig::tiny().validate().is_ok());
    for (field, config) in cases {
        match config.validate() {
            Err(SynthError::Config { field: f, .. }) => assert_eq!(f, field),
            other => panic!("{field}: {other:?}"),
        }
    }
}

#[test]
fn held_out_phase_capture_keeps_the_training_frames_and_scores_training_clips() {
    let (novel, held) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let config = SynthConfig {
        train_frames_per_clip: 2,
        ..small()
    };
    synthesize(novel.path(), &config).unwrap();
    synthesize(
        held.path(),
        &SynthConfig {
            test_motions: TestMotions::HeldOutPhases,
            ..config
        },
    )
    .unwrap();
    let (a, b) = (
        load_capture(novel.path()).unwrap(),
        load_capture(held.path()).unwrap(),
    );
    assert_eq!(a.template, b.template);
    assert_eq!(a.train_frames, b.train_frames);
    for &f in &a.train_frames {
        assert_eq!(a.poses[f], b.poses[f]);
    }
    let names: Vec<&str> = b
        .manifest
        .clips
        .iter()
        .filter(|c| c.split == "test")
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(
        names,
        [
            "walk_heldout",
            "squat_heldout",
            "arm_raise_twist_heldout",
            "lunge_left_heldout",
            "kick_low_heldout"
        ]
    );
    assert_eq!(b.test_frames.len(), 5);
}

#[test]
fn exr_images_carry_the_same_pixels_as_png_before_quantisation() {
    let (png, exr) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    synthesize(png.path(), &SynthConfig::tiny()).unwrap();
    let config = SynthConfig {
        image_format: skinfield_formats::capture::ImageFormat::Exr,
        ..SynthConfig::tiny()
    };
    synthesize(exr.path(), &config).unwrap();
    let (a, b) = (
        load_capture(png.path()).unwrap(),
        load_capture(exr.path()).unwrap(),
    );
    assert!(b.image_path(1, 2).extension().is_some_and(|e| e == "exr"));
    let (pa, pb) = (a.load_image(1, 2).unwrap(), b.load_image(1, 2).unwrap());
    // 8-bit sRGB quantisation is the only difference (at most ~0.5/255 · 2.4 in linear terms near white).
    for (x, y) in pa.rgb.iter().zip(&pb.rgb) {
        assert!((*x - *y).abs().max_element() < 0.006, "{x} vs {y}");
    }
    assert!(pb.rgb.iter().any(|p| p.max_element() > 0.1));
}

#[test]
fn a_mask_offset_moves_only_the_masks() {
    let (exact, grown) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    synthesize(exact.path(), &small()).unwrap();
    let offset = SynthConfig {
        mask_offset_px: 1.0,
        ..small()
    };
    synthesize(grown.path(), &offset).unwrap();
    let (a, b) = (tree(exact.path()), tree(grown.path()));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    let masks = a.keys().filter(|k| k.starts_with("masks/")).count();
    assert!(masks > 0);
    for (k, v) in &a {
        if k.starts_with("masks/") {
            assert_ne!(b[k], *v, "{k} unchanged");
        } else if !k.ends_with("capture.json") {
            assert!(b[k] == *v, "{k} changed");
        }
    }
    // Each mask grows by about its outline's length times one pixel.
    let (ca, cb) = (
        load_capture(exact.path()).unwrap(),
        load_capture(grown.path()).unwrap(),
    );
    let area = |c: &Capture| -> f32 { c.load_mask(0, 0).unwrap().coverage.iter().sum() };
    let mask = ca.load_mask(0, 0).unwrap();
    let outline =
        Outline::from_coverage(mask.width as usize, mask.height as usize, &mask.coverage).unwrap();
    let length: f32 = outline
        .segments
        .iter()
        .map(|s| (s[1] - s[0]).length())
        .sum();
    let grown_by = area(&cb) - area(&ca);
    assert!(
        (grown_by - length).abs() < 0.2 * length,
        "area +{grown_by} px² against an outline of {length} px"
    );
}
