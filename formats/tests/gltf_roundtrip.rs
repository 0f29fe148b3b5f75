//! glTF export read back by our importer (and validated by the gltf crate), and malformed
//! input: every truncated prefix and random bit flips of a small GLB give errors, never panics.

use glam::{Mat4, Quat, Vec2, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::gltf_io::{
    GltfError, load_gltf, load_gltf_slice, write_gltf_character, write_gltf_mesh_sequence_at,
};
use skinfield_formats::{Pose, Skeleton, StaticSkin, Template, Transform};

/// A bent strip of quads along +Y skinned to a 4-joint chain, with up to 5 influences per
/// vertex (two JOINTS/WEIGHTS sets), UVs, a non-identity base and a uniform scale on joint 1.
fn character() -> (Skeleton, Template, StaticSkin) {
    let names = ["hips", "spine", "chest", "head"]
        .map(String::from)
        .to_vec();
    let mut bind = vec![Transform::from_translation(Vec3::new(0.0, 0.5, 0.0)); 4];
    bind[0].translation = Vec3::new(0.1, 1.0, -0.2);
    bind[1].rotation = Quat::from_rotation_z(0.2);
    bind[1].scale = Vec3::splat(1.5);
    let base =
        Mat4::from_rotation_translation(Quat::from_rotation_y(0.3), Vec3::new(1.0, 0.0, 2.0));
    let skeleton = Skeleton::new(
        names,
        vec![None, Some(0), Some(1), Some(2)],
        bind,
        None,
        None,
        base,
    )
    .unwrap();
    let rows = 9;
    let mut t = Template::default();
    for r in 0..rows {
        for x in [-0.2f32, 0.2] {
            t.positions
                .push(Vec3::new(x, 1.0 + r as f32 * 0.25, 0.05 * r as f32));
        }
    }
    for r in 0..rows - 1 {
        let a = (2 * r) as u32;
        t.triangles.push([a, a + 1, a + 3]);
        t.triangles.push([a, a + 3, a + 2]);
    }
    t.compute_normals();
    t.uvs = Some(t.positions.iter().map(|p| Vec2::new(p.x, p.y)).collect());
    let nv = t.positions.len();
    let mut dense = vec![0.0f32; nv * 4];
    for v in 0..nv {
        let row = (v / 2) as f32 / (rows - 1) as f32 * 3.0;
        for j in 0..4 {
            dense[v * 4 + j] =
                (1.0 - (row - j as f32).abs() / 2.0).max(0.0) + 0.01 * (v % 3) as f32;
        }
    }
    // Vertex 0 gets five influences by listing joint 0 twice in the sparse form.
    let mut offsets = vec![0u32];
    let (mut joints, mut weights) = (Vec::new(), Vec::new());
    for v in 0..nv {
        for j in 0..4 {
            if dense[v * 4 + j] > 0.0 {
                joints.push(j as u32);
                weights.push(dense[v * 4 + j]);
            }
        }
        if v == 0 {
            // A repeated joint: five stored influences, so the export needs two sets.
            joints.extend([1, 2, 3]);
            weights.extend([0.05, 0.05, 0.05]);
        }
        offsets.push(joints.len() as u32);
    }
    let skin = StaticSkin::new(offsets, joints, weights, 4).unwrap();
    (skeleton, t, skin)
}

fn clip_poses(s: &Skeleton) -> (Vec<f32>, Vec<Pose>) {
    let times: Vec<f32> = (0..6).map(|k| k as f32 * 0.2).collect();
    let poses = times
        .iter()
        .map(|&t| {
            let angles: Vec<f32> = (0..s.angle_count())
                .map(|i| (t * 2.0 + i as f32).sin() * 0.4)
                .collect();
            s.pose_from_angles(Quat::from_rotation_y(t), Vec3::new(t, 0.0, 0.0), &angles)
                .unwrap()
        })
        .collect();
    (times, poses)
}

fn skinned(s: &Skeleton, t: &Template, w: &StaticSkin, pose: &Pose) -> Vec<Vec3> {
    let mut m = vec![Mat4::ZERO; s.len()];
    s.skinning_matrices(pose, &mut m).unwrap();
    (0..t.vertex_count())
        .map(|v| {
            let (j, ww) = w.influences(v);
            j.iter()
                .zip(ww)
                .map(|(&j, &w)| w * m[j as usize].transform_point3(t.positions[v]))
                .sum()
        })
        .collect()
}

fn max_dist(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f32::max)
}

