//! Small geometric helpers on top of glam: TRS transforms, rotation vectors, bounding boxes.

use glam::{Mat4, Quat, Vec3};

/// A rigid transform with scale, applied as `T · R · S` (glTF's node TRS convention).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Translation in the parent's frame.
    pub translation: Vec3,
    /// Rotation (unit quaternion).
    pub rotation: Quat,
    /// Per-axis scale (uniform in practice; glTF allows non-uniform).
    pub scale: Vec3,
}

impl Default for Transform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Transform {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        translation: Vec3::ZERO,
        rotation: Quat::IDENTITY,
        scale: Vec3::ONE,
    };

    /// A transform with only a translation.
    #[must_use]
    pub fn from_translation(translation: Vec3) -> Self {
        Self {
            translation,
            ..Self::IDENTITY
        }
    }

    /// A transform with only a rotation and a translation.
    #[must_use]
    pub fn from_rotation_translation(rotation: Quat, translation: Vec3) -> Self {
        Self {
            translation,
            rotation,
            scale: Vec3::ONE,
        }
    }

    /// The 4×4 matrix `T · R · S`.
    #[must_use]
    pub fn to_mat4(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }

    /// Decomposes an affine matrix into TRS (exact for matrices without shear).
    #[must_use]
    pub fn from_mat4(m: &Mat4) -> Self {
        let (scale, rotation, translation) = m.to_scale_rotation_translation();
        Self {
            translation,
            rotation: rotation.normalize(),
            scale,
        }
    }

    /// True when every component is finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.translation.is_finite() && self.rotation.is_finite() && self.scale.is_finite()
    }
}

/// Rotation vector (axis · angle, radians) of a unit quaternion, taking the shortest arc.
#[must_use]
pub fn quat_to_rotvec(q: Quat) -> Vec3 {
    // Shortest arc: q and -q are the same rotation; pick w >= 0 so the angle is in [0, π].
    let q = if q.w < 0.0 { -q } else { q };
    let v = Vec3::new(q.x, q.y, q.z);
    let s = v.length();
    if s < 1e-7 {
        // sin(θ/2) ≈ θ/2 for small angles, so θ·axis ≈ 2·v.
        return v * 2.0;
    }
    let angle = 2.0 * libm::atan2f(s, q.w);
    v * (angle / s)
}

/// Unit quaternion of a rotation vector (axis · angle, radians).
#[must_use]
pub fn rotvec_to_quat(r: Vec3) -> Quat {
    let angle = r.length();
    if angle < 1e-7 {
        return Quat::from_xyzw(r.x * 0.5, r.y * 0.5, r.z * 0.5, 1.0).normalize();
    }
    Quat::from_axis_angle(r / angle, angle)
}

/// Splits `q` into `twist · swing` where `twist` rotates about the unit `axis`.
///
/// The same twist serves `q = swing · twist` as well (the projection of the vector part onto
/// the axis is the same for both orders); returns the identity twist when `q` is a half turn
/// perpendicular to the axis.
#[must_use]
pub fn twist_about(q: Quat, axis: Vec3) -> Quat {
    let v = Vec3::new(q.x, q.y, q.z);
    let p = axis * v.dot(axis);
    let t = Quat::from_xyzw(p.x, p.y, p.z, q.w);
    let n = t.length();
    if n < 1e-9 { Quat::IDENTITY } else { t / n }
}

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3,
    /// Largest corner.
    pub max: Vec3,
}

impl Aabb {
    /// The box around `points`, or `None` when there are none or one is not finite.
    #[must_use]
    pub fn from_points(points: &[Vec3]) -> Option<Self> {
        let first = *points.first()?;
        let mut b = Self {
            min: first,
            max: first,
        };
        for p in points {
            if !p.is_finite() {
                return None;
            }
            b.min = b.min.min(*p);
            b.max = b.max.max(*p);
        }
        Some(b)
    }

    /// Centre of the box.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Edge lengths of the box.
    #[must_use]
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotvec_round_trip_and_shortest_arc() {
        for r in [
            Vec3::new(0.3, -0.2, 0.9),
            Vec3::new(1e-9, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
        ] {
            let q = rotvec_to_quat(r);
            assert!((quat_to_rotvec(q) - r).length() < 1e-5, "{r}");
            assert!((quat_to_rotvec(-q) - r).length() < 1e-5, "negated {r}");
        }
    }

    #[test]
    fn twist_recovers_yaw_of_yaw_times_tilt() {
        let yaw = Quat::from_rotation_y(0.8);
        let tilt = Quat::from_rotation_x(0.4) * Quat::from_rotation_z(-0.2);
        let t = twist_about(yaw * tilt, Vec3::Y);
        // The tilt has a small Y component of its own; the twist must at least be a pure Y rotation
        // and for a tilt with no Y twist component recover the yaw exactly.
        assert!(t.x.abs() < 1e-6 && t.z.abs() < 1e-6);
        let t2 = twist_about(yaw * Quat::from_rotation_x(0.4), Vec3::Y);
        assert!(t2.angle_between(yaw) < 1e-5);
    }

    #[test]
    fn transform_matrix_round_trip() {
        let t = Transform {
            translation: Vec3::new(1.0, 2.0, 3.0),
            rotation: Quat::from_rotation_z(0.5),
            scale: Vec3::splat(2.0),
        };
        let back = Transform::from_mat4(&t.to_mat4());
        assert!((back.translation - t.translation).length() < 1e-5);
        assert!(back.rotation.angle_between(t.rotation) < 1e-5);
        assert!((back.scale - t.scale).length() < 1e-5);
    }
}
