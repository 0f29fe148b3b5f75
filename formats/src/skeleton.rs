//! Kinematic skeleton: joints in topological order, bind-pose local transforms, inverse bind
//! matrices and per-joint degrees of freedom; forward kinematics into caller buffers.

use alloc::string::String;
use alloc::vec::Vec;

use glam::{Mat4, Quat, Vec3};

use crate::math::{Transform, rotvec_to_quat};
use crate::pose::Pose;

/// Largest joint count any reader or constructor accepts (a cap against hostile headers).
pub const MAX_JOINTS: usize = 1024;

/// A coordinate axis of a joint's local frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// Local X.
    X,
    /// Local Y.
    Y,
    /// Local Z.
    Z,
}

impl Axis {
    /// Unit vector of the axis.
    #[must_use]
    pub fn unit(self) -> Vec3 {
        match self {
            Axis::X => Vec3::X,
            Axis::Y => Vec3::Y,
            Axis::Z => Vec3::Z,
        }
    }
}

/// How a joint's local rotation is parameterised by joint angles (DeepCap/BVH style).
#[derive(Clone, Debug, PartialEq)]
pub enum JointDofs {
    /// Any rotation, parameterised by a rotation vector (3 angles).
    Free,
    /// Rotations about up to three named local axes, applied as `R(a₀)·R(a₁)·R(a₂)` (the
    /// order the axes are listed in, like BVH channels), each angle within `[min, max]` radians.
    Euler {
        /// Axes in application order (1 to 3 of them).
        axes: Vec<Axis>,
        /// Joint limits per axis, `[min, max]` in radians.
        limits: Vec<[f32; 2]>,
    },
    /// No rotational freedom (the joint keeps its bind rotation).
    Fixed,
}

impl JointDofs {
    /// Number of joint angles this joint consumes.
    #[must_use]
    pub fn count(&self) -> usize {
        match self {
            JointDofs::Free => 3,
            JointDofs::Euler { axes, .. } => axes.len(),
            JointDofs::Fixed => 0,
        }
    }

    /// Rotation relative to the bind rotation for the given angles (`angles.len() == count()`).
    #[must_use]
    pub fn rotation(&self, angles: &[f32]) -> Quat {
        match self {
            JointDofs::Free => rotvec_to_quat(Vec3::new(angles[0], angles[1], angles[2])),
            JointDofs::Euler { axes, .. } => {
                axes.iter().zip(angles).fold(Quat::IDENTITY, |q, (a, &t)| {
                    q * Quat::from_axis_angle(a.unit(), t)
                })
            }
            JointDofs::Fixed => Quat::IDENTITY,
        }
    }
}

/// Why a skeleton or a pose does not fit together.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SkeletonError {
    /// The skeleton has no joints.
    #[error("skeleton has no joints")]
    Empty,
    /// More joints than [`MAX_JOINTS`].
    #[error("skeleton has {0} joints, more than the cap of {MAX_JOINTS}")]
    TooManyJoints(usize),
    /// A per-joint array has a different length than `names`.
    #[error("skeleton field `{field}` has {len} entries, expected {expected}")]
    LengthMismatch {
        /// The offending field.
        field: &'static str,
        /// Its length.
        len: usize,
        /// The joint count.
        expected: usize,
    },
    /// A parent index is not smaller than its child's (not topological) or out of range.
    #[error("joint {joint} has parent {parent}: parents must come before their children")]
    BadParent {
        /// The child joint.
        joint: usize,
        /// Its parent index.
        parent: usize,
    },
    /// A transform or matrix holds NaN or infinity.
    #[error("joint {joint} has a non-finite `{field}`")]
    NonFinite {
        /// The joint.
        joint: usize,
        /// The field.
        field: &'static str,
    },
    /// Two joints share a name.
    #[error("joint name `{0}` appears twice")]
    DuplicateName(String),
    /// An Euler joint lists no axes, more than three, or limits of another length.
    #[error("joint {0} has invalid Euler degrees of freedom")]
    BadDofs(usize),
}

/// A kinematic skeleton.
///
/// Joint `j`'s world transform is `base · L(root) · … · L(parent(j)) · L(j)`; its skinning
/// matrix is `world(j) · inverse_bind(j)`, as in glTF. `bind_local` is the pose the mesh was
/// bound in (for glTF derived from the inverse bind matrices, not from the nodes' TRS).
#[derive(Clone, Debug, PartialEq)]
pub struct Skeleton {
    names: Vec<String>,
    parents: Vec<Option<usize>>,
    bind_local: Vec<Transform>,
    inverse_bind: Vec<Mat4>,
    dofs: Vec<JointDofs>,
    base: Mat4,
}

