//! The shared glTF assets: counts against their SOURCE.md, and sampled clip poses against an
//! independent glTF skinning reference written here straight on the gltf crate (its own buffer
//! loading, node hierarchy from sampled node TRS in f64, joint world × IBM, weighted sum).

use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3, Mat4, Vec3};
use skinfield_formats::gltf_io::{Clip, GltfDocument, GltfSkin, load_gltf};
use skinfield_formats::shared_data::shared_data_dir;

fn asset(rel: &str) -> Option<PathBuf> {
    shared_data_dir().map(|d| d.join(rel))
}

// ---------------------------------------------------------------- independent reference

type Trs = (DVec3, DQuat, DVec3);

struct Reference {
    doc: gltf::Document,
    buffers: Vec<gltf::buffer::Data>,
}

impl Reference {
    fn open(path: &Path) -> Self {
        let g = gltf::Gltf::open(path).unwrap();
        let buffers = gltf::import_buffers(&g.document, path.parent(), g.blob.clone()).unwrap();
        Self {
            doc: g.document,
            buffers,
        }
    }

    /// Node local TRS at time t with the channels of `animations` applied.
    fn locals(&self, animations: &[usize], t: f64) -> Vec<Trs> {
        let mut out: Vec<Trs> = self
            .doc
            .nodes()
            .map(|n| {
                let (tr, r, s) = n.transform().decomposed();
                let r = DQuat::from_xyzw(r[0].into(), r[1].into(), r[2].into(), r[3].into());
                (Vec3::from(tr).as_dvec3(), r, Vec3::from(s).as_dvec3())
            })
            .collect();
        let data = |b: gltf::Buffer<'_>| Some(&self.buffers[b.index()].0[..]);
        for a in animations {
            let anim = self.doc.animations().nth(*a).unwrap();
            for ch in anim.channels() {
                use gltf::animation::util::ReadOutputs as O;
                let r = ch.reader(data);
                let times: Vec<f64> = r.read_inputs().unwrap().map(f64::from).collect();
                let vals: Vec<[f64; 4]> = match r.read_outputs().unwrap() {
                    O::Translations(i) | O::Scales(i) => i
                        .map(|v| [v[0].into(), v[1].into(), v[2].into(), 0.0])
                        .collect(),
                    O::Rotations(i) => i
                        .into_f32()
                        .map(|v| [v[0].into(), v[1].into(), v[2].into(), v[3].into()])
                        .collect(),
                    O::MorphTargetWeights(_) => continue,
                };
                let v = sample_ref(
                    &times,
                    &vals,
                    ch.sampler().interpolation(),
                    ch.target().property(),
                    t,
                );
                let n = &mut out[ch.target().node().index()];
                match ch.target().property() {
                    gltf::animation::Property::Translation => n.0 = DVec3::new(v[0], v[1], v[2]),
                    gltf::animation::Property::Rotation => n.1 = DQuat::from_array(v).normalize(),
                    gltf::animation::Property::Scale => n.2 = DVec3::new(v[0], v[1], v[2]),
                    gltf::animation::Property::MorphTargetWeights => {}
                }
            }
        }
        out
    }

    fn worlds(&self, locals: &[Trs]) -> Vec<DMat4> {
        let mut parent = vec![None; locals.len()];
        for n in self.doc.nodes() {
            for c in n.children() {
                parent[c.index()] = Some(n.index());
            }
        }
        let local = |i: usize| {
            // Matrix nodes are used as given, TRS nodes from the (sampled) TRS.
            let node = self.doc.nodes().nth(i).unwrap();
            match node.transform() {
                gltf::scene::Transform::Matrix { matrix } => {
                    Mat4::from_cols_array_2d(&matrix).as_dmat4()
                }
                gltf::scene::Transform::Decomposed { .. } => {
                    let (t, r, s) = locals[i];
                    DMat4::from_scale_rotation_translation(s, r, t)
                }
            }
        };
        (0..locals.len())
            .map(|i| {
                let mut m = local(i);
                let mut at = parent[i];
                while let Some(p) = at {
                    m = local(p) * m;
                    at = parent[p];
                }
                m
            })
            .collect()
    }

