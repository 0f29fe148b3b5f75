//! Blending joint transforms per vertex: linear blend skinning and dual-quaternion skinning
//! (Kavan et al. 2007), for positions, normals and tangents.

use glam::{Mat3A, Mat4, Quat, Vec3, Vec3A, Vec4};

/// How joint transforms are blended.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Method {
    /// Linear blend skinning: `x = (Σ w_j M_j) x̄`.
    #[default]
    Lbs,
    /// Dual-quaternion skinning (Kavan 2007): blends the rigid part of each skinning matrix
    /// (rotation and translation; scale is dropped), so twists keep their volume.
    Dqs,
}

/// A unit dual quaternion `real + ε dual` (rotation, then translation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DualQuat {
    /// Rotation.
    pub real: Quat,
    /// `½ t · real` (t as a pure quaternion).
    pub dual: Quat,
}

impl DualQuat {
    /// The identity.
    pub const IDENTITY: Self = Self {
        real: Quat::IDENTITY,
        dual: Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
    };

    /// The rigid part of an affine matrix (scale and shear dropped).
    #[must_use]
    pub fn from_mat4(m: &Mat4) -> Self {
        let (_, r, t) = m.to_scale_rotation_translation();
        let r = r.normalize();
        let r = if r.is_finite() { r } else { Quat::IDENTITY };
        Self {
            real: r,
            dual: Quat::from_xyzw(t.x, t.y, t.z, 0.0) * r * 0.5,
        }
    }

    /// Translation `2 · dual · real*`.
    #[must_use]
    pub fn translation(&self) -> Vec3 {
        let t = self.dual * self.real.conjugate() * 2.0;
        Vec3::new(t.x, t.y, t.z)
    }
}

/// Cofactor matrix of `m`'s upper 3×3: `det(m) · m⁻ᵀ`, the normal transform that stays defined
/// for singular blends and keeps orientation under mirroring. In the 16-byte vector types
/// (`Vec3A`), whose cross products and dot products are SIMD shuffles where the target has
/// them: the per-vertex tail of every LBS job (perf put the 12-byte-`Vec3` version at a third
/// of the fast path's per-vertex time). Same products, same summation order as the scalar form.
fn cofactor(m: &Mat4) -> Mat3A {
    let (c0, c1, c2) = (
        Vec3A::from_vec4(m.x_axis),
        Vec3A::from_vec4(m.y_axis),
        Vec3A::from_vec4(m.z_axis),
    );
    Mat3A::from_cols(c1.cross(c2), c2.cross(c0), c0.cross(c1))
}

/// A skinned vertex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Skinned {
    pub position: Vec3,
    pub normal: Vec3,
    pub tangent: Vec4,
}

/// LBS of one vertex with influences `(joint, weight)`.
pub(crate) fn lbs(
    mats: &[Mat4],
    infl: impl Iterator<Item = (usize, f32)>,
    p: Vec3,
    n: Vec3,
    t: Vec4,
) -> Skinned {
    let mut m = Mat4::ZERO;
    for (j, w) in infl {
        if let Some(mj) = mats.get(j) {
            m += *mj * w;
        }
    }
    apply_matrix(&m, p, n, t)
}

/// Applies a blended skinning matrix to a position, normal (cofactor) and tangent.
pub(crate) fn apply_matrix(m: &Mat4, p: Vec3, n: Vec3, t: Vec4) -> Skinned {
    Skinned {
        position: lbs_point(m, p),
        normal: lbs_normal(m, n),
        tangent: lbs_tangent(m, t),
    }
}

/// A position under a blended skinning matrix (affine: the matrix's last row is ignored).
#[inline]
pub(crate) fn lbs_point(m: &Mat4, p: Vec3) -> Vec3 {
    Vec3::from(m.transform_point3a(Vec3A::from(p)))
}

/// A normal under a blended skinning matrix (cofactor: right for non-rigid blends).
#[inline]
pub(crate) fn lbs_normal(m: &Mat4, n: Vec3) -> Vec3 {
    unit(lbs_normal_unnormalised(m, n))
}