impl Skeleton {
    /// Builds and validates a skeleton; `inverse_bind` defaults to the inverse of the bind
    /// pose's world matrices and `dofs` to [`JointDofs::Free`] when `None`.
    pub fn new(
        names: Vec<String>,
        parents: Vec<Option<usize>>,
        bind_local: Vec<Transform>,
        inverse_bind: Option<Vec<Mat4>>,
        dofs: Option<Vec<JointDofs>>,
        base: Mat4,
    ) -> Result<Self, SkeletonError> {
        let n = names.len();
        if n == 0 {
            return Err(SkeletonError::Empty);
        }
        if n > MAX_JOINTS {
            return Err(SkeletonError::TooManyJoints(n));
        }
        let check = |field, len| {
            if len == n {
                Ok(())
            } else {
                Err(SkeletonError::LengthMismatch {
                    field,
                    len,
                    expected: n,
                })
            }
        };
        check("parents", parents.len())?;
        check("bind_local", bind_local.len())?;
        for (j, p) in parents.iter().enumerate() {
            if let Some(p) = *p
                && p >= j
            {
                return Err(SkeletonError::BadParent {
                    joint: j,
                    parent: p,
                });
            }
        }
        for (j, t) in bind_local.iter().enumerate() {
            if !t.is_finite() {
                return Err(SkeletonError::NonFinite {
                    joint: j,
                    field: "bind_local",
                });
            }
        }
        if !base.is_finite() {
            return Err(SkeletonError::NonFinite {
                joint: 0,
                field: "base",
            });
        }
        for (i, a) in names.iter().enumerate() {
            if names[..i].contains(a) {
                return Err(SkeletonError::DuplicateName(a.clone()));
            }
        }
        let dofs = dofs.unwrap_or_else(|| alloc::vec![JointDofs::Free; n]);
        check("dofs", dofs.len())?;
        for (j, d) in dofs.iter().enumerate() {
            if let JointDofs::Euler { axes, limits } = d
                && (axes.is_empty() || axes.len() > 3 || limits.len() != axes.len())
            {
                return Err(SkeletonError::BadDofs(j));
            }
        }
        let mut skeleton = Self {
            names,
            parents,
            bind_local,
            inverse_bind: Vec::new(),
            dofs,
            base,
        };
        let inverse_bind = match inverse_bind {
            Some(ibm) => {
                check("inverse_bind", ibm.len())?;
                ibm
            }
            None => {
                let mut world = alloc::vec![Mat4::IDENTITY; n];
                skeleton.world_matrices_of(&skeleton.bind_local, &mut world);
                world.iter().map(Mat4::inverse).collect()
            }
        };
        for (j, m) in inverse_bind.iter().enumerate() {
            if !m.is_finite() {
                return Err(SkeletonError::NonFinite {
                    joint: j,
                    field: "inverse_bind",
                });
            }
        }
        skeleton.inverse_bind = inverse_bind;
        Ok(skeleton)
    }

    /// Number of joints.
    #[must_use]
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// Always false: a skeleton has at least one joint.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Joint names, in joint order.
    #[must_use]
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Index of the joint called `name`.
    #[must_use]
    pub fn find(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Parent of each joint (`None` for roots).
    #[must_use]
    pub fn parents(&self) -> &[Option<usize>] {
        &self.parents
    }

    /// Bind-pose local transforms.
    #[must_use]
    pub fn bind_local(&self) -> &[Transform] {
        &self.bind_local
    }

    /// Inverse bind matrices (world to joint space in the bind pose).
    #[must_use]
    pub fn inverse_bind(&self) -> &[Mat4] {
        &self.inverse_bind
    }

    /// Per-joint degrees of freedom.
    #[must_use]
    pub fn dofs(&self) -> &[JointDofs] {
        &self.dofs
    }

    /// Replaces the degrees of freedom (same validation as [`Skeleton::new`]).
    pub fn set_dofs(&mut self, dofs: Vec<JointDofs>) -> Result<(), SkeletonError> {
        let checked = Self::new(
            self.names.clone(),
            self.parents.clone(),
            self.bind_local.clone(),
            Some(self.inverse_bind.clone()),
            Some(dofs),
            self.base,
        )?;
        *self = checked;
        Ok(())
    }

    /// The fixed transform above every root (the ancestors of the skeleton in its file).
    #[must_use]
    pub fn base(&self) -> Mat4 {
        self.base
    }

    /// Total number of joint angles over all joints.
    #[must_use]
    pub fn angle_count(&self) -> usize {
        self.dofs.iter().map(JointDofs::count).sum()
    }

    /// Children of `joint`, in joint order.
    pub fn children(&self, joint: usize) -> impl Iterator<Item = usize> + '_ {
        self.parents
            .iter()
            .enumerate()
            .filter(move |(_, p)| **p == Some(joint))
            .map(|(c, _)| c)
    }