#[test]
fn character_round_trips_through_glb_and_gltf() {
    let (s, t, w) = character();
    assert_eq!(w.max_influences(), 5);
    let (times, poses) = clip_poses(&s);
    let dir = tempfile::tempdir().unwrap();
    for name in ["c.glb", "c.gltf"] {
        let path = dir.path().join(name);
        write_gltf_character(&path, &s, &t, &w, Some(("wave", &times, &poses))).unwrap();
        gltf::Gltf::open(&path).expect("valid glTF");
        let doc = load_gltf(&path).unwrap();
        assert_eq!(doc.skins.len(), 1);
        let g = &doc.skins[0];
        assert_eq!(g.skeleton.names(), s.names());
        assert_eq!(g.skeleton.parents(), s.parents());
        assert!(g.skeleton.base().abs_diff_eq(s.base(), 1e-6));
        assert_eq!(g.template.positions, t.positions);
        assert_eq!(g.template.triangles, t.triangles);
        assert_eq!(g.template.uvs, t.uvs);
        let (a, b) = (g.skin.to_dense(), w.to_dense());
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-6));
        for (x, y) in g.skeleton.bind_local().iter().zip(s.bind_local()) {
            assert!((x.translation - y.translation).length() < 1e-5);
            assert!(x.rotation.dot(y.rotation).abs() > 1.0 - 1e-6);
            assert!((x.scale - y.scale).length() < 1e-5);
        }
        let clip = doc.clip("wave").unwrap();
        assert_eq!(clip.frames, times.len());
        assert!((clip.duration_s - 1.0).abs() < 1e-6);
        // At the keys the clip reproduces the poses; between keys it interpolates.
        for (k, &tk) in times.iter().enumerate() {
            let ours = skinned(&g.skeleton, &g.template, &g.skin, &clip.sample(g, tk));
            let want = skinned(&s, &t, &w, &poses[k]);
            assert!(max_dist(&ours, &want) < 1e-4, "{name} t={tk}");
            let by_name = clip.sample_by_name(&s, &s.bind_pose(), tk);
            assert!(max_dist(&skinned(&s, &t, &w, &by_name), &want) < 1e-4);
        }
    }
}

