//! The built-in character's skeleton: 24 joints with joint-angle degrees of freedom and limits,
//! bound in a T-pose (+Y up, facing +Z, metres, feet on y = 0, about 1.75 m tall).
//!
//! Every bind-pose local rotation is the identity, so each joint's Euler axes are world axes in
//! the bind pose: the arms lie along ±X (raise = about Z, swing forward = about Y, twist = about
//! X), the legs along −Y (kick forward = negative X rotation, knee bend = positive X rotation).

use glam::{Mat4, Vec3};
use skinfield_formats::{Axis, JointDofs, Skeleton, SkeletonError, Transform};

/// One joint of the built-in character: name, parent, bind position (world) and DOFs.
struct JointSpec {
    name: String,
    parent: Option<usize>,
    position: Vec3,
    dofs: JointDofs,
}

fn euler(axes: &str, limits: &[[f32; 2]]) -> JointDofs {
    let axes = axes
        .chars()
        .map(|c| match c {
            'X' => Axis::X,
            'Y' => Axis::Y,
            _ => Axis::Z,
        })
        .collect();
    JointDofs::Euler {
        axes,
        limits: limits.to_vec(),
    }
}

/// Joint indices of the built-in character, by role.
pub mod joint {
    /// Pelvis (root, free rotation).
    pub const HIPS: usize = 0;
    /// Lower spine.
    pub const SPINE: usize = 1;
    /// Middle spine.
    pub const SPINE1: usize = 2;
    /// Chest.
    pub const CHEST: usize = 3;
    /// Neck.
    pub const NECK: usize = 4;
    /// Head.
    pub const HEAD: usize = 5;
    /// Left clavicle (+X side); the right side's joints follow at `+5`.
    pub const L_CLAVICLE: usize = 6;
    /// Left shoulder.
    pub const L_SHOULDER: usize = 7;
    /// Left elbow (1 DOF).
    pub const L_ELBOW: usize = 8;
    /// Left forearm twist (1 DOF, about the forearm).
    pub const L_FOREARM: usize = 9;
    /// Left wrist.
    pub const L_WRIST: usize = 10;
    /// Right clavicle.
    pub const R_CLAVICLE: usize = 11;
    /// Right shoulder.
    pub const R_SHOULDER: usize = 12;
    /// Right elbow.
    pub const R_ELBOW: usize = 13;
    /// Right forearm twist.
    pub const R_FOREARM: usize = 14;
    /// Right wrist.
    pub const R_WRIST: usize = 15;
    /// Left hip; the right leg's joints follow at `+4`.
    pub const L_HIP: usize = 16;
    /// Left knee (1 DOF).
    pub const L_KNEE: usize = 17;
    /// Left ankle.
    pub const L_ANKLE: usize = 18;
    /// Left toes.
    pub const L_TOE: usize = 19;
    /// Right hip.
    pub const R_HIP: usize = 20;
    /// Right knee.
    pub const R_KNEE: usize = 21;
    /// Right ankle.
    pub const R_ANKLE: usize = 22;
    /// Right toes.
    pub const R_TOE: usize = 23;
    /// Number of joints.
    pub const COUNT: usize = 24;
}

