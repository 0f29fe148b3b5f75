//! Joint mapping by name: an engine's skeleton (its joint names, in its own order) mapped onto a
//! model's joints once at load time, so that per frame the engine passes its own local
//! transforms, in its own order, and the runtime picks the model's joints without allocating.
//!
//! Engines rarely store joints in the order of the file the character was trained from: an
//! importer reorders them, adds helper joints (twist, IK targets, sockets) or keeps several
//! characters in one array. Matching by name is what every engine's retargeting does, and a
//! name is the one thing the `.skf` keeps for each joint. Matching is exact (case and
//! namespace prefixes included): a silent fuzzy match would animate the wrong limb.

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;

use glam::{Mat3, Mat4, Vec3};
use skinfield_formats::{Pose, Skeleton, Transform};

use crate::error::RuntimeError;

/// How many missing names [`RuntimeError::MissingJoints`] spells out (the count is exact).
const MISSING_NAMES_SHOWN: usize = 8;

/// The transform from an engine's bind space to a model's canonical space
/// ([`JointMap::bind_space`]), applied to a mesh's rest positions and normals at load time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BindSpace {
    to_model: Mat4,
    /// Inverse transpose of the linear part, for normals.
    normal: Mat3,
}

impl BindSpace {
    fn new(to_model: Mat4) -> Self {
        Self {
            to_model,
            normal: Mat3::from_mat4(to_model).inverse().transpose(),
        }
    }

    /// The transform itself.
    #[must_use]
    pub fn matrix(&self) -> Mat4 {
        self.to_model
    }

    /// Rest positions in the model's canonical space (what [`crate::BoundMesh::bind`] takes).
    #[must_use]
    pub fn positions(&self, positions: &[Vec3]) -> Vec<Vec3> {
        positions
            .iter()
            .map(|&p| self.to_model.transform_point3(p))
            .collect()
    }

    /// The inverse transpose of the transform's linear part, which carries normals (renormalise
    /// after it) and, for tangents, the matrix's linear part itself.
    #[must_use]
    pub fn normal_matrix(&self) -> Mat3 {
        self.normal
    }

    /// Rest normals in the model's canonical space (unit length; zero stays zero).
    #[must_use]
    pub fn normals(&self, normals: &[Vec3]) -> Vec<Vec3> {
        normals
            .iter()
            .map(|&n| (self.normal * n).normalize_or_zero())
            .collect()
    }
}

/// For every model joint, the index of the engine joint of the same name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JointMap {
    engine_of_model: Vec<usize>,
    engine_joint_count: usize,
}

