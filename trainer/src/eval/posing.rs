//! Posing a template for evaluation with the runtime's own jobs, so the benchmark scores what
//! ships: static weights (bone heat, the learned baseline, the oracle rows, the fitted bounds)
//! through `StaticSkinJob` under LBS or DQS, SkinNet through `BoundMesh` + `FrameState` +
//! `SkinJob`, as an engine runs them.
//!
//! The synthetic capture's ground-truth deformer (`synth::deform`) stays a separate
//! implementation, so an `oracle` row still compares the runtime's skinning of the true weights
//! with another code path.

use glam::Vec3;
use skinfield_formats::{Pose, Skeleton, SkinError, StaticSkin};
use skinfield_runtime::{
    BoundMesh, FrameState, Method, Palette, RuntimeError, Scratch, SkinJob, SkinNetModel,
    StaticSkinJob, WeightsJob,
};

/// How static weights blend the joint transforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Blend {
    /// Linear blend skinning.
    Linear,
    /// Dual-quaternion skinning.
    DualQuaternion,
}

impl From<Method> for Blend {
    fn from(m: Method) -> Self {
        match m {
            Method::Lbs => Blend::Linear,
            Method::Dqs => Blend::DualQuaternion,
        }
    }
}

impl From<Blend> for Method {
    fn from(b: Blend) -> Self {
        match b {
            Blend::Linear => Method::Lbs,
            Blend::DualQuaternion => Method::Dqs,
        }
    }
}

/// Why a mesh could not be posed.
#[derive(Debug, thiserror::Error)]
pub enum PosingError {
    /// The runtime refused the pose, the mesh or the model.
    #[error("runtime: {0}")]
    Runtime(#[from] RuntimeError),
    /// Dense weights are not a valid skin (negative, NaN or an all-zero row).
    #[error("weights: {0}")]
    Weights(#[from] SkinError),
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

/// Poses `rest` (canonical positions) with static weights under `blend` (the runtime's
/// `StaticSkinJob`).
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
    let mut palette = Palette::new(skeleton.len());
    palette.set_pose(skeleton, pose)?;
    let mut out = vec![Vec3::ZERO; rest.len()];
    StaticSkinJob {
        skin,
        palette: &palette,
        method: blend.into(),
        first_vertex: 0,
        rest_positions: rest,
        rest_normals: None,
        rest_tangents: None,
        out_positions: &mut out,
        out_normals: None,
        out_tangents: None,
    }
    .run()?;
    Ok(out)
}

/// Poses `rest` with dense per-vertex weights (`rest.len() × skeleton.len()`, row-major, rows
/// summing to one, e.g. the fast path's or a fitted bound's) under linear blend skinning.
pub fn pose_dense_lbs(
    skeleton: &Skeleton,
    weights: &[f32],
    rest: &[Vec3],
    pose: &Pose,
) -> Result<Vec<Vec3>, PosingError> {
    let j = skeleton.len();
    if rest.len().checked_mul(j) != Some(weights.len()) {
        return Err(PosingError::Mismatch {
            weights_vertices: weights.len() / j.max(1),
            weights_joints: j,
            vertices: rest.len(),
            joints: j,
        });
    }
    let skin = StaticSkin::from_dense(weights, j)?;
    pose_static(skeleton, &skin, rest, pose, Blend::Linear)
}

/// Poses `rest` with SkinNet under LBS exactly as an engine does: bind the mesh, pose a frame
/// with the model's own skeleton, run `SkinJob`.
pub fn pose_skinnet(
    model: &SkinNetModel,
    rest: &[Vec3],
    pose: &Pose,
) -> Result<Vec<Vec3>, PosingError> {
    let mesh = BoundMesh::bind(model, rest)?;
    let mut frame = FrameState::new(model);
    frame.set_pose(model, pose)?;
    skin_frame(model, &mesh, &frame, Method::Lbs)
}

/// SkinNet's weights at every point of `rest` for `pose`, as a static skin (the runtime's
/// `WeightsJob`; weights the model's candidate mask zeroes are left out).
pub fn skinnet_weights(
    model: &SkinNetModel,
    rest: &[Vec3],
    pose: &Pose,
) -> Result<StaticSkin, PosingError> {
    let mesh = BoundMesh::bind(model, rest)?;
    let mut frame = FrameState::new(model);
    frame.set_pose(model, pose)?;
    let joints = model.joint_count();
    let mut dense = vec![0.0; rest.len() * joints];
    WeightsJob {
        model,
        mesh: &mesh,
        frame: &frame,
        first_vertex: 0,
        out_weights: &mut dense,
    }
    .run(&mut Scratch::new(model))?;
    Ok(StaticSkin::from_dense(&dense, joints)?)
}

/// Every vertex of a bound mesh skinned with SkinNet for a posed frame (`SkinJob`).
pub fn skin_frame(
    model: &SkinNetModel,
    mesh: &BoundMesh,
    frame: &FrameState,
    method: Method,
) -> Result<Vec<Vec3>, PosingError> {
    let mut out = vec![Vec3::ZERO; mesh.vertex_count()];
    SkinJob {
        model,
        mesh,
        frame,
        method,
        first_vertex: 0,
        rest_normals: None,
        rest_tangents: None,
        out_positions: &mut out,
        out_normals: None,
        out_tangents: None,
        out_weights: None,
    }
    .run(&mut Scratch::new(model))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat};
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