fn specs() -> Vec<JointSpec> {
    let mut v = vec![
        JointSpec {
            name: "hips".into(),
            parent: None,
            position: Vec3::new(0.0, 0.95, 0.0),
            dofs: JointDofs::Free,
        },
        JointSpec {
            name: "spine".into(),
            parent: Some(0),
            position: Vec3::new(0.0, 1.04, -0.01),
            dofs: euler("XYZ", &[[-0.6, 0.9], [-0.5, 0.5], [-0.4, 0.4]]),
        },
        JointSpec {
            name: "spine1".into(),
            parent: Some(1),
            position: Vec3::new(0.0, 1.16, -0.01),
            dofs: euler("XYZ", &[[-0.4, 0.6], [-0.4, 0.4], [-0.3, 0.3]]),
        },
        JointSpec {
            name: "chest".into(),
            parent: Some(2),
            position: Vec3::new(0.0, 1.29, 0.0),
            dofs: euler("XYZ", &[[-0.3, 0.4], [-0.4, 0.4], [-0.3, 0.3]]),
        },
        JointSpec {
            name: "neck".into(),
            parent: Some(3),
            position: Vec3::new(0.0, 1.45, 0.0),
            dofs: euler("XYZ", &[[-0.5, 0.6], [-0.7, 0.7], [-0.4, 0.4]]),
        },
        JointSpec {
            name: "head".into(),
            parent: Some(4),
            position: Vec3::new(0.0, 1.55, 0.01),
            dofs: euler("XYZ", &[[-0.5, 0.5], [-0.6, 0.6], [-0.3, 0.3]]),
        },
    ];
    for (side, s) in [("l", 1.0f32), ("r", -1.0f32)] {
        let base = v.len();
        let name = |n: &str| format!("{side}_{n}");
        // Mirrored limits: for the right arm (along −X) the same motion is the opposite angle.
        let m = |lo: f32, hi: f32| if s > 0.0 { [lo, hi] } else { [-hi, -lo] };
        v.push(JointSpec {
            name: name("clavicle"),
            parent: Some(3),
            position: Vec3::new(0.05 * s, 1.39, 0.0),
            dofs: euler("YZ", &[m(-0.3, 0.3), m(-0.2, 0.4)]),
        });
        v.push(JointSpec {
            name: name("shoulder"),
            parent: Some(base),
            position: Vec3::new(0.17 * s, 1.39, 0.0),
            dofs: euler("ZYX", &[m(-1.4, 1.6), m(-1.6, 0.8), [-1.2, 1.2]]),
        });
        v.push(JointSpec {
            name: name("elbow"),
            parent: Some(base + 1),
            position: Vec3::new(0.45 * s, 1.39, 0.0),
            dofs: euler("Y", &[m(-2.5, 0.0)]),
        });
        v.push(JointSpec {
            name: name("forearm"),
            parent: Some(base + 2),
            position: Vec3::new(0.575 * s, 1.39, 0.0),
            dofs: euler("X", &[[-1.6, 1.6]]),
        });
        v.push(JointSpec {
            name: name("wrist"),
            parent: Some(base + 3),
            position: Vec3::new(0.70 * s, 1.39, 0.0),
            dofs: euler("ZY", &[m(-0.7, 0.7), m(-0.4, 0.4)]),
        });
    }
    for (side, s) in [("l", 1.0f32), ("r", -1.0f32)] {
        let base = v.len();
        let name = |n: &str| format!("{side}_{n}");
        let m = |lo: f32, hi: f32| if s > 0.0 { [lo, hi] } else { [-hi, -lo] };
        v.push(JointSpec {
            name: name("hip"),
            parent: Some(0),
            position: Vec3::new(0.10 * s, 0.90, 0.0),
            dofs: euler("XZY", &[[-2.0, 0.6], m(-0.4, 0.8), m(-0.6, 0.6)]),
        });
        v.push(JointSpec {
            name: name("knee"),
            parent: Some(base),
            position: Vec3::new(0.10 * s, 0.48, 0.0),
            dofs: euler("X", &[[0.0, 2.5]]),
        });
        v.push(JointSpec {
            name: name("ankle"),
            parent: Some(base + 1),
            position: Vec3::new(0.10 * s, 0.08, -0.01),
            dofs: euler("XZ", &[[-0.7, 0.6], [-0.3, 0.3]]),
        });
        v.push(JointSpec {
            name: name("toe"),
            parent: Some(base + 2),
            position: Vec3::new(0.10 * s, 0.03, 0.13),
            dofs: euler("X", &[[-0.3, 0.7]]),
        });
    }
    v
}

