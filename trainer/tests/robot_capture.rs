//! `trainer synth --character RobotExpressive.glb`: the whole robot is the template (two skins
//! over the same joints and twelve rigid parts, 7,214 vertices), and template, ground truth and
//! cameras agree on where it is. Checked against the independent glTF skinning reference
//! (`formats/tests/gltf_reference`, written on the gltf crate alone): the capture's template,
//! posed by linear blend skinning with the capture's own skeleton and true weights, must land
//! on the glTF world positions of every vertex (skinned hands: joint world × inverse bind;
//! rigid parts: the mesh node's world matrix) at the capture's frame times. And bone heat on
//! that template puts the robot's small head details on the head, as the asset does.

use glam::{DVec3, Mat4, Vec3};
use skinfield_formats::capture::load_capture;
use skinfield_formats::shared_data::shared_data_dir;
use skinfield_trainer::eval::{EvalOptions, Skinning, evaluate};
use skinfield_trainer::heat::{HeatOptions, bone_heat};
use skinfield_trainer::synth::{GltfSource, SynthConfig, synthesize_gltf};

#[path = "../../formats/tests/gltf_reference/mod.rs"]
mod gltf_reference;
use gltf_reference::Reference;

/// World positions of every vertex of the robot at `locals`: skin 0's meshes, skin 1's, then
/// every unskinned mesh node in node order (the order the capture's template documents).
fn reference_positions(r: &Reference, worlds: &[glam::DMat4]) -> Vec<DVec3> {
    let mut out = r.skinned(0, worlds);
    out.extend(r.skinned(1, worlds));
    let data = |b: gltf::Buffer<'_>| Some(&r.buffers[b.index()].0[..]);
    for node in r.doc.nodes() {
        let (Some(mesh), None) = (node.mesh(), node.skin()) else {
            continue;
        };
        for p in mesh.primitives() {
            let positions = p.reader(data).read_positions().unwrap();
            out.extend(
                positions.map(|v| worlds[node.index()].transform_point3(Vec3::from(v).as_dvec3())),
            );
        }
    }
    out
}

/// A capture of the robot (training clip `Walking`, test clip `Wave`) with `cameras` cameras of
/// `side`² pixels and `frames` frames per clip, in a temporary folder.
fn synthesize_robot(
    asset: &std::path::Path,
    cameras: usize,
    side: u32,
    frames: usize,
) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let source = GltfSource {
        character: asset.to_path_buf(),
        motion: None,
        joint_map: None,
        in_place: false,
        train_clips: vec!["Walking".into()],
        test_clips: vec!["Wave".into()],
    };
    let config = SynthConfig {
        cameras,
        width: side,
        height: side,
        train_frames_per_clip: frames,
        test_frames_per_clip: frames,
        ..SynthConfig::tiny()
    };
    synthesize_gltf(tmp.path(), &config, &source).unwrap();
    tmp
}

