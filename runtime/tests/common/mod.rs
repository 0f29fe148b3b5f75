//! Shared fixtures for the runtime's integration tests: random (seeded) `.skf` models on a
//! small tree skeleton, poses and points.
#![allow(dead_code)]

use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::math::rotvec_to_quat;
use skinfield_formats::skf::{ModelConfig, Net, SkfModel};
use skinfield_formats::{Pose, Skeleton, Transform};

/// Canonical bounding-box minimum of the fixture models (a person-sized box, metres).
pub const BBOX_MIN: [f32; 3] = [-0.6, -0.1, -0.3];
/// Canonical bounding-box maximum of the fixture models.
pub const BBOX_MAX: [f32; 3] = [0.6, 1.8, 0.3];

/// The seeded generator every fixture draws from.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A binary-tree skeleton of `j` joints hanging down from a root at 1 m.
pub fn skeleton(j: usize, rng: &mut ChaCha8Rng) -> Skeleton {
    let names = (0..j).map(|i| format!("joint{i}")).collect();
    let parents = (0..j)
        .map(|i| if i == 0 { None } else { Some((i - 1) / 2) })
        .collect();
    let locals = (0..j)
        .map(|i| {
            let t = if i == 0 {
                Vec3::new(0.0, 1.0, 0.0)
            } else {
                Vec3::new(
                    rng.random_range(-0.2..0.2),
                    -0.15,
                    rng.random_range(-0.1..0.1),
                )
            };
            let r = rotvec_to_quat(Vec3::new(
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.3..0.3),
            ));
            Transform::from_rotation_translation(r, t)
        })
        .collect();
    Skeleton::new(names, parents, locals, None, None, Mat4::IDENTITY).unwrap()
}

/// A config and random weights (He-like scale, so activations neither vanish nor explode).
pub fn random_model(config: ModelConfig, seed: u64) -> SkfModel {
    let mut rng = rng(seed);
    let skeleton = skeleton(config.joint_count as usize, &mut rng);
    let mut m = SkfModel {
        config,
        skeleton,
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    let shapes: Vec<_> = config.layer_shapes(Net::Skin).collect();
    for (i, (out, inp)) in shapes.into_iter().enumerate() {
        let s = (6.0 / inp as f32).sqrt();
        let w = (0..out * inp).map(|_| rng.random_range(-s..s)).collect();
        let b = (0..out).map(|_| rng.random_range(-0.1..0.1)).collect();
        m.push_layer(Net::Skin, i, w, out, inp, b);
    }
    m
}

/// The paper's architecture for `j` joints, random weights, as `.skf` bytes.
pub fn vinecs_bytes(j: u32, seed: u64) -> Vec<u8> {
    random_model(ModelConfig::paper_architecture(j, BBOX_MIN, BBOX_MAX), seed)
        .to_bytes()
        .unwrap()
}

/// A small odd-shaped config (widths not multiples of the panel height, a skip at layer 2).
pub fn odd_config() -> ModelConfig {
    let mut c = ModelConfig::paper_architecture(5, BBOX_MIN, BBOX_MAX);
    c.pe_frequencies = 2;
    c.hidden_count = 3;
    c.hidden = [13, 21, 9, 0, 0, 0, 0, 0];
    c.skip_layer = 2;
    c
}

/// Another: no skip connection (skip at layer 0 means only layer 0 sees the input).
pub fn no_skip_config() -> ModelConfig {
    let mut c = ModelConfig::paper_architecture(3, BBOX_MIN, BBOX_MAX);
    c.pe_frequencies = 0;
    c.softplus_beta = 1.0;
    c.hidden_count = 2;
    c.hidden = [10, 6, 0, 0, 0, 0, 0, 0];
    c.skip_layer = 0;
    c
}

/// A pose: every joint bent by a random rotation of up to `amount` rad, root moved and turned.
pub fn random_pose(s: &Skeleton, rng: &mut ChaCha8Rng, amount: f32) -> Pose {
    let mut pose = s.bind_pose();
    for (j, l) in pose.locals.iter_mut().enumerate() {
        let r = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * amount;
        l.rotation = (l.rotation * rotvec_to_quat(r)).normalize();
        if j == 0 {
            l.rotation =
                (Quat::from_rotation_y(rng.random_range(-3.0..3.0)) * l.rotation).normalize();
            l.translation += Vec3::new(
                rng.random_range(-1.0..1.0),
                0.0,
                rng.random_range(-1.0..1.0),
            );
        }
    }
    pose
}

/// Points in (and a little outside) the canonical box.
pub fn random_points(n: usize, rng: &mut ChaCha8Rng) -> Vec<Vec3> {
    (0..n)
        .map(|_| {
            Vec3::from_array(std::array::from_fn(|k| {
                let (lo, hi) = (BBOX_MIN[k], BBOX_MAX[k]);
                rng.random_range(lo - 0.05..hi + 0.05)
            }))
        })
        .collect()
}

/// Random unit normals and tangents.
pub fn random_frames(n: usize, rng: &mut ChaCha8Rng) -> (Vec<Vec3>, Vec<glam::Vec4>) {
    let mut unit = || {
        Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(Vec3::Y)
    };
    let normals: Vec<Vec3> = (0..n).map(|_| unit()).collect();
    let tangents = (0..n)
        .map(|i| unit().extend(if i.is_multiple_of(2) { 1.0 } else { -1.0 }))
        .collect();
    (normals, tangents)
}

/// A closed ellipsoid filling the fixture box, as a UV sphere with a seam: `rings` latitude
/// bands, `segments` longitudes, the seam column duplicated (as glTF exporters split UV seams)
/// and one vertex per pole. Returns positions, outward normals and triangles.
pub fn ellipsoid(rings: u32, segments: u32) -> (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>) {
    let c = Vec3::from_array(std::array::from_fn(|k| 0.5 * (BBOX_MIN[k] + BBOX_MAX[k])));
    let r = Vec3::from_array(std::array::from_fn(|k| 0.45 * (BBOX_MAX[k] - BBOX_MIN[k])));
    let mut unit = vec![Vec3::Y];
    for i in 1..rings {
        let theta = std::f32::consts::PI * i as f32 / rings as f32;
        for s in 0..=segments {
            let phi = std::f32::consts::TAU * (s % segments) as f32 / segments as f32;
            unit.push(Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            ));
        }
    }
    unit.push(-Vec3::Y);
    let row = |i: u32, s: u32| 1 + (i - 1) * (segments + 1) + s;
    let south = unit.len() as u32 - 1;
    let mut tris = Vec::new();
    for s in 0..segments {
        tris.push([0, row(1, s + 1), row(1, s)]);
        for i in 1..rings - 1 {
            let (a, b, c2, d) = (row(i, s), row(i, s + 1), row(i + 1, s), row(i + 1, s + 1));
            tris.push([a, b, c2]);
            tris.push([b, d, c2]);
        }
        tris.push([south, row(rings - 1, s), row(rings - 1, s + 1)]);
    }
    let positions = unit.iter().map(|u| c + *u * r).collect();
    let normals = unit.iter().map(|u| (*u / r).normalize()).collect();
    (positions, normals, tris)
}
