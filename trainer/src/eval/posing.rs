//! Posing a template with static weights: linear blend skinning and dual-quaternion skinning.
//!
//! Written for evaluation, independently of the ground-truth deformer of the synthetic capture
//! and of the runtime, so that an `oracle` row measures the weights and not a shared bug.
//! LBS: `x = Σ_j w_j · S_j · x̄` with `S_j = world_j · inverse_bind_j`.
//! DQS (Kavan et al. 2007): each `S_j` as a unit dual quaternion, blended linearly with every
//! influence flipped into the hemisphere of the vertex's heaviest influence, normalised, applied.
//! DQS assumes rigid skinning matrices: a scale in `S_j` is dropped (the synthetic skeletons
//! have none).

use glam::{Mat4, Quat, Vec3};
use skinfield_formats::{Pose, Skeleton, SkeletonError, StaticSkin};

/// How static weights blend the joint transforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Blend {
    /// Linear blend skinning.
    Linear,
    /// Dual-quaternion skinning.
    DualQuaternion,
}

/// Why a mesh could not be posed.
#[derive(Debug, thiserror::Error)]
pub enum PosingError {
    /// The pose does not fit the skeleton.
    #[error("pose: {0}")]
    Pose(#[from] SkeletonError),
    /// The weights are for another vertex or joint count.
    #[error(
        "weights cover {weights_vertices} vertices and {weights_joints} joints, the mesh has {vertices} and the skeleton {joints}"
    )]
    Mismatch {
        /// Vertices in the weights.
        weights_vertices: usize,
        /// Joints in the weights.
        weights_joints: usize,
        /// Vertices in the mesh.
        vertices: usize,
        /// Joints in the skeleton.
        joints: usize,
    },
}

/// A rigid transform as a unit dual quaternion `real + ε·dual`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct DualQuat {
    real: Quat,
    dual: Quat,
}

impl DualQuat {
    fn from_mat4(m: &Mat4) -> Self {
        let (_, rotation, t) = m.to_scale_rotation_translation();
        let real = rotation.normalize();
        // dual = ½ · (t, 0) · real
        let dual = Quat::from_xyzw(t.x, t.y, t.z, 0.0) * real * 0.5;
        Self { real, dual }
    }

    fn transform_point(&self, p: Vec3) -> Vec3 {
        // Translation: 2 · dual · conj(real) (vector part) for a unit real part.
        let t = self.dual * self.real.conjugate() * 2.0;
        self.real * p + Vec3::new(t.x, t.y, t.z)
    }
}

/// Skinning matrices of `pose` (one per joint).
pub fn skinning_matrices(skeleton: &Skeleton, pose: &Pose) -> Result<Vec<Mat4>, SkeletonError> {
    let mut m = vec![Mat4::IDENTITY; skeleton.len()];
    skeleton.skinning_matrices(pose, &mut m)?;
    Ok(m)
}

/// Poses `rest` (canonical positions) with static weights under `blend`.
pub fn pose_static(
    skeleton: &Skeleton,
    skin: &StaticSkin,
    rest: &[Vec3],
    pose: &Pose,
    blend: Blend,
) -> Result<Vec<Vec3>, PosingError> {
    if skin.vertex_count() != rest.len() || skin.joint_count() != skeleton.len() {
        return Err(PosingError::Mismatch {
            weights_vertices: skin.vertex_count(),
            weights_joints: skin.joint_count(),
            vertices: rest.len(),
            joints: skeleton.len(),
        });
    }
    let mats = skinning_matrices(skeleton, pose)?;
    Ok(match blend {
        Blend::Linear => rest
            .iter()
            .enumerate()
            .map(|(v, &x)| {
                let (joints, weights) = skin.influences(v);
                joints
                    .iter()
                    .zip(weights)
                    .map(|(&j, &w)| mats[j as usize].transform_point3(x) * w)
                    .sum()
            })
            .collect(),
        Blend::DualQuaternion => {
            let dqs: Vec<DualQuat> = mats.iter().map(DualQuat::from_mat4).collect();
            rest.iter()
                .enumerate()
                .map(|(v, &x)| dqs_point(&dqs, skin, v, x))
                .collect()
        }
    })
}

/// Poses `rest` with dense per-vertex weights (`rest.len() × skeleton.len()`, row-major, e.g.
/// SkinNet's output for this pose) under linear blend skinning.
pub fn pose_dense_lbs(
    skeleton: &Skeleton,
    weights: &[f32],
    rest: &[Vec3],
    pose: &Pose,
) -> Result<Vec<Vec3>, PosingError> {
    let j = skeleton.len();
    if rest.len().checked_mul(j) != Some(weights.len()) {
        return Err(PosingError::Mismatch {
            weights_vertices: weights.len() / j,
            weights_joints: j,
            vertices: rest.len(),
            joints: j,
        });
    }
    let mats = skinning_matrices(skeleton, pose)?;
    Ok(rest
        .iter()
        .zip(weights.chunks_exact(j))
        .map(|(&x, w)| {
            // Blend the matrices, then transform once: the same sum, J times fewer transforms.
            let m = mats
                .iter()
                .zip(w)
                .filter(|(_, w)| **w != 0.0)
                .fold(Mat4::ZERO, |acc, (m, &w)| acc + *m * w);
            m.transform_point3(x)
        })
        .collect())
}

