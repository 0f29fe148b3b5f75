//! The shared glTF assets: counts against their SOURCE.md, and sampled clip poses against an
//! independent glTF skinning reference written here straight on the gltf crate (its own buffer
//! loading, node hierarchy from sampled node TRS in f64, joint world × IBM, weighted sum).

use std::path::{Path, PathBuf};

use glam::{Mat4, Vec3};
use skinfield_formats::gltf_io::{Clip, GltfDocument, GltfSkin, load_gltf};
use skinfield_formats::shared_data::shared_data_dir;

fn asset(rel: &str) -> Option<PathBuf> {
    shared_data_dir().map(|d| d.join(rel))
}

mod gltf_reference;
use gltf_reference::{Reference, relative_error};

// ---------------------------------------------------------------- ours

fn our_skinned(skin: &GltfSkin, pose: &skinfield_formats::Pose) -> Vec<Vec3> {
    let mut m = vec![Mat4::ZERO; skin.skeleton.len()];
    skin.skeleton.skinning_matrices(pose, &mut m).unwrap();
    skin.template
        .positions
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let (j, w) = skin.skin.influences(v);
            j.iter()
                .zip(w)
                .map(|(&j, &w)| w * m[j as usize].transform_point3(*p))
                .sum()
        })
        .collect()
}

/// Compares every skin at several times of `clip` (made of the file's `animations`, played
/// together) with the reference; `None` compares the rest scene (node default TRS).
fn check_clip(
    path: &Path,
    doc: &GltfDocument,
    reference: &Reference,
    clip: Option<(&Clip, Vec<usize>)>,
) {
    let times: Vec<f32> = match &clip {
        Some((c, _)) => vec![
            -0.1,
            0.0,
            c.duration_s * 0.37,
            c.duration_s * 0.81,
            c.duration_s + 0.5,
        ],
        None => vec![0.0],
    };
    let mut worst = 0.0f64;
    for &t in &times {
        let anims = clip.as_ref().map_or_else(Vec::new, |(_, a)| a.clone());
        let worlds = reference.worlds(&reference.locals(&anims, f64::from(t)));
        for skin in &doc.skins {
            let pose = clip
                .as_ref()
                .map_or_else(|| skin.default_pose(), |(c, _)| c.sample(skin, t));
            let err = relative_error(
                &our_skinned(skin, &pose),
                &reference.skinned(skin.index, &worlds),
            );
            let name = clip.as_ref().map_or("<rest>", |(c, _)| c.name.as_str());
            assert!(
                err < 1e-5,
                "{}: skin {} clip {name} t={t}: relative error {err:e}",
                path.display(),
                skin.index
            );
            worst = worst.max(err);
        }
    }
    let name = clip.as_ref().map_or("<rest>", |(c, _)| c.name.as_str());
    eprintln!("{}: {name}: worst relative error {worst:e}", path.display());
}

fn check_all_clips(path: &Path, doc: &GltfDocument) {
    let reference = Reference::open(path);
    check_clip(path, doc, &reference, None);
    let mut moved = 0.0f64;
    for (i, c) in doc.clips.iter().enumerate() {
        check_clip(path, doc, &reference, Some((c, vec![i])));
        // The comparison must be able to fail: the clip moves the mesh away from the bind pose.
        let worlds = reference.worlds(&reference.locals(&[i], f64::from(c.duration_s) * 0.37));
        for skin in &doc.skins {
            moved = moved.max(relative_error(
                &skin.template.positions,
                &reference.skinned(skin.index, &worlds),
            ));
        }
    }
    if !doc.clips.is_empty() {
        assert!(
            moved > 1e-2,
            "{}: clips barely move the mesh ({moved:e})",
            path.display()
        );
    }
    for skin in &doc.skins {
        // How far the file's rest scene (node TRS) is from the bind pose (IBM), for the report.
        let d = skin
            .node_defaults
            .iter()
            .zip(skin.skeleton.bind_local())
            .map(|(a, b)| {
                (a.translation - b.translation).length() + (1.0 - a.rotation.dot(b.rotation).abs())
            })
            .fold(0.0f32, f32::max);
        eprintln!(
            "{}: skin {}: {} skeleton joints, max |node TRS - bind_local| = {d:e}",
            path.display(),
            skin.index,
            skin.skeleton.len()
        );
    }
}

/// Bind pose: skinning matrices are the identity, so vertices stay where the file has them.
fn check_bind_pose(skin: &GltfSkin) {
    let mut m = vec![Mat4::ZERO; skin.skeleton.len()];
    skin.skeleton
        .skinning_matrices(&skin.skeleton.bind_pose(), &mut m)
        .unwrap();
    for (j, m) in m.iter().enumerate() {
        let scale = m
            .abs()
            .to_cols_array()
            .iter()
            .fold(1.0f32, |a, b| a.max(*b));
        assert!(
            m.abs_diff_eq(Mat4::IDENTITY, 1e-4 * scale),
            "joint {j}: {m}"
        );
    }
}

struct Expect {
    vertices: usize,
    triangles: usize,
    skins: usize,
    joints: usize,
    max_influences: usize,
    unnormalized: bool,
    clips: &'static [(&'static str, f32)],
    clip_count: usize,
}