/// [`lbs_normal`] before its normalisation. Jobs that skin many vertices write this and call
/// [`normalise_block`] on a block afterwards: a normalisation is a square root and a division
/// that each wait on the last, and done vertex by vertex that chain stalled the next vertex's
/// blend (a fifth of the fast path's per-vertex samples sat on it); over a block the chains are
/// independent. The result is the same to the bit.
#[inline]
pub(crate) fn lbs_normal_unnormalised(m: &Mat4, n: Vec3) -> Vec3 {
    Vec3::from(cofactor(m) * Vec3A::from(n))
}

/// A tangent under a blended skinning matrix, handedness `w` kept.
#[inline]
pub(crate) fn lbs_tangent(m: &Mat4, t: Vec4) -> Vec4 {
    unit_tangent(lbs_tangent_unnormalised(m, t))
}

/// [`lbs_tangent`] before its normalisation (see [`lbs_normal_unnormalised`]).
#[inline]
pub(crate) fn lbs_tangent_unnormalised(m: &Mat4, t: Vec4) -> Vec4 {
    Vec3::from(m.transform_vector3a(Vec3A::from_vec4(t))).extend(t.w)
}

/// `v` scaled to unit length, or zero where that is not finite.
#[inline]
fn unit(v: Vec3) -> Vec3 {
    Vec3::from(Vec3A::from(v).normalize_or_zero())
}

/// A tangent's direction scaled to unit length (or zero), its handedness `w` kept.
#[inline]
fn unit_tangent(t: Vec4) -> Vec4 {
    unit(t.truncate()).extend(t.w)
}

/// Normalises outputs `range` of the [`lbs_normal_unnormalised`] normals and
/// [`lbs_tangent_unnormalised`] tangents an LBS job wrote (either may be absent), a block at a
/// time.
pub(crate) fn normalise_block(
    normals: Option<&mut [Vec3]>,
    tangents: Option<&mut [Vec4]>,
    range: core::ops::Range<usize>,
) {
    if let Some(o) = normals {
        for n in &mut o[range.clone()] {
            *n = unit(*n);
        }
    }
    if let Some(o) = tangents {
        for t in &mut o[range] {
            *t = unit_tangent(*t);
        }
    }
}

