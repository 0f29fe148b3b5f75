//! Bone segments in the bind pose: which segment belongs to which joint.
//!
//! Joint heads come from the inverse bind matrices (the bind world matrix is `IBM⁻¹`, the head
//! its translation), so a skeleton whose `bind_local` disagrees with its IBMs (glTF allows it)
//! is still weighted where the mesh was bound.
//!
//! Ownership (glTF/BVH convention: a joint rotates the bone that leaves it):
//! - a joint with children owns one segment from its head to each child's head;
//! - a leaf with a parent owns a segment from its head continuing the parent's direction, of
//!   `leaf_fraction` times the parent segment's length (the tip of a finger, the top of the head);
//! - a lone root (no parent, no children) owns the point at its head;
//! - with explicit tails (`HeatOptions::bone_tails`, e.g. MakeHuman or Blender bones), every
//!   joint owns exactly the segment from its head to its tail instead.

use glam::DVec3;
use skinfield_formats::Skeleton;

/// One bone segment `a → b` (possibly a point, `a == b`) owned by `joint`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoneSegment {
    /// The joint whose weight this segment attracts.
    pub joint: u32,
    /// Start (the joint's head).
    pub a: DVec3,
    /// End.
    pub b: DVec3,
}

impl BoneSegment {
    /// Closest point of the segment to `p`.
    #[must_use]
    pub fn closest_point(&self, p: DVec3) -> DVec3 {
        let d = self.b - self.a;
        let len2 = d.length_squared();
        if len2 <= 0.0 {
            return self.a;
        }
        let t = ((p - self.a).dot(d) / len2).clamp(0.0, 1.0);
        self.a + d * t
    }
}

/// World bind-pose head of every joint (translation of `IBM⁻¹`), or the first joint whose
/// inverse bind matrix cannot be inverted.
pub(crate) fn joint_heads(skeleton: &Skeleton) -> Result<Vec<DVec3>, usize> {
    skeleton
        .inverse_bind()
        .iter()
        .enumerate()
        .map(|(j, m)| {
            let m = m.as_dmat4();
            let det = m.determinant();
            if !(det.is_finite() && det.abs() > 1e-12) {
                return Err(j);
            }
            let head = m.inverse().w_axis.truncate();
            if head.is_finite() { Ok(head) } else { Err(j) }
        })
        .collect()
}

/// The segments of a skeleton (see the module docs for who owns what).
#[must_use]
pub(crate) fn bone_segments(
    skeleton: &Skeleton,
    heads: &[DVec3],
    tails: Option<&[DVec3]>,
    leaf_fraction: f64,
) -> Vec<BoneSegment> {
    if let Some(tails) = tails {
        return heads.iter().zip(tails).enumerate().map(|(j, (&a, &b))| BoneSegment { joint: j as u32, a, b }).collect();
    }
    let parents = skeleton.parents();
    let mut segments = Vec::with_capacity(heads.len() + 8);
    for j in 0..heads.len() {
        let a = heads[j];
        let mut has_child = false;
        for c in skeleton.children(j) {
            has_child = true;
            segments.push(BoneSegment { joint: j as u32, a, b: heads[c] });
        }
        if has_child {
            continue;
        }
        let b = match parents[j] {
            Some(p) => a + (a - heads[p]) * leaf_fraction,
            None => a,
        };
        segments.push(BoneSegment { joint: j as u32, a, b });
    }
    segments
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Vec3};
    use skinfield_formats::Transform;

    #[test]
    fn ownership_follows_the_child_convention() {
        // hips → spine, hips → leg; spine → head (leaf).
        let t = |x: f32, y: f32| Transform::from_translation(Vec3::new(x, y, 0.0));
        let s = Skeleton::new(
            ["hips", "spine", "leg", "head"].map(String::from).to_vec(),
            vec![None, Some(0), Some(0), Some(1)],
            vec![t(0.0, 1.0), t(0.0, 0.5), t(0.2, -0.5), t(0.0, 0.4)],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap();
        let heads = joint_heads(&s).unwrap();
        assert!((heads[3] - DVec3::new(0.0, 1.9, 0.0)).length() < 1e-6);
        let segs = bone_segments(&s, &heads, None, 0.5);
        let owned: Vec<u32> = segs.iter().map(|s| s.joint).collect();
        assert_eq!(owned, vec![0, 0, 1, 2, 3]);
        assert!((segs[1].b - DVec3::new(0.2, 0.5, 0.0)).length() < 1e-6);
        // The head continues the spine direction for half of its 0.4 length.
        assert!((segs[4].b - DVec3::new(0.0, 2.1, 0.0)).length() < 1e-6);
        // The leg is a leaf too: a segment continuing hips → leg.
        assert!((segs[3].b - (heads[2] + (heads[2] - heads[0]) * 0.5)).length() < 1e-9);
        let seg = segs[2];
        assert!((seg.closest_point(DVec3::new(1.0, 1.7, 0.0)) - DVec3::new(0.0, 1.7, 0.0)).length() < 1e-9);
        assert!((seg.closest_point(DVec3::new(1.0, 1.2, 0.0)) - DVec3::new(0.0, 1.5, 0.0)).length() < 1e-9);
    }
}
