//! Fixtures shared by the criterion benches in `benches/`: seeded random SkinNet models with the
//! paper's architecture, canonical points and poses.

use glam::{Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::math::rotvec_to_quat;
use skinfield_formats::skf::{ModelConfig, Net, SkfModel};
use skinfield_formats::{Pose, Skeleton, Transform};

/// Canonical box of the fixtures (a standing person, metres).
pub const BBOX_MIN: [f32; 3] = [-0.6, -0.1, -0.3];
/// Canonical box maximum.
pub const BBOX_MAX: [f32; 3] = [0.6, 1.8, 0.3];

/// A seeded RNG.
#[must_use]
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A binary-tree skeleton of `j` joints.
#[must_use]
pub fn skeleton(j: usize, rng: &mut ChaCha8Rng) -> Skeleton {
    let names = (0..j).map(|i| format!("joint{i}")).collect();
    let parents = (0..j)
        .map(|i| if i == 0 { None } else { Some((i - 1) / 2) })
        .collect();
    let locals = (0..j)
        .map(|i| {
            let t = if i == 0 {
                Vec3::Y
            } else {
                Vec3::new(rng.random_range(-0.2..0.2), -0.15, 0.0)
            };
            Transform::from_rotation_translation(Quat::IDENTITY, t)
        })
        .collect();
    // Joint names are distinct and parents precede children: construction cannot fail.
    Skeleton::new(names, parents, locals, None, None, Mat4::IDENTITY)
        .expect("valid fixture skeleton")
}

/// `.skf` bytes of the paper's SkinNet (hidden 256, 256, 128, 256, 256, skip at layer 2,
/// L = 6, β = 100) for `j` joints with random He-scaled weights.
#[must_use]
pub fn vinecs_skf(j: u32, seed: u64) -> Vec<u8> {
    let mut rng = rng(seed);
    let config = ModelConfig::vinecs(j, BBOX_MIN, BBOX_MAX);
    let skeleton = skeleton(j as usize, &mut rng);
    let mut m = SkfModel {
        config,
        skeleton,
        tensors: Vec::new(),
    };
    let shapes: Vec<_> = config.layer_shapes(Net::Skin).collect();
    for (i, (out, inp)) in shapes.into_iter().enumerate() {
        let s = (6.0 / inp as f32).sqrt();
        let w = (0..out * inp).map(|_| rng.random_range(-s..s)).collect();
        let b = (0..out).map(|_| rng.random_range(-0.1..0.1)).collect();
        m.push_layer(Net::Skin, i, w, out, inp, b);
    }
    m.to_bytes().expect("fixture model serialises")
}

/// `n` points in the canonical box.
#[must_use]
pub fn points(n: usize, rng: &mut ChaCha8Rng) -> Vec<Vec3> {
    (0..n)
        .map(|_| {
            Vec3::from_array(std::array::from_fn(|k| {
                rng.random_range(BBOX_MIN[k]..BBOX_MAX[k])
            }))
        })
        .collect()
}

/// A random pose: every joint bent by up to `amount` rad.
#[must_use]
pub fn pose(s: &Skeleton, rng: &mut ChaCha8Rng, amount: f32) -> Pose {
    let mut pose = s.bind_pose();
    for l in &mut pose.locals {
        let r = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * amount;
        l.rotation = (l.rotation * rotvec_to_quat(r)).normalize();
    }
    pose
}
