//! The kinematics layer (DeepCap §3.2) in double precision: joint angles and a root rotation to
//! the world positions of landmarks attached to the skeleton, with the root translation left at
//! zero (the global alignment layer supplies it).
//!
//! It mirrors `Skeleton::pose_from_angles` followed by `Skeleton::world_matrices` (which are
//! f32): each joint's local rotation is its bind rotation times `JointDofs::rotation(angles)`,
//! the root's is pre-multiplied by the root rotation, and world matrices chain from the
//! skeleton's base. The tracker differentiates it by central differences, which f32 would turn
//! into noise.

use glam::{DMat4, DQuat, DVec3, Quat, Vec3};
use skinfield_formats::{JointDofs, Pose, Skeleton, SkeletonError};

/// A 3D point the detector sees: a joint's origin plus an offset in that joint's local frame
/// (DeepCap's face landmarks are offsets from the head joint).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landmark {
    /// Joint index in the skeleton.
    pub joint: usize,
    /// Offset in the joint's local frame (skeleton units).
    pub offset: DVec3,
}

/// The skeleton widened to f64, ready for repeated forward kinematics.
#[derive(Clone, Debug)]
pub struct Kinematics {
    parents: Vec<Option<usize>>,
    dofs: Vec<JointDofs>,
    /// Bind-pose local translation, rotation and scale per joint.
    bind: Vec<(DVec3, DQuat, DVec3)>,
    base: DMat4,
    angle_count: usize,
}

/// Rotation of one joint's degrees of freedom, in f64 (`JointDofs::rotation` widened).
fn dofs_rotation(dofs: &JointDofs, angles: &[f64]) -> DQuat {
    match dofs {
        JointDofs::Free => {
            let v = DVec3::new(angles[0], angles[1], angles[2]);
            rotvec_to_dquat(v)
        }
        JointDofs::Euler { axes, .. } => {
            axes.iter().zip(angles).fold(DQuat::IDENTITY, |q, (a, &t)| {
                q * DQuat::from_axis_angle(a.unit().as_dvec3(), t)
            })
        }
        JointDofs::Fixed => DQuat::IDENTITY,
    }
}

/// The rotation about `v / |v|` by `|v|` radians (identity at zero).
#[must_use]
pub fn rotvec_to_dquat(v: DVec3) -> DQuat {
    let angle = v.length();
    if angle < 1e-300 {
        DQuat::IDENTITY
    } else {
        DQuat::from_axis_angle(v / angle, angle)
    }
}

impl Kinematics {
    /// Widens `skeleton` to f64.
    #[must_use]
    pub fn new(skeleton: &Skeleton) -> Self {
        Self {
            parents: skeleton.parents().to_vec(),
            dofs: skeleton.dofs().to_vec(),
            bind: skeleton
                .bind_local()
                .iter()
                .map(|t| {
                    (
                        t.translation.as_dvec3(),
                        t.rotation.as_dquat(),
                        t.scale.as_dvec3(),
                    )
                })
                .collect(),
            base: skeleton.base().as_dmat4(),
            angle_count: skeleton.angle_count(),
        }
    }

    /// Number of joints.
    #[must_use]
    pub fn joint_count(&self) -> usize {
        self.parents.len()
    }

    /// Number of joint angles (`Skeleton::angle_count`).
    #[must_use]
    pub fn angle_count(&self) -> usize {
        self.angle_count
    }

    /// The degrees of freedom of every joint.
    #[must_use]
    pub fn dofs(&self) -> &[JointDofs] {
        &self.dofs
    }

    /// Joint parents.
    #[must_use]
    pub fn parents(&self) -> &[Option<usize>] {
        &self.parents
    }

    /// World matrix of every joint for a root rotation and joint angles, root translation zero,
    /// into `out` (joint count).
    pub fn world_matrices(&self, root_rotation: DQuat, angles: &[f64], out: &mut [DMat4]) {
        let mut k = 0;
        for j in 0..self.parents.len() {
            let c = self.dofs[j].count();
            let (t, bind_r, s) = self.bind[j];
            let mut r = (bind_r * dofs_rotation(&self.dofs[j], &angles[k..k + c])).normalize();
            k += c;
            if self.parents[j].is_none() {
                r = (root_rotation * r).normalize();
            }
            let local = DMat4::from_scale_rotation_translation(s, r, t);
            out[j] = match self.parents[j] {
                Some(p) => out[p] * local,
                None => self.base * local,
            };
        }
    }

    /// World positions of `landmarks` (root translation zero) into `out`, using `worlds`
    /// (joint count) as scratch.
    pub fn landmarks(
        &self,
        root_rotation: DQuat,
        angles: &[f64],
        landmarks: &[Landmark],
        worlds: &mut [DMat4],
        out: &mut [DVec3],
    ) {
        self.world_matrices(root_rotation, angles, worlds);
        for (o, l) in out.iter_mut().zip(landmarks) {
            *o = worlds[l.joint].transform_point3(l.offset);
        }
    }

    /// The world-space shift of every joint caused by a root translation `t` (the linear part
    /// of the base applied to it); [`Self::root_translation_for`] inverts it.
    #[must_use]
    pub fn world_shift(&self, root_translation: DVec3) -> DVec3 {
        self.base.transform_vector3(root_translation)
    }

    /// The root translation that shifts the skeleton by `world` in world space.
    #[must_use]
    pub fn root_translation_for(&self, world: DVec3) -> DVec3 {
        self.base.inverse().transform_vector3(world)
    }

    /// The [`Pose`] (f32) of a root rotation, a world-space shift and joint angles.
    pub fn pose(
        &self,
        skeleton: &Skeleton,
        root_rotation: DQuat,
        world_shift: DVec3,
        angles: &[f64],
    ) -> Result<Pose, SkeletonError> {
        let a: Vec<f32> = angles.iter().map(|&x| x as f32).collect();
        let t: Vec3 = self.root_translation_for(world_shift).as_vec3();
        let q: Quat = root_rotation.as_quat();
        skeleton.pose_from_angles(q, t, &a)
    }
}
