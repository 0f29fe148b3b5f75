//! The ground truth's static weights for the built-in character: smooth distance-to-bone
//! weights (deliberately *not* bone heat, which the trainer uses for its initial weights).
//!
//! Rule: for vertex `x` and joint `j` with bone segment `s_j` ([`bone_segments`]),
//! `d_j = dist(x, s_j)`; the [`INFLUENCES`] joints with the smallest `d_j` get
//! `w_j ∝ (d_min + ε)⁴ / (d_j + ε)⁴` with `ε` = [`EPSILON`] m, weights below 1 % are dropped and
//! the rest normalised. Ties go to the lower joint index.
//!
//! Skirt vertices hang from the waist: weight `1 − λ` on the hips and `λ` =
//! [`SKIRT_LEG_SHARE`] split between the two hip joints by the same inverse-power rule, so a
//! skirt skinned with these weights barely follows the thighs and the legs would pierce it
//! without the deformer's push-out.

use glam::Vec3;
use skinfield_formats::{Skeleton, SkinError, StaticSkin};

use super::character::{bone_segments, joint, segment_distance};

/// Influences kept per vertex.
pub const INFLUENCES: usize = 4;
/// Softening distance of the inverse-power falloff (metres).
pub const EPSILON: f32 = 0.02;
/// Share of the hip joints (thighs) in a skirt vertex's weights.
pub const SKIRT_LEG_SHARE: f32 = 0.3;

/// True static weights of `positions` (bind pose) for the character `skeleton`; `skirt[v]`
/// marks skirt vertices (an empty slice: none).
pub fn true_weights(
    skeleton: &Skeleton,
    positions: &[Vec3],
    skirt: &[bool],
) -> Result<StaticSkin, SkinError> {
    let segments = bone_segments(skeleton);
    let thighs = [joint::L_HIP, joint::R_HIP];
    let mut offsets = vec![0u32];
    let mut joints = Vec::new();
    let mut weights = Vec::new();
    for (v, &p) in positions.iter().enumerate() {
        let is_skirt = skirt.get(v).copied().unwrap_or(false);
        let mut d: Vec<(f32, usize)> = segments
            .iter()
            .filter(|s| !is_skirt || thighs.contains(&s.joint))
            .map(|s| (segment_distance(p, s.a, s.b).0, s.joint))
            .collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let nearest = d[0].0 + EPSILON;
        let mut row: Vec<(u32, f32)> = d[..INFLUENCES.min(d.len())]
            .iter()
            .map(|&(dj, j)| (j as u32, (nearest / (dj + EPSILON)).powi(4)))
            .collect();
        if is_skirt {
            let sum: f32 = row.iter().map(|r| r.1).sum();
            for r in &mut row {
                r.1 *= SKIRT_LEG_SHARE / sum;
            }
            row.push((joint::HIPS as u32, 1.0 - SKIRT_LEG_SHARE));
        }
        let sum: f32 = row.iter().map(|r| r.1).sum();
        row.retain(|r| r.1 >= 0.01 * sum);
        let kept: f32 = row.iter().map(|r| r.1).sum();
        row.sort_by_key(|r| r.0);
        for (j, w) in row {
            joints.push(j);
            weights.push(w / kept);
        }
        offsets.push(joints.len() as u32);
    }
    StaticSkin::new(offsets, joints, weights, skeleton.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::character::build_skeleton;

    #[test]
    fn weights_follow_the_nearest_bones_and_blend_at_joints() {
        let s = build_skeleton().unwrap();
        let pts = [
            Vec3::new(0.30, 1.44, 0.0),  // on the upper arm
            Vec3::new(0.45, 1.44, 0.0),  // above the elbow
            Vec3::new(0.10, 0.70, 0.07), // on the thigh
        ];
        let w = true_weights(&s, &pts, &[]).unwrap();
        let dense = w.to_dense();
        let row = |v: usize| &dense[v * s.len()..(v + 1) * s.len()];
        assert!(row(0)[joint::L_SHOULDER] > 0.9, "{:?}", row(0));
        // At the elbow, the upper arm's and the elbow's segments are equally near.
        assert!(
            (row(1)[joint::L_SHOULDER] - row(1)[joint::L_ELBOW]).abs() < 0.05,
            "{:?}",
            row(1)
        );
        assert!(row(2)[joint::L_HIP] > 0.9, "{:?}", row(2));
        assert!(w.max_influences() <= INFLUENCES);
        // The same thigh point as a skirt vertex hangs mostly from the hips.
        let skirt = true_weights(&s, &pts[2..], &[true]).unwrap().to_dense();
        assert!(
            skirt[joint::HIPS] > 0.5 && skirt[joint::L_HIP] < 0.5,
            "{skirt:?}"
        );
        assert!(
            skirt
                .iter()
                .enumerate()
                .all(|(j, &w)| w == 0.0 || [joint::HIPS, joint::L_HIP, joint::R_HIP].contains(&j))
        );
    }
}