impl JointMap {
    /// Maps `engine_names` (the engine skeleton's joints, in the engine's order) onto
    /// `model`'s joints. Engine joints the model does not have are ignored; every model joint
    /// must be named exactly once. Allocates; call it at load time.
    pub fn new<S: AsRef<str>>(model: &Skeleton, engine_names: &[S]) -> Result<Self, RuntimeError> {
        // Sorted (name, index) pairs find duplicates and look names up in O(n log n), without
        // a hash map (which `no_std` lacks).
        let mut sorted: Vec<(&str, usize)> = engine_names
            .iter()
            .enumerate()
            .map(|(i, n)| (n.as_ref(), i))
            .collect();
        sorted.sort_unstable();
        if let Some(w) = sorted.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(RuntimeError::DuplicateJoint {
                name: String::from(w[0].0),
                first: w[0].1,
                second: w[1].1,
            });
        }
        let mut engine_of_model = Vec::with_capacity(model.len());
        let mut missing: Vec<&str> = Vec::new();
        for name in model.names() {
            match sorted.binary_search_by(|(n, _)| (*n).cmp(name.as_str())) {
                Ok(k) => engine_of_model.push(sorted[k].1),
                Err(_) => missing.push(name),
            }
        }
        if !missing.is_empty() {
            let mut names = missing
                .iter()
                .take(MISSING_NAMES_SHOWN)
                .map(|n| format!("`{n}`"))
                .collect::<Vec<_>>()
                .join(", ");
            if missing.len() > MISSING_NAMES_SHOWN {
                names.push_str(", …");
            }
            return Err(RuntimeError::MissingJoints {
                count: missing.len(),
                names,
            });
        }
        Ok(Self {
            engine_of_model,
            engine_joint_count: engine_names.len(),
        })
    }

    /// The identity map of a skeleton onto itself (the engine uses the model's order).
    #[must_use]
    pub fn identity(model: &Skeleton) -> Self {
        Self {
            engine_of_model: (0..model.len()).collect(),
            engine_joint_count: model.len(),
        }
    }

    /// Checks that the hierarchies agree on the mapped joints: each model joint's parent maps
    /// to its engine joint's parent (`engine_parents[i]` is the parent of engine joint `i`).
    /// Local transforms only mean the same thing when they do: an engine helper joint inserted
    /// between two model joints would otherwise be silently skipped.
    pub fn check_parents<S: AsRef<str>>(
        &self,
        model: &Skeleton,
        engine_names: &[S],
        engine_parents: &[Option<usize>],
    ) -> Result<(), RuntimeError> {
        self.check_model(model)?;
        for (field, len) in [
            ("engine_names", engine_names.len()),
            ("engine_parents", engine_parents.len()),
        ] {
            if len != self.engine_joint_count {
                return Err(RuntimeError::BufferLength {
                    field,
                    len,
                    expected: self.engine_joint_count,
                });
            }
        }
        let engine_name = |p: Option<usize>| match p {
            Some(p) => engine_names
                .get(p)
                .map_or_else(|| format!("#{p}"), |n| format!("`{}`", n.as_ref())),
            None => String::from("none"),
        };
        for (j, &e) in self.engine_of_model.iter().enumerate() {
            let expected = model.parents()[j].map(|p| self.engine_of_model[p]);
            let found = engine_parents[e];
            if found != expected {
                return Err(RuntimeError::ParentMismatch {
                    name: model.names()[j].clone(),
                    model_parent: model.parents()[j].map_or_else(
                        || String::from("none"),
                        |p| format!("`{}`", model.names()[p]),
                    ),
                    engine_parent: engine_name(found),
                });
            }
        }
        Ok(())
    }

    /// Number of model joints.
    #[must_use]
    pub fn model_joint_count(&self) -> usize {
        self.engine_of_model.len()
    }

    /// Number of engine joints the per-frame transforms must have.
    #[must_use]
    pub fn engine_joint_count(&self) -> usize {
        self.engine_joint_count
    }

    /// The engine index of each model joint.
    #[must_use]
    pub fn engine_of_model(&self) -> &[usize] {
        &self.engine_of_model
    }

    /// Writes the model pose from the engine's local transforms (engine order) into `pose`
    /// (which holds one local per model joint, e.g. from [`Skeleton::bind_pose`]). Never
    /// allocates; NaN or infinite transforms of mapped joints are errors (unmapped joints are
    /// not read).
    pub fn pose_into(
        &self,
        engine_locals: &[Transform],
        pose: &mut Pose,
    ) -> Result<(), RuntimeError> {
        if engine_locals.len() != self.engine_joint_count {
            return Err(RuntimeError::BufferLength {
                field: "engine_locals",
                len: engine_locals.len(),
                expected: self.engine_joint_count,
            });
        }
        if pose.locals.len() != self.engine_of_model.len() {
            return Err(RuntimeError::BufferLength {
                field: "pose",
                len: pose.locals.len(),
                expected: self.engine_of_model.len(),
            });
        }
        if let Some(&e) = self
            .engine_of_model
            .iter()
            .find(|&&e| !engine_locals[e].is_finite())
        {
            return Err(RuntimeError::NonFinite {
                field: "engine_locals",
                index: e,
            });
        }
        for (dst, &e) in pose.locals.iter_mut().zip(&self.engine_of_model) {
            *dst = engine_locals[e];
        }
        Ok(())
    }

    /// The transform from the engine's bind space (where its mesh's rest positions live) to
    /// the model's canonical space (where [`crate::BoundMesh::bind`] wants them), from both
    /// skeletons' inverse bind matrices (`engine_inverse_binds[i]` of engine joint `i`):
    /// `M = IBM_model⁻¹ · IBM_engine`, the same for every mapped joint when the two bind poses
    /// agree up to one transform. Importers and trainers may re-express the bind space (a
    /// character whose armature node scales or turns it), so an engine binds `M · x`, not `x`.
    /// Refuses (naming the joint) when some joint's `M` differs from the root's by more than
    /// `tolerance` relative to the matrices' size: then the bind poses differ and positions
    /// alone cannot fix it.
    pub fn bind_space(
        &self,
        model: &Skeleton,
        engine_inverse_binds: &[Mat4],
        tolerance: f32,
    ) -> Result<BindSpace, RuntimeError> {
        self.check_model(model)?;
        if engine_inverse_binds.len() != self.engine_joint_count {
            return Err(RuntimeError::BufferLength {
                field: "engine_inverse_binds",
                len: engine_inverse_binds.len(),
                expected: self.engine_joint_count,
            });
        }
        let estimate = |j: usize| -> Result<Mat4, RuntimeError> {
            let e = self.engine_of_model[j];
            let m = model.inverse_bind()[j].inverse() * engine_inverse_binds[e];
            if m.is_finite() {
                Ok(m)
            } else {
                Err(RuntimeError::NonFinite {
                    field: "engine_inverse_binds",
                    index: e,
                })
            }
        };
        let reference = estimate(0)?;
        let size = reference
            .to_cols_array()
            .iter()
            .fold(0.0f32, |a, b| a.max(b.abs()));
        for j in 1..self.engine_of_model.len() {
            let m = estimate(j)?;
            let diff = (m - reference)
                .to_cols_array()
                .iter()
                .fold(0.0f32, |a, b| a.max(b.abs()));
            // Written so that a NaN tolerance refuses too.
            let within = diff <= tolerance * size;
            if !within {
                return Err(RuntimeError::BindMismatch {
                    name: model.names()[j].clone(),
                    difference: diff / size,
                });
            }
        }
        Ok(BindSpace::new(reference))
    }

    fn check_model(&self, model: &Skeleton) -> Result<(), RuntimeError> {
        if model.len() != self.engine_of_model.len() {
            return Err(RuntimeError::BufferLength {
                field: "skeleton",
                len: model.len(),
                expected: self.engine_of_model.len(),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;
    use glam::{Quat, Vec3};

    /// root → spine → head, root → leg.
    fn model() -> Skeleton {
        let names = ["root", "spine", "head", "leg"].map(String::from).to_vec();
        let parents = vec![None, Some(0), Some(1), Some(0)];
        let bind = (0..4)
            .map(|i| Transform::from_translation(Vec3::new(0.0, i as f32 * 0.1, 0.0)))
            .collect();
        Skeleton::new(names, parents, bind, None, None, Mat4::IDENTITY).unwrap()
    }

    fn rotated(i: usize) -> Transform {
        Transform::from_rotation_translation(
            Quat::from_rotation_z(i as f32 * 0.1),
            Vec3::splat(i as f32),
        )
    }

    #[test]
    fn engine_order_and_extra_joints_map_to_the_model_order() {
        let engine = ["ik_target", "leg", "head", "spine", "root", "socket"];
        let map = JointMap::new(&model(), &engine).unwrap();
        assert_eq!(map.engine_of_model(), &[4, 3, 2, 1]);
        let locals: Vec<Transform> = (0..engine.len()).map(rotated).collect();
        let mut pose = model().bind_pose();
        map.pose_into(&locals, &mut pose).unwrap();
        assert_eq!(
            pose.locals,
            vec![rotated(4), rotated(3), rotated(2), rotated(1)]
        );
        let parents = [None, Some(4), Some(3), Some(4), None, Some(2)];
        map.check_parents(&model(), &engine, &parents).unwrap();
    }

    #[test]
    fn missing_duplicate_and_reparented_joints_are_named() {
        let e = JointMap::new(&model(), &["root", "head"]).unwrap_err();
        assert_eq!(
            e,
            RuntimeError::MissingJoints {
                count: 2,
                names: String::from("`spine`, `leg`"),
            }
        );
        let e = JointMap::new(&model(), &["root", "spine", "head", "leg", "spine"]).unwrap_err();
        assert_eq!(
            e,
            RuntimeError::DuplicateJoint {
                name: String::from("spine"),
                first: 1,
                second: 4,
            }
        );
        let engine = ["root", "spine", "twist", "head", "leg"];
        let map = JointMap::new(&model(), &engine).unwrap();
        // A twist joint between spine and head: head's engine parent is `twist`.
        let parents = [None, Some(0), Some(1), Some(2), Some(0)];
        let e = map.check_parents(&model(), &engine, &parents).unwrap_err();
        assert_eq!(
            e,
            RuntimeError::ParentMismatch {
                name: String::from("head"),
                model_parent: String::from("`spine`"),
                engine_parent: String::from("`twist`"),
            }
        );
    }

    #[test]
    fn bad_frames_are_refused_without_touching_the_pose() {
        let engine = ["leg", "root", "spine", "head", "unused"];
        let map = JointMap::new(&model(), &engine).unwrap();
        let mut pose = model().bind_pose();
        let before = pose.clone();
        let mut locals: Vec<Transform> = (0..5).map(rotated).collect();
        assert!(matches!(
            map.pose_into(&locals[..4], &mut pose),
            Err(RuntimeError::BufferLength {
                field: "engine_locals",
                len: 4,
                expected: 5
            })
        ));
        locals[2].rotation = Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0);
        assert_eq!(
            map.pose_into(&locals, &mut pose),
            Err(RuntimeError::NonFinite {
                field: "engine_locals",
                index: 2
            })
        );
        assert_eq!(pose, before);
        // An unmapped joint may hold anything.
        locals[2] = rotated(2);
        locals[4].translation = Vec3::NAN;
        map.pose_into(&locals, &mut pose).unwrap();
        let mut short = Pose {
            locals: vec![Transform::default(); 3],
        };
        assert!(matches!(
            map.pose_into(&locals, &mut short),
            Err(RuntimeError::BufferLength { field: "pose", .. })
        ));
    }
}

#[cfg(test)]
mod bind_space_tests {
    use super::*;
    use alloc::vec;
    use glam::{Quat, Vec3};

    fn chain(base: Mat4) -> Skeleton {
        let names = ["hips", "spine", "arm"].map(String::from).to_vec();
        let bind = vec![
            Transform::from_rotation_translation(Quat::from_rotation_y(0.4), Vec3::Y),
            Transform::from_translation(Vec3::new(0.0, 0.3, 0.1)),
            Transform::from_rotation_translation(Quat::from_rotation_z(1.0), Vec3::X * 0.2),
        ];
        Skeleton::new(names, vec![None, Some(0), Some(1)], bind, None, None, base).unwrap()
    }

    #[test]
    fn a_bind_space_turned_and_scaled_by_the_importer_is_recovered() {
        // The engine's skeleton sits under an armature node that turns Z-up into Y-up and
        // scales by 100; the model's does not. Engine order: arm, hips, spine.
        let armature = Mat4::from_scale_rotation_translation(
            Vec3::splat(100.0),
            Quat::from_rotation_x(-core::f32::consts::FRAC_PI_2),
            Vec3::new(0.5, 0.0, 0.0),
        );
        let model = chain(Mat4::IDENTITY);
        let engine = chain(armature);
        let order = [2, 0, 1];
        let names: Vec<&str> = order.iter().map(|&j| engine.names()[j].as_str()).collect();
        let ibms: Vec<Mat4> = order.iter().map(|&j| engine.inverse_bind()[j]).collect();
        let map = JointMap::new(&model, &names).unwrap();
        let space = map.bind_space(&model, &ibms, 1e-4).unwrap();
        // A point of the engine's bind space lands where the model's bind pose has it, and a
        // normal turns with the rotation only.
        let x = Vec3::new(1.0, 2.0, 3.0);
        let want = armature.inverse().transform_point3(x);
        assert!(space.positions(&[x])[0].distance(want) < 1e-5 * want.length());
        let n = space.normals(&[Vec3::Y])[0];
        assert!(n.distance(armature.inverse().transform_vector3(Vec3::Y).normalize()) < 1e-5);

        // A joint bent differently in the engine's bind pose is named.
        let mut bent = ibms.clone();
        bent[0] = Mat4::from_rotation_z(0.3) * bent[0];
        assert!(matches!(
            map.bind_space(&model, &bent, 1e-4),
            Err(RuntimeError::BindMismatch { name, .. }) if name == "arm"
        ));
        assert!(matches!(
            map.bind_space(&model, &ibms[..2], 1e-4),
            Err(RuntimeError::BufferLength {
                field: "engine_inverse_binds",
                ..
            })
        ));
    }
}