/// The built-in character's skeleton (24 joints, bind rotations identity, world bind positions
/// as in the table in this module).
pub fn build_skeleton() -> Result<Skeleton, SkeletonError> {
    let specs = specs();
    let names = specs.iter().map(|s| s.name.clone()).collect();
    let parents = specs.iter().map(|s| s.parent).collect();
    let locals = specs
        .iter()
        .map(|s| {
            Transform::from_translation(
                s.position - s.parent.map_or(Vec3::ZERO, |p| specs[p].position),
            )
        })
        .collect();
    let dofs = specs.into_iter().map(|s| s.dofs).collect();
    Skeleton::new(names, parents, locals, None, Some(dofs), Mat4::IDENTITY)
}

/// A bone segment of the character: the joint whose rotation moves it, and its two ends in the
/// bind pose. Every joint owns exactly one segment, from its position to its first child's
/// (end joints get a short stub along their limb); the true weights are built from these.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoneSegment {
    /// The joint that moves the segment.
    pub joint: usize,
    /// Start (the joint's bind position).
    pub a: Vec3,
    /// End.
    pub b: Vec3,
}

/// One segment per joint (see [`BoneSegment`]).
#[must_use]
pub fn bone_segments(skeleton: &Skeleton) -> Vec<BoneSegment> {
    let pos = bind_positions(skeleton);
    (0..skeleton.len())
        .map(|j| {
            let a = pos[j];
            // The hips' segment runs up the spine, the chest's up to the neck: the first child.
            let b = match skeleton.children(j).next() {
                Some(c) => pos[c],
                None => {
                    let stub = match j {
                        joint::HEAD => Vec3::Y * 0.16,
                        joint::L_WRIST => Vec3::X * 0.10,
                        joint::R_WRIST => Vec3::NEG_X * 0.10,
                        _ => Vec3::Z * 0.06,
                    };
                    a + stub
                }
            };
            BoneSegment { joint: j, a, b }
        })
        .collect()
}

/// World positions of the joints in the bind pose.
#[must_use]
pub fn bind_positions(skeleton: &Skeleton) -> Vec<Vec3> {
    skeleton
        .inverse_bind()
        .iter()
        .map(|m| m.inverse().w_axis.truncate())
        .collect()
}

/// Distance from `p` to the segment `a`–`b`, and the parameter in [0, 1] of the closest point.
#[must_use]
pub fn segment_distance(p: Vec3, a: Vec3, b: Vec3) -> (f32, f32) {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-12)).clamp(0.0, 1.0);
    ((p - (a + ab * t)).length(), t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skeleton_has_24_joints_with_the_named_degrees_of_freedom() {
        let s = build_skeleton().unwrap();
        assert_eq!(s.len(), joint::COUNT);
        assert_eq!(s.names()[joint::R_KNEE], "r_knee");
        assert_eq!(s.dofs()[joint::L_ELBOW].count(), 1);
        assert_eq!(s.dofs()[joint::L_KNEE].count(), 1);
        assert_eq!(s.dofs()[joint::HIPS].count(), 3);
        let p = bind_positions(&s);
        assert!((p[joint::L_KNEE] - Vec3::new(0.10, 0.48, 0.0)).length() < 1e-6);
        // A bent left knee (positive X) moves the ankle backwards (−Z) — the documented convention.
        let mut angles = vec![0.0; s.angle_count()];
        let knee_angle = s.dofs()[..joint::L_KNEE]
            .iter()
            .map(|d| d.count())
            .sum::<usize>();
        angles[knee_angle] = 1.0;
        let pose = s
            .pose_from_angles(glam::Quat::IDENTITY, Vec3::ZERO, &angles)
            .unwrap();
        let mut w = vec![Mat4::IDENTITY; s.len()];
        s.world_matrices(&pose, &mut w).unwrap();
        assert!(w[joint::L_ANKLE].w_axis.z < -0.2);
    }
}
