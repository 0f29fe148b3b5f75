//! Poses and the pose features `θ̃` that SkinNet takes as input (see `docs/design.md`,
//! *Pose features*).
//!
//! One function, [`pose_features`], is used by the trainer and the runtime alike, so the
//! encoding cannot drift between them; [`POSE_FEATURE_ENCODING`] is recorded in the `.skf`.

use alloc::vec::Vec;

use glam::{Quat, Vec3};

use crate::math::{Transform, quat_to_rotvec, twist_about};
use crate::skeleton::{Skeleton, SkeletonError};

/// Identifier of the pose-feature encoding implemented by [`pose_features`], stored in `.skf`
/// files: 1 = translation dropped, root yaw about the up axis removed, every joint's local
/// rotation relative to its bind local rotation as a rotation vector, 3 numbers per joint in
/// joint order.
pub const POSE_FEATURE_ENCODING: u32 = 1;

/// A skeleton pose: the local transform of every joint, in joint order.
///
/// Joints that a motion does not animate keep their bind-pose values; the root translation is
/// `locals[root].translation`.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    /// Local transform per joint.
    pub locals: Vec<Transform>,
}

/// The world's up axis (the axis about which root heading is removed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpAxis {
    /// +Y (glTF, BVH).
    Y,
    /// +Z.
    Z,
}

impl UpAxis {
    /// Unit vector of the axis.
    #[must_use]
    pub fn unit(self) -> Vec3 {
        match self {
            UpAxis::Y => Vec3::Y,
            UpAxis::Z => Vec3::Z,
        }
    }

    /// Code stored in `.skf` files.
    #[must_use]
    pub fn code(self) -> u32 {
        match self {
            UpAxis::Y => 1,
            UpAxis::Z => 2,
        }
    }

    /// Axis from its `.skf` code.
    #[must_use]
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            1 => Some(UpAxis::Y),
            2 => Some(UpAxis::Z),
            _ => None,
        }
    }
}

/// Why pose features could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PoseError {
    /// The pose does not fit the skeleton (joint count, NaN).
    #[error(transparent)]
    Skeleton(#[from] SkeletonError),
    /// The output slice has the wrong length.
    #[error("pose feature buffer has {len} entries, expected {expected}")]
    OutputLength {
        /// Its length.
        len: usize,
        /// `3 × joints`.
        expected: usize,
    },
}

/// Number of pose features for a skeleton of `joints` joints.
#[must_use]
pub const fn pose_feature_count(joints: usize) -> usize {
    3 * joints
}

/// Writes the pose features `θ̃` of `pose` into `out` (length `3 × joints`), without allocating.
///
/// - non-root joint `j`: `log(b_j⁻¹ · q_j)`, the local rotation relative to the bind local
///   rotation `b_j`, as a shortest-arc rotation vector;
/// - root joint: the world rotation relative to the bind world rotation,
///   `R = (B·q)(B·b)⁻¹` with `B` the skeleton base rotation, with its heading (twist about the
///   world up axis) removed: `log(twist⁻¹ · R)`;
/// - translations are dropped.
pub fn pose_features(
    skeleton: &Skeleton,
    pose: &Pose,
    up: UpAxis,
    out: &mut [f32],
) -> Result<(), PoseError> {
    skeleton.check_pose(pose)?;
    let expected = pose_feature_count(skeleton.len());
    if out.len() != expected {
        return Err(PoseError::OutputLength {
            len: out.len(),
            expected,
        });
    }
    let base_rotation = Transform::from_mat4(&skeleton.base()).rotation;
    for (j, ((local, bind), parent)) in pose
        .locals
        .iter()
        .zip(skeleton.bind_local())
        .zip(skeleton.parents())
        .enumerate()
    {
        let q = local.rotation.normalize();
        let rel = match parent {
            Some(_) => bind.rotation.inverse() * q,
            None => {
                let world: Quat = base_rotation * q * (base_rotation * bind.rotation).inverse();
                let yaw = twist_about(world, up.unit());
                yaw.inverse() * world
            }
        };
        let r = quat_to_rotvec(rel.normalize());
        out[3 * j..3 * j + 3].copy_from_slice(&r.to_array());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString;
    use alloc::vec;
    use glam::Mat4;

    fn two_joint() -> Skeleton {
        Skeleton::new(
            vec!["hips".to_string(), "knee".to_string()],
            vec![None, Some(0)],
            vec![
                Transform::from_rotation_translation(Quat::from_rotation_x(0.3), Vec3::Y),
                Transform::from_rotation_translation(Quat::from_rotation_z(0.2), Vec3::NEG_Y * 0.4),
            ],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn bind_pose_has_zero_features() {
        let s = two_joint();
        let mut f = [1.0; 6];
        pose_features(&s, &s.bind_pose(), UpAxis::Y, &mut f).unwrap();
        assert!(f.iter().all(|v| v.abs() < 1e-6), "{f:?}");
    }

    #[test]
    fn heading_and_translation_are_removed_and_bends_are_kept() {
        let s = two_joint();
        let mut pose = s.bind_pose();
        pose.locals[0].rotation = Quat::from_rotation_y(1.1) * pose.locals[0].rotation;
        pose.locals[0].translation += Vec3::new(3.0, 0.0, -2.0);
        pose.locals[1].rotation *= Quat::from_rotation_x(0.7);
        let mut f = [0.0; 6];
        pose_features(&s, &pose, UpAxis::Y, &mut f).unwrap();
        assert!(f[..3].iter().all(|v| v.abs() < 1e-5), "root {f:?}");
        assert!(
            (Vec3::from_slice(&f[3..]) - Vec3::new(0.7, 0.0, 0.0)).length() < 1e-5,
            "{f:?}"
        );
        // A root tilt (about X, not the up axis) is kept.
        pose.locals[0].rotation = Quat::from_rotation_x(0.25) * s.bind_local()[0].rotation;
        pose_features(&s, &pose, UpAxis::Y, &mut f).unwrap();
        assert!(
            (Vec3::from_slice(&f[..3]) - Vec3::new(0.25, 0.0, 0.0)).length() < 1e-5,
            "{f:?}"
        );
    }

    #[test]
    fn errors_on_bad_input() {
        let s = two_joint();
        let mut f = [0.0; 5];
        assert!(matches!(
            pose_features(&s, &s.bind_pose(), UpAxis::Y, &mut f),
            Err(PoseError::OutputLength { .. })
        ));
        let mut pose = s.bind_pose();
        pose.locals[0].rotation = Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0);
        let mut f = [0.0; 6];
        assert!(matches!(
            pose_features(&s, &pose, UpAxis::Y, &mut f),
            Err(PoseError::Skeleton(_))
        ));
    }
}