    /// The bind pose as a [`Pose`].
    #[must_use]
    pub fn bind_pose(&self) -> Pose {
        Pose {
            locals: self.bind_local.clone(),
        }
    }

    /// A pose from joint angles: each joint's rotation is its bind rotation times
    /// [`JointDofs::rotation`]; roots additionally get `root_rotation` (applied before the
    /// bind rotation, in the parent frame) and `root_translation` (added to the bind translation).
    pub fn pose_from_angles(
        &self,
        root_rotation: Quat,
        root_translation: Vec3,
        angles: &[f32],
    ) -> Result<Pose, SkeletonError> {
        if angles.len() != self.angle_count() {
            return Err(SkeletonError::LengthMismatch {
                field: "angles",
                len: angles.len(),
                expected: self.angle_count(),
            });
        }
        let mut locals = self.bind_local.clone();
        let mut k = 0;
        for (j, local) in locals.iter_mut().enumerate() {
            let c = self.dofs[j].count();
            let r = self.dofs[j].rotation(&angles[k..k + c]);
            k += c;
            local.rotation = (local.rotation * r).normalize();
            if self.parents[j].is_none() {
                local.rotation = (root_rotation * local.rotation).normalize();
                local.translation += root_translation;
            }
        }
        Ok(Pose { locals })
    }

    fn world_matrices_of(&self, locals: &[Transform], out: &mut [Mat4]) {
        for j in 0..self.names.len() {
            let local = locals[j].to_mat4();
            out[j] = match self.parents[j] {
                Some(p) => out[p] * local,
                None => self.base * local,
            };
        }
    }

    /// Forward kinematics: world matrix of every joint into `out` (length = joint count).
    pub fn world_matrices(&self, pose: &Pose, out: &mut [Mat4]) -> Result<(), SkeletonError> {
        self.check_pose(pose)?;
        if out.len() != self.len() {
            return Err(SkeletonError::LengthMismatch {
                field: "out",
                len: out.len(),
                expected: self.len(),
            });
        }
        self.world_matrices_of(&pose.locals, out);
        Ok(())
    }

    /// Skinning matrices `world(j) · inverse_bind(j)` into `out` (length = joint count).
    pub fn skinning_matrices(&self, pose: &Pose, out: &mut [Mat4]) -> Result<(), SkeletonError> {
        self.world_matrices(pose, out)?;
        for (m, ibm) in out.iter_mut().zip(&self.inverse_bind) {
            *m *= *ibm;
        }
        Ok(())
    }