#[test]
fn mesh_sequence_round_trips_one_node_per_frame() {
    let (_, t, _) = character();
    let frames: Vec<Vec<Vec3>> = (0..4)
        .map(|k| {
            t.positions
                .iter()
                .map(|p| *p + Vec3::new(0.1 * k as f32, p.y * 0.01 * k as f32, 0.0))
                .collect()
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("seq.glb");
    write_gltf_mesh_sequence_at(&path, &t, &frames, 10.0).unwrap();
    gltf::Gltf::open(&path).expect("valid glTF");
    let doc = load_gltf(&path).unwrap();
    assert_eq!(doc.static_meshes.len(), 4);
    for (k, m) in doc.static_meshes.iter().enumerate() {
        assert_eq!(m.template.positions, frames[k]);
        assert_eq!(m.template.triangles, t.triangles);
    }
    let clip = doc.clip("sequence").unwrap();
    assert_eq!(clip.frames, 4);
    let nodes: Vec<usize> = doc.static_meshes.iter().map(|m| m.node).collect();
    let defaults: Vec<Transform> = nodes.iter().map(|&n| doc.nodes[n].local).collect();
    for k in 0..4 {
        let locals = clip.sample_nodes(&nodes, &defaults, (k as f32 + 0.5) / 10.0);
        for (i, l) in locals.iter().enumerate() {
            assert_eq!(
                l.scale,
                Vec3::splat(if i == k { 1.0 } else { 0.0 }),
                "frame {k} node {i}"
            );
        }
    }
    let bad = write_gltf_mesh_sequence_at(&path, &t, &[vec![Vec3::ZERO; 3]], 10.0);
    assert!(matches!(bad, Err(GltfError::Export { .. })));
}

fn small_glb() -> Vec<u8> {
    let (s, t, w) = character();
    let (times, poses) = clip_poses(&s);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.glb");
    write_gltf_character(&path, &s, &t, &w, Some(("wave", &times, &poses))).unwrap();
    std::fs::read(path).unwrap()
}

fn no_panic_variant(r: &Result<skinfield_formats::gltf_io::GltfDocument, GltfError>, what: &str) {
    if let Err(GltfError::Panic { message, .. }) = r {
        panic!("{what}: the gltf crate panicked behind our checks: {message}");
    }
}

#[test]
fn every_truncated_prefix_is_an_error() {
    let glb = small_glb();
    load_gltf_slice(&glb, None).unwrap();
    for n in 0..glb.len() {
        let r = load_gltf_slice(&glb[..n], None);
        assert!(r.is_err(), "prefix of {n} bytes accepted");
        no_panic_variant(&r, &format!("prefix {n}"));
    }
}

#[test]
fn bit_flips_never_panic() {
    let glb = small_glb();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut ok, mut err) = (0, 0);
    for i in 0..10000 {
        let mut v = glb.clone();
        for _ in 0..rng.random_range(1..4) {
            let at = rng.random_range(0..v.len());
            v[at] ^= 1 << rng.random_range(0..8);
        }
        let r = load_gltf_slice(&v, None);
        no_panic_variant(&r, &format!("flip {i}"));
        if r.is_ok() { ok += 1 } else { err += 1 }
    }
    // Most flips land in float data and still load; some must hit the header or JSON.
    assert!(err > 0 && ok > 0, "ok {ok} err {err}");
}

/// Edits the JSON of an exported `.gltf` and reloads it.
fn edited(
    edit: impl FnOnce(&mut serde_json::Value),
) -> Result<skinfield_formats::gltf_io::GltfDocument, GltfError> {
    let (s, t, w) = character();
    let (times, poses) = clip_poses(&s);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("e.gltf");
    write_gltf_character(&path, &s, &t, &w, Some(("wave", &times, &poses))).unwrap();
    let mut json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    edit(&mut json);
    let r = load_gltf_slice(&serde_json::to_vec(&json).unwrap(), None);
    no_panic_variant(&r, "edited");
    r
}

#[test]
fn hostile_fields_give_errors_naming_the_field() {
    let msg = |r: Result<_, GltfError>| r.err().map(|e| e.to_string()).unwrap_or_default();
    assert!(edited(|_| {}).is_ok());
    // A skin that no mesh node uses is valid: its skeleton loads, its template is empty, and
    // the mesh becomes a static mesh.
    let unused = edited(|j| {
        j["nodes"][5].as_object_mut().unwrap().remove("skin");
    })
    .unwrap();
    assert_eq!(unused.skins[0].skeleton.len(), 4);
    assert_eq!(unused.skins[0].template.vertex_count(), 0);
    assert_eq!(unused.static_meshes.len(), 1);
    let m = msg(edited(|j| {
        j["accessors"][0]["count"] = serde_json::json!(u32::MAX)
    }));
    assert!(m.contains("accessors[0]"), "{m}");
    let m = msg(edited(|j| {
        j["bufferViews"][0]["byteLength"] = serde_json::json!(1u64 << 40)
    }));
    assert!(m.contains("bufferViews[0]"), "{m}");
    let m = msg(edited(|j| {
        j["nodes"][3]["children"] = serde_json::json!([0])
    }));
    assert!(m.contains("cycle") || m.contains("parent"), "{m}");
    let m = msg(edited(|j| {
        j["skins"][0]["joints"] = serde_json::json!([0, 1])
    }));
    assert!(m.contains("JOINTS_0"), "{m}");
    let m = msg(edited(|j| {
        j["buffers"][0]["uri"] = serde_json::json!("missing.bin")
    }));
    assert!(m.contains("buffers[0]"), "{m}");
    let m = msg(edited(|j| {
        j["nodes"][1]["translation"] = serde_json::json!([1e39, 0, 0])
    }));
    assert!(!m.is_empty());
}