#[test]
fn robot_expressive_capture_agrees_with_gltf_skinning_everywhere() {
    let Some(dir) = shared_data_dir() else { return };
    let asset = dir.join("threejs-robotexpressive/RobotExpressive.glb");
    let tmp = synthesize_robot(&asset, 4, 48, 2);
    let cap = load_capture(tmp.path()).unwrap();
    assert_eq!(cap.template.vertex_count(), 7214, "every mesh of the robot");
    assert_eq!(cap.skeleton.len(), 43);

    let r = Reference::open(&asset);
    let clip_index = |name: &str| {
        r.doc
            .animations()
            .position(|a| a.name() == Some(name))
            .unwrap()
    };
    let truth = cap.evaluation_true_weights().unwrap().unwrap();
    // Frame times: (i + ½)/n of each clip (Walking 0.9583 s, Wave 1.8333 s as stored).
    let doc = skinfield_formats::gltf_io::load_gltf(&asset).unwrap();
    let mut frame = 0;
    let mut size = 0.0f64;
    for (clip, n) in [("Walking", 2), ("Wave", 2)] {
        let duration = doc.clip(clip).unwrap().duration_s;
        for i in 0..n {
            let t = f64::from(duration * (i as f32 + 0.5) / n as f32);
            let want = reference_positions(&r, &r.worlds(&r.locals(&[clip_index(clip)], t)));
            let mut m = vec![Mat4::IDENTITY; cap.skeleton.len()];
            cap.skeleton
                .skinning_matrices(&cap.poses[frame], &mut m)
                .unwrap();
            let got: Vec<Vec3> = cap
                .template
                .positions
                .iter()
                .enumerate()
                .map(|(v, &x)| {
                    let (js, ws) = truth.influences(v);
                    js.iter()
                        .zip(ws)
                        .map(|(&j, &w)| m[j as usize].transform_point3(x) * w)
                        .sum()
                })
                .collect();
            let error = gltf_reference::relative_error(&got, &want);
            assert!(
                error < 1e-5,
                "{clip} at {t} s: the capture's LBS is {error} of the robot's size from glTF"
            );
            let (lo, hi) = want.iter().fold(
                (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
                |(lo, hi), p| (lo.min(*p), hi.max(*p)),
            );
            size = size.max((hi - lo).length());
            frame += 1;
        }
    }
    // In glTF's world the robot is about 4.5 units tall; the template is in that world too.
    let template_size = f64::from(cap.template.bounds().unwrap().size().length());
    assert!(
        (template_size / size - 1.0).abs() < 0.5,
        "template {template_size} vs posed {size}"
    );

    // Every camera sees the robot whole in every test frame, and the oracle is close to the
    // ground truth (DQS + bulges with the same weights), not metres off. The rigid parts (every
    // vertex after the two skins') move rigidly in the ground truth: no flexion bulge on metal.
    let rest = r.worlds(&r.locals(&[], 0.0));
    let skinned = r.skinned(0, &rest).len() + r.skinned(1, &rest).len();
    assert!(skinned < 7214 / 2, "the rigid parts are most of the robot");
    let mut largest_bulge = 0.0f32;
    for &f in &cap.test_frames {
        let gt = cap.evaluation_gt_mesh(f).unwrap();
        let mut m = vec![Mat4::IDENTITY; cap.skeleton.len()];
        cap.skeleton
            .skinning_matrices(&cap.poses[f], &mut m)
            .unwrap();
        for (v, (&x, &g)) in cap.template.positions.iter().zip(&gt).enumerate() {
            let (js, ws) = truth.influences(v);
            let lbs: Vec3 = js
                .iter()
                .zip(ws)
                .map(|(&j, &w)| m[j as usize].transform_point3(x) * w)
                .sum();
            let d = (lbs - g).length() / template_size as f32;
            if v >= skinned {
                assert!(
                    d < 1e-5,
                    "frame {f}: rigid vertex {v} is {d} of the size off its joint"
                );
            } else {
                largest_bulge = largest_bulge.max(d);
            }
        }
        for c in &cap.rig.cameras {
            for p in &gt {
                let px = c.project(*p).expect("in front of the camera");
                assert!(
                    px.x > 0.0 && px.y > 0.0 && px.x < 48.0 && px.y < 48.0,
                    "{} sees {p} at {px}",
                    c.name
                );
            }
        }
        let mask = cap.load_mask(0, f).unwrap();
        assert!(mask.inside.iter().filter(|&&m| m).count() > 100);
    }
    // The skinned hands still bulge at the flexed wrists' parent (`LowerArm`): the rule is
    // about the parts, not the joints.
    assert!(
        largest_bulge > 1e-4,
        "skinned vertices: largest bulge {largest_bulge}"
    );
    let oracle = evaluate(
        &cap,
        &Skinning::Oracle,
        &EvalOptions {
            samples: 2000,
            seed: 0,
        },
    )
    .unwrap();
    assert!(
        oracle.chamfer_pct < 1.0,
        "oracle Chamfer {} % of the size",
        oracle.chamfer_pct
    );
}

/// The joint with the largest weight on vertex `v` (ties: the lower index).
fn dominant(skin: &skinfield_formats::StaticSkin, v: usize) -> u32 {
    let (j, w) = skin.influences(v);
    let mut best = (0u32, f32::NEG_INFINITY);
    for (&j, &w) in j.iter().zip(w) {
        if w > best.1 || (w == best.1 && j < best.0) {
            best = (j, w);
        }
    }
    best.0
}

#[test]
fn robot_head_details_take_the_heads_weights_in_bone_heat() {
    let Some(dir) = shared_data_dir() else { return };
    let tmp = synthesize_robot(
        &dir.join("threejs-robotexpressive/RobotExpressive.glb"),
        1,
        16,
        1,
    );
    let cap = load_capture(tmp.path()).unwrap();
    let truth = cap.evaluation_true_weights().unwrap().unwrap();
    let heat = |fraction: f64, far: f64| {
        let options = HeatOptions {
            small_piece_fraction: fraction,
            far_visible_ratio: far,
            ..HeatOptions::default()
        };
        bone_heat(&cap.template, &cap.skeleton, &options).unwrap()
    };
    let defaults = HeatOptions::default();
    let with = heat(defaults.small_piece_fraction, defaults.far_visible_ratio);
    let without = heat(0.0, defaults.far_visible_ratio);
    assert_eq!(without.stats.inherited_vertices, 0);
    assert!(with.stats.inherited_vertices > 0, "{:?}", with.stats);
    // The vertices whose weights the rule changed: the asset's own weights are the reference.
    let n = cap.template.vertex_count();
    let changed: Vec<usize> = (0..n)
        .filter(|&v| with.skin.influences(v) != without.skin.influences(v))
        .collect();
    let agree = |skin: &skinfield_formats::StaticSkin| {
        changed
            .iter()
            .filter(|&&v| dominant(skin, v) == dominant(&truth, v))
            .count()
    };
    let (on, off) = (agree(&with.skin), agree(&without.skin));
    eprintln!(
        "{} welded vertices inherited, {} file vertices changed: dominant joint as the asset's \
         on {on} with the rule, {off} without",
        with.stats.inherited_vertices,
        changed.len()
    );
    assert!(on > off, "{on} vs {off} of {}", changed.len());
    // The head details that were every test frame's worst vertex in the zoo now follow `Head`.
    let head = cap
        .skeleton
        .names()
        .iter()
        .position(|s| s == "Head")
        .unwrap() as u32;
    let head_details: Vec<usize> = changed
        .iter()
        .copied()
        .filter(|&v| dominant(&truth, v) == head)
        .collect();
    assert!(!head_details.is_empty());
    for v in head_details {
        assert_eq!(dominant(&with.skin, v), head, "vertex {v}");
    }
    // The face plate sees only the IK pole targets; with Pinocchio's visibility alone (far
    // visible bones accepted) it follows them, by distance it follows the head.
    let pinocchio = heat(defaults.small_piece_fraction, f64::MAX);
    let pole = |name: &str| cap.skeleton.names().iter().position(|s| s == name).unwrap() as u32;
    let poles = [pole("PoleTarget.L"), pole("PoleTarget.R")];
    let plate: Vec<usize> = (0..n)
        .filter(|&v| poles.contains(&dominant(&pinocchio.skin, v)) && dominant(&truth, v) == head)
        .collect();
    let plate_on_head = plate
        .iter()
        .filter(|&&v| dominant(&with.skin, v) == head)
        .count();
    let agree_all = |skin: &skinfield_formats::StaticSkin| {
        (0..n)
            .filter(|&v| dominant(skin, v) == dominant(&truth, v))
            .count()
    };
    eprintln!(
        "{} head vertices on the pole targets without the far-bone rule, {plate_on_head} on \
         the head with it; dominant joint as the asset's on {} of {n} vertices with it, {} \
         without",
        plate.len(),
        agree_all(&with.skin),
        agree_all(&pinocchio.skin)
    );
    assert!(!plate.is_empty());
    assert_eq!(plate_on_head, plate.len());
    assert!(agree_all(&with.skin) > agree_all(&pinocchio.skin));
}