    /// Skinned positions of every primitive skinned by `skin`, in mesh/primitive/vertex order;
    /// weights divided by their sum (Skinfield's semantics for un-normalised files).
    fn skinned(&self, skin: usize, worlds: &[DMat4]) -> Vec<DVec3> {
        let data = |b: gltf::Buffer<'_>| Some(&self.buffers[b.index()].0[..]);
        let s = self.doc.skins().nth(skin).unwrap();
        let joints: Vec<usize> = s.joints().map(|j| j.index()).collect();
        let ibm: Vec<DMat4> = match s.reader(data).read_inverse_bind_matrices() {
            Some(it) => it
                .map(|m| Mat4::from_cols_array_2d(&m).as_dmat4())
                .collect(),
            None => vec![DMat4::IDENTITY; joints.len()],
        };
        let mats: Vec<DMat4> = joints
            .iter()
            .zip(&ibm)
            .map(|(&j, b)| worlds[j] * *b)
            .collect();
        let mut out = Vec::new();
        for mesh in self.doc.meshes() {
            let used = self.doc.nodes().any(|n| {
                n.mesh().map(|m| m.index()) == Some(mesh.index())
                    && n.skin().map(|s| s.index()) == Some(skin)
            });
            if !used {
                continue;
            }
            for p in mesh.primitives() {
                let r = p.reader(data);
                let pos: Vec<DVec3> = r
                    .read_positions()
                    .unwrap()
                    .map(|p| Vec3::from(p).as_dvec3())
                    .collect();
                let mut acc = vec![(DVec3::ZERO, 0.0f64); pos.len()];
                let mut set = 0;
                while let (Some(js), Some(ws)) = (r.read_joints(set), r.read_weights(set)) {
                    for (v, (j, w)) in js.into_u16().zip(ws.into_f32()).enumerate() {
                        for k in 0..4 {
                            let w = f64::from(w[k]);
                            acc[v].0 += w * mats[usize::from(j[k])].transform_point3(pos[v]);
                            acc[v].1 += w;
                        }
                    }
                    set += 1;
                }
                out.extend(acc.iter().map(|(p, w)| *p / *w));
            }
        }
        out
    }
}

fn sample_ref(
    times: &[f64],
    vals: &[[f64; 4]],
    interp: gltf::animation::Interpolation,
    prop: gltf::animation::Property,
    t: f64,
) -> [f64; 4] {
    use gltf::animation::Interpolation as I;
    let cubic = interp == I::CubicSpline;
    let value = |k: usize| if cubic { vals[3 * k + 1] } else { vals[k] };
    let n = times.len();
    if t <= times[0] {
        return value(0);
    }
    if t >= times[n - 1] {
        return value(n - 1);
    }
    let mut k = 0;
    while times[k + 1] <= t {
        k += 1;
    }
    let dt = times[k + 1] - times[k];
    let u = (t - times[k]) / dt;
    let lerp = |a: [f64; 4], b: [f64; 4], u: f64| [0, 1, 2, 3].map(|i| a[i] + (b[i] - a[i]) * u);
    match interp {
        I::Step => value(k),
        I::Linear if prop == gltf::animation::Property::Rotation => {
            // Slerp from the spec's formula: a = acos|d|, sign-corrected second quaternion.
            let (a, b) = (vals[k], vals[k + 1]);
            let d: f64 = (0..4).map(|i| a[i] * b[i]).sum();
            let s = if d < 0.0 { -1.0 } else { 1.0 };
            let ang = d.abs().min(1.0).acos();
            if ang < 1e-9 {
                return lerp(a, b.map(|x| x * s), u);
            }
            let (ka, kb) = (
                ((1.0 - u) * ang).sin() / ang.sin(),
                s * (u * ang).sin() / ang.sin(),
            );
            [0, 1, 2, 3].map(|i| ka * a[i] + kb * b[i])
        }
        I::Linear => lerp(vals[k], vals[k + 1], u),
        I::CubicSpline => {
            let (p0, m0, p1, m1) = (
                vals[3 * k + 1],
                vals[3 * k + 2],
                vals[3 * k + 4],
                vals[3 * k + 3],
            );
            let (u2, u3) = (u * u, u * u * u);
            [0, 1, 2, 3].map(|i| {
                (2.0 * u3 - 3.0 * u2 + 1.0) * p0[i]
                    + (u3 - 2.0 * u2 + u) * dt * m0[i]
                    + (-2.0 * u3 + 3.0 * u2) * p1[i]
                    + (u3 - u2) * dt * m1[i]
            })
        }
    }
}

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

/// Largest distance between our skinned positions and the reference's, over the model size.
fn relative_error(ours: &[Vec3], reference: &[DVec3]) -> f64 {
    assert_eq!(ours.len(), reference.len());
    let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
    for r in reference {
        lo = lo.min(*r);
        hi = hi.max(*r);
    }
    let size = (hi - lo).length().max(1e-9);
    ours.iter()
        .zip(reference)
        .map(|(a, b)| (a.as_dvec3() - *b).length())
        .fold(0.0, f64::max)
        / size
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
                err < 1e-4,
                "{}: skin {} clip {name} t={t}: relative error {err:e}",
                path.display(),
                skin.index
            );
        }
    }
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