fn check_counts(path: &Path, e: &Expect) -> GltfDocument {
    let doc = load_gltf(path).unwrap_or_else(|err| panic!("{err}"));
    let p = path.display();
    assert_eq!(doc.vertex_count, e.vertices, "{p}");
    assert_eq!(doc.triangle_count, e.triangles, "{p}");
    assert_eq!(doc.skins.len(), e.skins, "{p}");
    for s in &doc.skins {
        assert_eq!(s.skin_joint_count(), e.joints, "{p}");
        assert!(s.skin.max_influences() <= e.max_influences, "{p}");
        assert_eq!(s.skin.unnormalized_count() > 0, e.unnormalized, "{p}");
        assert_eq!(s.template.vertex_count(), s.skin.vertex_count());
        s.template.validate().unwrap();
        check_bind_pose(s);
    }
    assert_eq!(doc.clips.len(), e.clip_count, "{p}");
    for (name, dur) in e.clips {
        let c = doc
            .clip(name)
            .unwrap_or_else(|| panic!("{p}: no clip {name}"));
        assert!(
            (c.duration_s - dur).abs() < 0.01,
            "{p}: {name}: {}",
            c.duration_s
        );
    }
    doc
}

#[test]
fn cesium_man() {
    let Some(p) = asset("khronos-cesiumman/CesiumMan.glb") else {
        return;
    };
    let e = Expect {
        vertices: 3273,
        triangles: 4672,
        skins: 1,
        joints: 19,
        max_influences: 4,
        unnormalized: false,
        clips: &[],
        clip_count: 1,
    };
    let doc = check_counts(&p, &e);
    assert_eq!(doc.skins[0].template.vertex_count(), 3273);
    assert!((doc.clips[0].duration_s - 2.0).abs() < 0.01);
    check_all_clips(&p, &doc);
}

#[test]
fn cesium_man_legacy_weights_and_split_animations() {
    let Some(p) = asset("khronos-cesiumman/CesiumMan_legacy.glb") else {
        return;
    };
    let e = Expect {
        vertices: 3273,
        triangles: 4672,
        skins: 1,
        joints: 19,
        max_influences: 4,
        unnormalized: true,
        clips: &[],
        clip_count: 19,
    };
    let doc = check_counts(&p, &e);
    for s in &doc.skins {
        for v in 0..s.skin.vertex_count() {
            let sum: f32 = s.skin.influences(v).1.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5);
        }
    }
    // The 19 animations play together: merged, they must match the reference playing all 19.
    let merged = Clip::merged("walk", &doc.clips);
    assert!((merged.duration_s - 2.0).abs() < 0.01);
    let reference = Reference::open(&p);
    check_clip(&p, &doc, &reference, Some((&merged, (0..19).collect())));
    check_clip(&p, &doc, &reference, None);
}

#[test]
fn fox() {
    let Some(p) = asset("khronos-fox/Fox.glb") else {
        return;
    };
    let e = Expect {
        vertices: 1728,
        triangles: 576,
        skins: 1,
        joints: 24,
        max_influences: 4,
        unnormalized: false,
        clips: &[("Survey", 3.417), ("Walk", 0.708), ("Run", 1.158)],
        clip_count: 3,
    };
    let doc = check_counts(&p, &e);
    check_all_clips(&p, &doc);
}

#[test]
fn simple_skin() {
    let Some(p) = asset("khronos-simpleskin/SimpleSkin.gltf") else {
        return;
    };
    let e = Expect {
        vertices: 10,
        triangles: 8,
        skins: 1,
        joints: 2,
        max_influences: 2,
        unnormalized: false,
        clips: &[],
        clip_count: 1,
    };
    let doc = check_counts(&p, &e);
    assert!((doc.clips[0].duration_s - 5.5).abs() < 0.01);
    check_all_clips(&p, &doc);
}

#[test]
fn robot_expressive_two_skins_and_rigid_parts() {
    let Some(p) = asset("threejs-robotexpressive/RobotExpressive.glb") else {
        return;
    };
    let e = Expect {
        vertices: 7214,
        triangles: 3237,
        skins: 2,
        joints: 43,
        max_influences: 4,
        unnormalized: true,
        clips: &[
            ("Dance", 3.33),
            ("Death", 0.96),
            ("Idle", 3.33),
            ("Jump", 0.71),
            ("No", 1.67),
            ("Punch", 0.83),
            ("Running", 0.96),
            ("Sitting", 0.42),
            ("Standing", 0.42),
            ("ThumbsUp", 1.58),
            ("Walking", 0.96),
            ("WalkJump", 0.83),
            ("Wave", 1.83),
            ("Yes", 1.67),
        ],
        clip_count: 14,
    };
    let doc = check_counts(&p, &e);
    let skinned: usize = doc.skins.iter().map(|s| s.template.vertex_count()).sum();
    assert_eq!(skinned, 1108);
    assert_eq!(doc.primitive_count, 19);
    check_all_clips(&p, &doc);
}

#[test]
fn witch_embedded_buffer() {
    let Some(p) = asset("quaternius-witch/Witch.gltf") else {
        return;
    };
    let e = Expect {
        vertices: 13884,
        triangles: 6872,
        skins: 1,
        joints: 62,
        max_influences: 4,
        unnormalized: false,
        clips: &[
            ("Death", 1.33),
            ("Idle", 2.08),
            ("Run", 1.0),
            ("Walk", 1.67),
            ("Wave", 2.08),
            ("Sword_Slash", 1.29),
        ],
        clip_count: 24,
    };
    let doc = check_counts(&p, &e);
    check_all_clips(&p, &doc);
}

#[test]
fn female_peasant_external_bin() {
    let Some(p) = asset("quaternius-female-peasant/Female_Peasant.gltf") else {
        return;
    };
    let e = Expect {
        vertices: 10184,
        triangles: 13568,
        skins: 1,
        joints: 65,
        max_influences: 4,
        unnormalized: false,
        clips: &[],
        clip_count: 0,
    };
    let doc = check_counts(&p, &e);
    assert_eq!(doc.skins[0].primitives.len(), 4);
    assert!(doc.skins[0].template.colors.is_some());
    check_all_clips(&p, &doc);
}