fn dqs_point(dqs: &[DualQuat], skin: &StaticSkin, v: usize, x: Vec3) -> Vec3 {
    let (joints, weights) = skin.influences(v);
    let mut heaviest = 0;
    for (k, &w) in weights.iter().enumerate() {
        if w > weights[heaviest] {
            heaviest = k;
        }
    }
    let pivot = dqs[joints[heaviest] as usize].real;
    let (mut real, mut dual) = (
        Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
    );
    for (&j, &w) in joints.iter().zip(weights) {
        let dq = dqs[j as usize];
        // q and -q are the same rotation; blending across hemispheres would cancel them.
        let w = if dq.real.dot(pivot) < 0.0 { -w } else { w };
        real += dq.real * w;
        dual += dq.dual * w;
    }
    let norm = real.length();
    if norm.is_nan() || norm <= 1e-12 {
        // Opposite rotations with equal weights: no defined blend; keep the heaviest joint's.
        return dqs[joints[heaviest] as usize].transform_point(x);
    }
    DualQuat {
        real: real / norm,
        dual: dual / norm,
    }
    .transform_point(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinfield_formats::Transform;

    /// Two joints along +Y: a root at the origin and a child at y = 1.
    fn two_bones() -> Skeleton {
        Skeleton::new(
            vec!["root".into(), "child".into()],
            vec![None, Some(0)],
            vec![Transform::IDENTITY, Transform::from_translation(Vec3::Y)],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap()
    }

    fn twisted(angle: f32) -> Pose {
        let s = two_bones();
        let mut pose = s.bind_pose();
        pose.locals[1].rotation = Quat::from_rotation_y(angle);
        pose
    }

    #[test]
    fn rigid_weights_move_with_their_joint_under_both_blends() {
        let s = two_bones();
        let skin = StaticSkin::from_dense(&[1.0, 0.0, 0.0, 1.0], 2).unwrap();
        let rest = [Vec3::new(0.3, 0.5, 0.0), Vec3::new(0.3, 1.5, 0.0)];
        let mut pose = s.bind_pose();
        pose.locals[1].rotation = Quat::from_rotation_z(0.7);
        pose.locals[0].translation = Vec3::new(0.1, 0.2, 0.3);
        let mut world = [Mat4::IDENTITY; 2];
        s.world_matrices(&pose, &mut world).unwrap();
        let expect = [
            world[0].transform_point3(rest[0]),
            world[1].transform_point3(rest[1] - Vec3::Y),
        ];
        for blend in [Blend::Linear, Blend::DualQuaternion] {
            let got = pose_static(&s, &skin, &rest, &pose, blend).unwrap();
            for (g, e) in got.iter().zip(&expect) {
                assert!((*g - *e).length() < 1e-5, "{blend:?}: {g} vs {e}");
            }
        }
    }

    #[test]
    fn half_weights_under_a_twist_collapse_with_lbs_and_keep_volume_with_dqs() {
        // A point at radius r around the twisting bone, weighted half and half. LBS averages the
        // rotated and unrotated points: radius r·|cos(θ/2)|, zero at θ = π (candy wrapper). DQS
        // rotates by θ/2 about the same axis: radius r exactly.
        let s = two_bones();
        let skin = StaticSkin::from_dense(&[0.5, 0.5], 2).unwrap();
        let r = 0.2f32;
        let rest = [Vec3::new(r, 1.0, 0.0)];
        for angle in [0.5f32, 1.5, 3.0] {
            let pose = twisted(angle);
            let lbs = pose_static(&s, &skin, &rest, &pose, Blend::Linear).unwrap()[0];
            let dqs = pose_static(&s, &skin, &rest, &pose, Blend::DualQuaternion).unwrap()[0];
            let radius = |p: Vec3| Vec3::new(p.x, 0.0, p.z).length();
            assert!(
                (radius(lbs) - r * (angle / 2.0).cos().abs()).abs() < 1e-5,
                "lbs at {angle}"
            );
            assert!((radius(dqs) - r).abs() < 1e-5, "dqs at {angle}");
            let expect = Quat::from_rotation_y(angle / 2.0) * Vec3::new(r, 0.0, 0.0) + Vec3::Y;
            assert!(
                (dqs - expect).length() < 1e-5,
                "dqs direction at {angle}: {dqs} vs {expect}"
            );
        }
    }

    #[test]
    fn dense_lbs_equals_sparse_lbs() {
        let s = two_bones();
        let dense = [0.2, 0.8, 0.6, 0.4, 1.0, 0.0];
        let skin = StaticSkin::from_dense(&dense, 2).unwrap();
        let rest = [
            Vec3::new(0.1, 0.4, 0.2),
            Vec3::new(-0.3, 1.2, 0.1),
            Vec3::new(0.0, 2.0, -0.5),
        ];
        let mut pose = twisted(0.9);
        pose.locals[1].rotation *= Quat::from_rotation_x(0.4);
        pose.locals[0].translation = Vec3::new(0.5, 0.0, -0.2);
        let a = pose_static(&s, &skin, &rest, &pose, Blend::Linear).unwrap();
        let b = pose_dense_lbs(&s, &dense, &rest, &pose).unwrap();
        for (a, b) in a.iter().zip(&b) {
            assert!((*a - *b).length() < 1e-5, "{a} vs {b}");
        }
        assert!(pose_dense_lbs(&s, &dense[..4], &rest, &pose).is_err());
    }

    #[test]
    fn mismatched_weights_are_an_error() {
        let s = two_bones();
        let skin = StaticSkin::from_dense(&[1.0, 0.0], 2).unwrap();
        let e = pose_static(
            &s,
            &skin,
            &[Vec3::ZERO, Vec3::X],
            &s.bind_pose(),
            Blend::Linear,
        );
        assert!(matches!(
            e,
            Err(PosingError::Mismatch {
                weights_vertices: 1,
                vertices: 2,
                ..
            })
        ));
    }
}
