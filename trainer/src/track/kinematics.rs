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
    /// Calibrated change of each joint's bind-pose local translation (zero for the roots, whose
    /// translation the alignment layer supplies); see [`super::calibration`].
    bone_offsets: Vec<DVec3>,
    /// Per joint, the index of its per-frame translation among the translating joints
    /// ([`Self::with_translating_joints`]).
    translation_slot: Vec<Option<usize>>,
    /// Skeleton units per unit of a translation parameter (10 % of the bind-pose size).
    translation_unit: f64,
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
        let mut kinematics = Self {
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
            bone_offsets: vec![DVec3::ZERO; skeleton.len()],
            translation_slot: vec![None; skeleton.len()],
            translation_unit: 0.0,
        };
        kinematics.translation_unit = 0.1 * kinematics.bind_size();
        kinematics
    }

    /// The layer with a per-frame translation for each of `joints` (non-root joint indices;
    /// the roots' translation is the alignment layer's), for rigs whose animation moves joints
    /// by translation, such as inverse-kinematics feet parented to the root. Each adds three
    /// parameters after the angles ([`Self::param_count`]): the joint's local translation minus
    /// its bind-pose one, in units of 10 % of the skeleton's bind-pose size.
    ///
    /// # Panics
    /// If a joint index is out of range.
    #[must_use]
    pub fn with_translating_joints(mut self, joints: &[usize]) -> Self {
        self.translation_slot = vec![None; self.parents.len()];
        let mut k = 0;
        for &j in joints {
            if self.parents[j].is_some() && self.translation_slot[j].is_none() {
                self.translation_slot[j] = Some(k);
                k += 1;
            }
        }
        self
    }

    /// The joints with a per-frame translation, in parameter order.
    #[must_use]
    pub fn translating_joints(&self) -> Vec<usize> {
        let mut joints: Vec<(usize, usize)> = self
            .translation_slot
            .iter()
            .enumerate()
            .filter_map(|(j, s)| s.map(|s| (s, j)))
            .collect();
        joints.sort_unstable();
        joints.into_iter().map(|(_, j)| j).collect()
    }

    /// Parameters of a pose after the root rotation: the joint angles, then three per
    /// translating joint.
    #[must_use]
    pub fn param_count(&self) -> usize {
        self.angle_count + 3 * self.translation_slot.iter().flatten().count()
    }

    /// The local translation change of translating joint `j` under `params` (zero for the
    /// others).
    fn translation(&self, j: usize, params: &[f64]) -> DVec3 {
        self.translation_slot[j].map_or(DVec3::ZERO, |k| {
            let i = self.angle_count + 3 * k;
            DVec3::from_slice(&params[i..i + 3]) * self.translation_unit
        })
    }

    /// The layer with every joint's bind-pose local translation moved by `offsets` (one per
    /// joint, in the parent's frame, skeleton units): a skeleton calibrated to the detections.
    /// The roots' entries are ignored (the alignment layer places the skeleton).
    ///
    /// # Panics
    /// If `offsets` does not have one entry per joint.
    #[must_use]
    pub fn with_bone_offsets(mut self, offsets: &[DVec3]) -> Self {
        assert_eq!(
            offsets.len(),
            self.parents.len(),
            "one bone offset per joint"
        );
        for ((o, new), parent) in self.bone_offsets.iter_mut().zip(offsets).zip(&self.parents) {
            *o = if parent.is_some() { *new } else { DVec3::ZERO };
        }
        self
    }

    /// Joint `j`'s bind-pose local translation (its bone, in the parent's frame, before any
    /// offset).
    #[must_use]
    pub fn bind_translation(&self, j: usize) -> DVec3 {
        self.bind[j].0
    }

    /// Every joint's calibrated change of its bind-pose local translation (zero unless
    /// [`Self::with_bone_offsets`] set one).
    #[must_use]
    pub fn bone_offsets(&self) -> &[DVec3] {
        &self.bone_offsets
    }

    /// Diagonal of the bounding box of the joints in the bind pose (skeleton units, at least
    /// 1e-9): the scale the calibration's prior is measured in.
    #[must_use]
    pub fn bind_size(&self) -> f64 {
        let mut worlds = vec![DMat4::IDENTITY; self.parents.len()];
        self.world_matrices(DQuat::IDENTITY, &vec![0.0; self.param_count()], &mut worlds);
        let (lo, hi) = worlds.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), w| {
                let p = w.w_axis.truncate();
                (lo.min(p), hi.max(p))
            },
        );
        (hi - lo).length().max(1e-9)
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

    /// World matrix of every joint for a root rotation and joint angles (the
    /// [`Self::param_count`] parameters: angles, then translations), root translation zero, into
    /// `out` (joint count).
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
            let t = t + self.bone_offsets[j] + self.translation(j, angles);
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

    /// The [`Pose`] (f32) of a root rotation, a world-space shift and the pose parameters
    /// ([`Self::param_count`]), with the bone offsets and the translating joints' translations
    /// in the joints' local translations.
    pub fn pose(
        &self,
        skeleton: &Skeleton,
        root_rotation: DQuat,
        world_shift: DVec3,
        angles: &[f64],
    ) -> Result<Pose, SkeletonError> {
        let a: Vec<f32> = angles[..self.angle_count]
            .iter()
            .map(|&x| x as f32)
            .collect();
        let t: Vec3 = self.root_translation_for(world_shift).as_vec3();
        let q: Quat = root_rotation.as_quat();
        let mut pose = skeleton.pose_from_angles(q, t, &a)?;
        for (j, (local, offset)) in pose.locals.iter_mut().zip(&self.bone_offsets).enumerate() {
            local.translation += (*offset + self.translation(j, angles)).as_vec3();
        }
        Ok(pose)
    }
}