    /// Checks that `pose` has one finite transform per joint.
    pub fn check_pose(&self, pose: &Pose) -> Result<(), SkeletonError> {
        if pose.locals.len() != self.len() {
            return Err(SkeletonError::LengthMismatch {
                field: "pose.locals",
                len: pose.locals.len(),
                expected: self.len(),
            });
        }
        for (j, t) in pose.locals.iter().enumerate() {
            if !t.is_finite() {
                return Err(SkeletonError::NonFinite {
                    joint: j,
                    field: "pose.locals",
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString;
    use alloc::vec;

    fn chain() -> Skeleton {
        Skeleton::new(
            vec!["root".to_string(), "mid".to_string(), "tip".to_string()],
            vec![None, Some(0), Some(1)],
            vec![
                Transform::from_translation(Vec3::new(0.0, 1.0, 0.0)),
                Transform::from_translation(Vec3::new(0.0, 0.5, 0.0)),
                Transform::from_translation(Vec3::new(0.0, 0.5, 0.0)),
            ],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn bind_pose_skinning_matrices_are_identity() {
        let s = chain();
        let mut m = vec![Mat4::ZERO; 3];
        s.skinning_matrices(&s.bind_pose(), &mut m).unwrap();
        for m in m {
            assert!(m.abs_diff_eq(Mat4::IDENTITY, 1e-6));
        }
    }

    #[test]
    fn bent_elbow_moves_tip_analytically() {
        let s = chain();
        let mut angles = vec![0.0; 9];
        angles[5] = core::f32::consts::FRAC_PI_2; // mid: rotation vector about Z
        let pose = s
            .pose_from_angles(Quat::IDENTITY, Vec3::ZERO, &angles)
            .unwrap();
        let mut w = vec![Mat4::ZERO; 3];
        s.world_matrices(&pose, &mut w).unwrap();
        // tip is 0.5 above mid; a +90° turn about Z sends +Y to -X.
        let tip = w[2].transform_point3(Vec3::ZERO);
        assert!((tip - Vec3::new(-0.5, 1.5, 0.0)).length() < 1e-5, "{tip}");
    }

    #[test]
    fn rejects_every_invalid_configuration() {
        let t = Transform::IDENTITY;
        let n = |k: usize| (0..k).map(|i| i.to_string()).collect::<Vec<_>>();
        let e = Skeleton::new(vec![], vec![], vec![], None, None, Mat4::IDENTITY);
        assert_eq!(e, Err(SkeletonError::Empty));
        let e = Skeleton::new(n(2), vec![None], vec![t; 2], None, None, Mat4::IDENTITY);
        assert!(matches!(
            e,
            Err(SkeletonError::LengthMismatch {
                field: "parents",
                ..
            })
        ));
        let e = Skeleton::new(
            n(2),
            vec![Some(1), None],
            vec![t; 2],
            None,
            None,
            Mat4::IDENTITY,
        );
        assert!(matches!(
            e,
            Err(SkeletonError::BadParent {
                joint: 0,
                parent: 1
            })
        ));
        let mut bad = t;
        bad.translation.x = f32::NAN;
        let e = Skeleton::new(n(1), vec![None], vec![bad], None, None, Mat4::IDENTITY);
        assert!(matches!(
            e,
            Err(SkeletonError::NonFinite {
                field: "bind_local",
                ..
            })
        ));
        let e = Skeleton::new(
            vec!["a".into(), "a".into()],
            vec![None, Some(0)],
            vec![t; 2],
            None,
            None,
            Mat4::IDENTITY,
        );
        assert!(matches!(e, Err(SkeletonError::DuplicateName(_))));
        let e = Skeleton::new(
            n(1),
            vec![None],
            vec![t],
            Some(vec![]),
            None,
            Mat4::IDENTITY,
        );
        assert!(matches!(
            e,
            Err(SkeletonError::LengthMismatch {
                field: "inverse_bind",
                ..
            })
        ));
        let e = Skeleton::new(
            n(1),
            vec![None],
            vec![t],
            Some(vec![Mat4::NAN]),
            None,
            Mat4::IDENTITY,
        );
        assert!(matches!(
            e,
            Err(SkeletonError::NonFinite {
                field: "inverse_bind",
                ..
            })
        ));
        let bad_dofs = vec![JointDofs::Euler {
            axes: vec![],
            limits: vec![],
        }];
        let e = Skeleton::new(
            n(1),
            vec![None],
            vec![t],
            None,
            Some(bad_dofs),
            Mat4::IDENTITY,
        );
        assert_eq!(e, Err(SkeletonError::BadDofs(0)));
        let e = Skeleton::new(
            n(MAX_JOINTS + 1),
            vec![None; MAX_JOINTS + 1],
            vec![t; MAX_JOINTS + 1],
            None,
            None,
            Mat4::IDENTITY,
        );
        assert!(matches!(e, Err(SkeletonError::TooManyJoints(_))));
        let s = chain();
        let mut pose = s.bind_pose();
        pose.locals[1].rotation.x = f32::NAN;
        let mut out = vec![Mat4::ZERO; 3];
        assert!(matches!(
            s.world_matrices(&pose, &mut out),
            Err(SkeletonError::NonFinite { joint: 1, .. })
        ));
        pose.locals.pop();
        assert!(matches!(
            s.world_matrices(&pose, &mut out),
            Err(SkeletonError::LengthMismatch { .. })
        ));
        assert!(
            s.pose_from_angles(Quat::IDENTITY, Vec3::ZERO, &[0.0])
                .is_err()
        );
    }
}