/// DQS of one vertex; falls back to LBS where the blended rotation vanishes (weights that
/// cancel exactly), so no input gives NaN.
pub(crate) fn dqs(
    mats: &[Mat4],
    dqs: &[DualQuat],
    infl: impl Iterator<Item = (usize, f32)> + Clone,
    p: Vec3,
    n: Vec3,
    t: Vec4,
) -> Skinned {
    // Antipodality: align every quaternion with the most influential one (Kavan's pivot).
    let mut pivot = Quat::IDENTITY;
    let mut best = f32::NEG_INFINITY;
    for (j, w) in infl.clone() {
        if let Some(d) = dqs.get(j)
            && w > best
        {
            best = w;
            pivot = d.real;
        }
    }
    let (mut real, mut dual) = (Vec4::ZERO, Vec4::ZERO);
    for (j, w) in infl.clone() {
        if let Some(d) = dqs.get(j) {
            let s = if d.real.dot(pivot) < 0.0 { -w } else { w };
            real += Vec4::from(d.real) * s;
            dual += Vec4::from(d.dual) * s;
        }
    }
    let len = real.length();
    if len.is_nan() || len <= 1e-8 {
        return lbs(mats, infl, p, n, t);
    }
    let b = DualQuat {
        real: Quat::from_vec4(real / len),
        dual: Quat::from_vec4(dual / len),
    };
    // For a non-unit blend, the translation of the normalised dual quaternion must use the part
    // of `dual` orthogonal to `real` (Kavan 2007, eq. 5); `translation()` does this implicitly
    // through `dual · real*`, whose scalar part we discard.
    let pos = b.real * p + b.translation();
    Skinned {
        position: pos,
        normal: (b.real * n).normalize_or_zero(),
        tangent: (b.real * t.truncate()).normalize_or_zero().extend(t.w),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::FRAC_PI_2;

    #[test]
    fn dual_quat_round_trips_a_rigid_matrix() {
        let m =
            Mat4::from_rotation_translation(Quat::from_rotation_y(0.7), Vec3::new(1.0, -2.0, 0.5));
        let d = DualQuat::from_mat4(&m);
        let p = Vec3::new(0.3, 0.4, -0.2);
        assert!((d.real * p + d.translation() - m.transform_point3(p)).length() < 1e-6);
    }

    #[test]
    fn one_rotated_bone_moves_points_analytically_with_both_methods() {
        // Bone rotated 90° about Z around the pivot (0, 1, 0).
        let pivot = Vec3::Y;
        let r = Quat::from_rotation_z(FRAC_PI_2);
        let m = Mat4::from_translation(pivot) * Mat4::from_quat(r) * Mat4::from_translation(-pivot);
        let mats = [Mat4::IDENTITY, m];
        let dq = [DualQuat::from_mat4(&mats[0]), DualQuat::from_mat4(&mats[1])];
        let p = Vec3::new(0.0, 2.0, 0.0);
        let n = Vec3::X;
        let t = Vec4::new(0.0, 1.0, 0.0, -1.0);
        let infl = [(1usize, 1.0f32)];
        for s in [
            lbs(&mats, infl.iter().copied(), p, n, t),
            dqs(&mats, &dq, infl.iter().copied(), p, n, t),
        ] {
            // (0, 2, 0) is 1 above the pivot; +90° about Z sends +Y to −X.
            assert!(
                (s.position - Vec3::new(-1.0, 1.0, 0.0)).length() < 1e-6,
                "{s:?}"
            );
            assert!((s.normal - Vec3::Y).length() < 1e-6, "{s:?}");
            assert!(
                (s.tangent - Vec4::new(-1.0, 0.0, 0.0, -1.0)).length() < 1e-6,
                "{s:?}"
            );
        }
    }

    #[test]
    fn dqs_keeps_length_under_a_twist_where_lbs_collapses() {
        // A point at radius 1 around the X axis, weighted half on a bone twisted about X.
        for angle in [FRAC_PI_2, 2.0 * FRAC_PI_2] {
            let twist = Mat4::from_quat(Quat::from_rotation_x(angle));
            let mats = [Mat4::IDENTITY, twist];
            let dq = [DualQuat::from_mat4(&mats[0]), DualQuat::from_mat4(&mats[1])];
            let p = Vec3::new(0.5, 1.0, 0.0);
            let infl = [(0usize, 0.5f32), (1, 0.5)];
            let l = lbs(&mats, infl.iter().copied(), p, Vec3::Y, Vec4::X).position;
            let d = dqs(&mats, &dq, infl.iter().copied(), p, Vec3::Y, Vec4::X).position;
            let radius = |v: Vec3| (v.y * v.y + v.z * v.z).sqrt();
            // LBS averages the two rotated points: radius cos(angle/2) (0.707 at 90°, the
            // candy-wrapper collapse to the axis at 180°).
            assert!((radius(l) - (angle / 2.0).cos()).abs() < 1e-6, "lbs {l}");
            // DQS rotates by angle/2: radius kept, on the bisecting direction (at 180° the two
            // bisectors are equally valid, so only |z| is fixed).
            assert!((radius(d) - 1.0).abs() < 1e-6, "dqs {d}");
            let want = Vec3::new(0.5, (angle / 2.0).cos(), (angle / 2.0).sin());
            assert!(
                (Vec3::new(d.x, d.y, d.z.abs()) - want).length() < 1e-6,
                "dqs {d}"
            );
        }
    }

    #[test]
    fn lbs_normals_use_the_inverse_transpose() {
        // Non-uniform scale: a 45° normal must tilt towards the squashed axis.
        let m = Mat4::from_scale(Vec3::new(2.0, 1.0, 1.0));
        let n = Vec3::new(1.0, 1.0, 0.0).normalize();
        let s = lbs(&[m], [(0, 1.0)].into_iter(), Vec3::ZERO, n, Vec4::X);
        let want = Vec3::new(0.5, 1.0, 0.0).normalize();
        assert!((s.normal - want).length() < 1e-6, "{s:?}");
    }

    #[test]
    fn cancelling_dual_quaternions_fall_back_without_nan() {
        let mats = [Mat4::IDENTITY, Mat4::IDENTITY];
        let mut dq = [DualQuat::IDENTITY; 2];
        dq[1].real = -dq[1].real;
        // Weights of opposite sign (only reachable through a hand-made skin) must not give NaN.
        let s = dqs(
            &mats,
            &dq,
            [(0usize, 1.0f32), (1, -1.0)].into_iter(),
            Vec3::ONE,
            Vec3::Y,
            Vec4::X,
        );
        assert!(s.position.is_finite());
    }
}
