//! An independent glTF skinning reference for the tests, written straight on the gltf crate:
//! its own buffer loading, node hierarchy from sampled node TRS in f64, joint world × IBM,
//! weighted sum. Shares no code with `skinfield_formats::gltf_io`.
#![allow(dead_code)]

use std::path::Path;

use glam::{DMat4, DQuat, DVec3, Mat4, Vec3};

// ---------------------------------------------------------------- independent reference

pub type Trs = (DVec3, DQuat, DVec3);

pub struct Reference {
    /// The parsed document.
    pub doc: gltf::Document,
    /// Its buffers, loaded by the gltf crate's own importer.
    pub buffers: Vec<gltf::buffer::Data>,
}

impl Reference {
    pub fn open(path: &Path) -> Self {
        let g = gltf::Gltf::open(path).unwrap();
        let buffers = gltf::import_buffers(&g.document, path.parent(), g.blob.clone()).unwrap();
        Self {
            doc: g.document,
            buffers,
        }
    }

    /// Node local TRS at time t with the channels of `animations` applied.
    pub fn locals(&self, animations: &[usize], t: f64) -> Vec<Trs> {
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

    pub fn worlds(&self, locals: &[Trs]) -> Vec<DMat4> {
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
    pub fn skinned(&self, skin: usize, worlds: &[DMat4]) -> Vec<DVec3> {
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

/// Largest distance between our skinned positions and the reference's, over the model size.
pub fn relative_error(ours: &[Vec3], reference: &[DVec3]) -> f64 {
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
