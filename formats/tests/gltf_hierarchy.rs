//! Hierarchy cases the shared assets do not have, built by editing an exported character's
//! JSON and checked against the independent reference: a node between two skin joints that is
//! not in the skin (animated), an animated node above the skeleton's base, STEP samplers and
//! CUBICSPLINE channels (translation and rotation).

mod gltf_reference;

use base64::Engine as _;
use glam::{Mat4, Quat, Vec3};
use gltf_reference::{Reference, relative_error};
use serde_json::{Value, json};
use skinfield_formats::gltf_io::{load_gltf, write_gltf_character};
use skinfield_formats::{Pose, Skeleton, StaticSkin, Template, Transform};

/// A 4-joint chain with a strip of quads along it, and a 6-key clip.
fn character() -> (Skeleton, Template, StaticSkin, Vec<f32>, Vec<Pose>) {
    let names = ["hips", "spine", "chest", "head"]
        .map(String::from)
        .to_vec();
    let mut bind = vec![Transform::from_translation(Vec3::new(0.0, 0.5, 0.0)); 4];
    bind[0].translation = Vec3::new(0.0, 1.0, 0.0);
    let base = Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0));
    let s = Skeleton::new(
        names,
        vec![None, Some(0), Some(1), Some(2)],
        bind,
        None,
        None,
        base,
    )
    .unwrap();
    let mut t = Template::default();
    for r in 0..9 {
        for x in [-0.2f32, 0.2] {
            t.positions
                .push(Vec3::new(x + 0.5, 1.0 + r as f32 * 0.25, 0.0));
        }
    }
    for r in 0..8u32 {
        t.triangles.push([2 * r, 2 * r + 1, 2 * r + 3]);
        t.triangles.push([2 * r, 2 * r + 3, 2 * r + 2]);
    }
    t.compute_normals();
    let nv = t.positions.len();
    let mut dense = vec![0.0f32; nv * 4];
    for v in 0..nv {
        let row = (v / 2) as f32 / 8.0 * 3.0;
        for j in 0..4 {
            dense[v * 4 + j] = (1.0 - (row - j as f32).abs()).max(0.0);
        }
    }
    let w = StaticSkin::from_dense(&dense, 4).unwrap();
    let times: Vec<f32> = (0..6).map(|k| k as f32 * 0.2).collect();
    let poses = times
        .iter()
        .map(|&tt| {
            let angles: Vec<f32> = (0..s.angle_count())
                .map(|i| (tt * 3.0 + i as f32).sin() * 0.5)
                .collect();
            s.pose_from_angles(
                Quat::from_rotation_y(tt),
                Vec3::new(0.0, tt * 0.1, 0.0),
                &angles,
            )
            .unwrap()
        })
        .collect();
    (s, t, w, times, poses)
}

/// Exported nodes: 0..4 joints, 4 skeleton_base, 5 mesh; samplers 3j (T), 3j+1 (R), 3j+2 (S).
fn edited(interpolation: &str) -> Value {
    let (s, t, w, times, poses) = character();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.gltf");
    write_gltf_character(&path, &s, &t, &w, Some(("clip", &times, &poses))).unwrap();
    let mut j: Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    // Node 6 "twist" between spine and chest, not in the skin, animated by joint 2's rotations.
    let twist = json!({ "name": "twist", "rotation": Quat::from_rotation_x(0.3).to_array(),
                        "translation": [0.0, 0.1, 0.0], "children": [2] });
    j["nodes"].as_array_mut().unwrap().push(twist);
    j["nodes"][1]["children"] = json!([6]);
    // Node 7 "mover" above skeleton_base, animated by joint 1's rotations.
    j["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "name": "mover", "translation": [0.0, 0.0, 0.3], "children": [4] }));
    j["scenes"][0]["nodes"] = json!([7, 5]);
    let anim = &mut j["animations"][0];
    anim["channels"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "sampler": 7, "target": { "node": 6, "path": "rotation" } }));
    anim["channels"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "sampler": 4, "target": { "node": 7, "path": "rotation" } }));
    for sampler in anim["samplers"].as_array_mut().unwrap() {
        sampler["interpolation"] = json!(interpolation);
    }
    // Two CUBICSPLINE channels: a 2-key input over the existing 6-value outputs (3 per key).
    let b64 = base64::engine::general_purpose::STANDARD
        .encode(bytemuck::cast_slice::<f32, u8>(&[0.1, 0.9]));
    j["buffers"].as_array_mut().unwrap().push(
        json!({ "byteLength": 8, "uri": format!("data:application/octet-stream;base64,{b64}") }),
    );
    j["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "buffer": 1, "byteOffset": 0, "byteLength": 8 }));
    let view = j["bufferViews"].as_array().unwrap().len() - 1;
    j["accessors"].as_array_mut().unwrap().push(
        json!({ "bufferView": view, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.1], "max": [0.9] }),
    );
    let input = j["accessors"].as_array().unwrap().len() - 1;
    let anim = &mut j["animations"][0];
    for (channel, output_sampler) in [(0usize, 0usize), (10, 10)] {
        let output = anim["samplers"][output_sampler]["output"].clone();
        anim["samplers"]
            .as_array_mut()
            .unwrap()
            .push(json!({ "input": input, "output": output, "interpolation": "CUBICSPLINE" }));
        anim["channels"][channel]["sampler"] =
            json!(anim["samplers"].as_array().unwrap().len() - 1);
    }
    j
}

fn check(interpolation: &str) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("edited.gltf");
    std::fs::write(&path, serde_json::to_vec(&edited(interpolation)).unwrap()).unwrap();
    let doc = load_gltf(&path).unwrap();
    let skin = &doc.skins[0];
    assert_eq!(
        skin.skeleton.len(),
        5,
        "the in-between node joins the skeleton"
    );
    assert_eq!(skin.skin_joint_count(), 4);
    let twist = skin.skeleton.find("twist").unwrap();
    assert_eq!(skin.joint_skin_index[twist], None);
    assert_eq!(
        skin.skeleton.parents()[skin.skeleton.find("chest").unwrap()],
        Some(twist)
    );
    assert_eq!(skin.root_ancestors, vec![7, 4]);
    let reference = Reference::open(&path);
    let clip = &doc.clips[0];
    let mut moved = 0.0f64;
    for t in [-0.5f32, 0.0, 0.13, 0.3, 0.5, 0.77, 0.95, 1.0, 2.0] {
        let worlds = reference.worlds(&reference.locals(&[0], f64::from(t)));
        let want = reference.skinned(0, &worlds);
        let mut m = vec![Mat4::ZERO; skin.skeleton.len()];
        skin.skeleton
            .skinning_matrices(&clip.sample(skin, t), &mut m)
            .unwrap();
        let ours: Vec<Vec3> = (0..skin.template.vertex_count())
            .map(|v| {
                let (js, ws) = skin.skin.influences(v);
                js.iter()
                    .zip(ws)
                    .map(|(&j, &w)| w * m[j as usize].transform_point3(skin.template.positions[v]))
                    .sum()
            })
            .collect();
        let err = relative_error(&ours, &want);
        assert!(err < 1e-4, "{interpolation} t={t}: relative error {err:e}");
        moved = moved.max(relative_error(&skin.template.positions, &want));
    }
    assert!(
        moved > 1e-2,
        "the edited clip must move the mesh ({moved:e})"
    );
}

#[test]
fn in_between_node_animated_ancestor_and_cubic_channels_linear() {
    check("LINEAR");
}

#[test]
fn in_between_node_animated_ancestor_and_cubic_channels_step() {
    check("STEP");
}
