//! The joints a point may be skinned to: locality by construction.
//!
//! SkinNet's softmax ranges over every joint, so nothing but a soft regulariser keeps a vertex of
//! the torso from taking weight from a finger: a small weight on a far joint moves the vertex by
//! centimetres, and on a 67-joint rig an unconstrained net produced exactly such spikes. Here
//! each point gets a short list of candidate joints, and the weights of all other joints are
//! zero by construction (a masked softmax, in training and in the runtime).
//!
//! The list of a vertex is the support of its initial (bone-heat) weights — the joints with
//! weight at least [`SUPPORT_THRESHOLD`], strongest first — followed by their neighbours in the
//! skeleton (parent, then children), up to [`DEFAULT_CANDIDATES`] joints. Bone heat is local and
//! aware of which bones a surface point sees (a hip vertex next to a hanging hand takes nothing
//! from the hand), and the neighbours let the weights move across the joint a vertex sits near,
//! which is what pose-dependent skinning needs; a skirt's hem sees both thighs and the hips, and
//! with them the knees and the spine. This is the paper's geodesic regulariser (Eqs. 7–8) made a
//! hard constraint, with bone heat's support in place of geodesic distance to the argmax region
//! (which is infinite between a skirt and the legs it must follow when they are separate
//! surfaces).
//!
//! The lists are generous on purpose. An inner thigh sees the other thigh's bone, so its list
//! holds the other hip and knee, and silhouettes alone can put such a vertex on the other knee.
//! Narrower rules measured on the built-in capture (neighbours of strong support only; two
//! skeleton edges from the strongest joint; the strongest joint's chain plus the first joint of
//! each branch) cost SkinNet 12–40 % of Chamfer (0.650 → 0.729–0.904 cm) for the few
//! centimetres they took off those vertices (`docs/experiments/fidelity.md`; single runs at
//! the zoo's budget, where the network's initialisation alone moves SkinNet by as much).
//!
//! An optional gate (`reach`, `TrainConfig::candidate_reach`) admits a skeleton neighbour only if
//! one of its bind-pose bones passes within `reach` times the point's distance to its support's
//! bones, which removes exactly those far neighbours (reach 2 narrows the built-in character's
//! lists from 5.9 to 4.5 joints on average). It is off by default: it shrinks the largest
//! spikes on the built-in capture, but its effect on Chamfer is smaller than what one run
//! differs from another, and silhouettes alone do worse with it (the measurements are in
//! `docs/experiments/fidelity.md`).
//!
//! The runtime must rebuild the lists for meshes of any resolution, so the `.skf` stores the
//! training template's vertices as anchors with their lists, and every point takes the list of
//! its nearest anchor (`skinfield_runtime::candidates::nearest_anchors`); training uses the same
//! function for its query points.

use glam::{DVec3, Vec3};
use rayon::prelude::*;
use skinfield_formats::Skeleton;

use crate::heat::bones::{BoneSegment, bone_segments, joint_heads};

/// Most candidate joints per point.
pub const DEFAULT_CANDIDATES: usize = 8;
/// Initial weights from this up count as support.
pub const SUPPORT_THRESHOLD: f32 = 0.01;

/// Skeleton neighbours join a list only if one of their bones passes within this many times the
/// distance from the point to the nearest bone of its support (bind pose); see the module docs.
pub const DEFAULT_NEIGHBOUR_REACH: f32 = f32::INFINITY;

/// The candidate joints of every vertex of dense initial weights `init` (`[V, J]` row-major) at
/// canonical `positions`: each list sorted ascending, between 1 and `k` joints (see the module
/// docs). A skeleton neighbour of the support is added only where one of its bones passes within
/// `reach` times the point's distance to its support's bones (`f32::INFINITY`: always, as
/// before the gate existed; also where the skeleton's bind matrices cannot be inverted).
///
/// # Panics
/// If `positions` does not hold one point per row of `init`.
#[must_use]
pub fn candidate_sets(
    init: &[f32],
    skeleton: &Skeleton,
    positions: &[Vec3],
    k: usize,
    reach: f32,
) -> Vec<Vec<u16>> {
    let j = skeleton.len();
    assert_eq!(
        init.len(),
        positions.len() * j,
        "one position per weight row"
    );
    let k = k.clamp(1, j.max(1));
    let parents = skeleton.parents();
    let children: Vec<Vec<usize>> = (0..j).map(|p| skeleton.children(p).collect()).collect();
    let bones = BonesOfJoints::new(skeleton, reach);
    init.par_chunks(j.max(1))
        .zip(positions.par_iter())
        .map(|(w, &x)| {
            let mut order: Vec<usize> = (0..j).collect();
            order.sort_by(|&a, &b| w[b].total_cmp(&w[a]).then(a.cmp(&b)));
            let mut list: Vec<usize> = order
                .iter()
                .copied()
                .take_while(|&i| w[i] >= SUPPORT_THRESHOLD)
                .take(k)
                .collect();
            if list.is_empty() {
                list.push(order[0]);
            }
            let support = list.clone();
            // The gate's bones, the point and the farthest a neighbour's bone may be; without
            // the gate every neighbour is within reach.
            let limit = bones.as_ref().map(|b| {
                let x = x.as_dvec3();
                let d = support
                    .iter()
                    .map(|&s| b.distance(s, x))
                    .fold(f64::INFINITY, f64::min);
                (b, x, f64::from(reach) * d)
            });
            let within = |n: usize| limit.is_none_or(|(b, x, l)| b.distance(n, x) <= l);
            for &s in &support {
                let near = parents[s].into_iter().chain(children[s].iter().copied());
                for n in near {
                    if list.len() >= k {
                        break;
                    }
                    if !list.contains(&n) && within(n) {
                        list.push(n);
                    }
                }
            }
            list.sort_unstable();
            list.into_iter().map(|i| i as u16).collect()
        })
        .collect()
}

/// The bind-pose bone segments of every joint (bone heat's ownership rule), for the gate on
/// skeleton neighbours.
struct BonesOfJoints {
    per_joint: Vec<Vec<BoneSegment>>,
}

impl BonesOfJoints {
    /// `None` when the gate is off (`reach` infinite or not positive) or the bind matrices
    /// cannot be inverted.
    fn new(skeleton: &Skeleton, reach: f32) -> Option<Self> {
        if !(reach.is_finite() && reach > 0.0) {
            return None;
        }
        let heads = joint_heads(skeleton).ok()?;
        let leaf_fraction = crate::heat::HeatOptions::default().leaf_fraction;
        let mut per_joint = vec![Vec::new(); skeleton.len()];
        for segment in bone_segments(skeleton, &heads, None, leaf_fraction) {
            per_joint[segment.joint as usize].push(segment);
        }
        Some(Self { per_joint })
    }

    /// Distance from `x` to the nearest bone of `joint`.
    fn distance(&self, joint: usize, x: DVec3) -> f64 {
        self.per_joint[joint]
            .iter()
            .map(|s| s.closest_point(x).distance(x))
            .fold(f64::INFINITY, f64::min)
    }
}

/// An additive mask `[V, J]` (0 on candidates, −∞ elsewhere) for the lists `sets`.
#[must_use]
pub fn additive_mask(sets: &[Vec<u16>], joints: usize) -> Vec<f32> {
    let mut mask = vec![f32::NEG_INFINITY; sets.len() * joints];
    for (row, set) in mask.chunks_mut(joints.max(1)).zip(sets) {
        for &j in set {
            if let Some(m) = row.get_mut(j as usize) {
                *m = 0.0;
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat, Vec3};

    use skinfield_formats::math::Transform;

    /// root → a → b → c, root → d.
    fn skeleton() -> Skeleton {
        let t = Transform {
            translation: Vec3::Y,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        };
        Skeleton::new(
            ["root", "a", "b", "c", "d"].map(String::from).to_vec(),
            vec![None, Some(0), Some(1), Some(2), Some(0)],
            vec![t; 5],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap()
    }

    #[test]
    fn support_first_then_skeleton_neighbours_up_to_k() {
        let s = skeleton();
        // Vertex 0: all on b → b, then its parent a and child c.
        // Vertex 1: a 0.6, root 0.395, d 0.005 (below the threshold) → a, root, then a's
        // parent (root, present), a's child b, root's children (a present) d.
        let init = [
            0.0, 0.0, 1.0, 0.0, 0.0, //
            0.395, 0.6, 0.0, 0.0, 0.005,
        ];
        let at = [Vec3::ZERO; 2];
        let sets = candidate_sets(&init, &s, &at, 8, f32::INFINITY);
        assert_eq!(sets[0], vec![1, 2, 3]);
        assert_eq!(sets[1], vec![0, 1, 2, 4]);
        // With k = 2 only the support survives.
        let sets = candidate_sets(&init, &s, &at, 2, f32::INFINITY);
        assert_eq!(sets[0], vec![1, 2]);
        assert_eq!(sets[1], vec![0, 1]);
        // A vertex without any weight above the threshold keeps its strongest joint.
        let flat = [0.2; 5];
        let sets = candidate_sets(&flat, &s, &at[..1], 1, f32::INFINITY);
        assert_eq!(sets[0], vec![0]);
    }

    #[test]
    fn neighbours_join_only_within_reach_of_the_support() {
        // Heads on the y axis: root 1, a 2, b 3, c 4 (d at 2, a leaf beside a). A point 0.1
        // beside a's bone (2 → 3) with all its weight on a: a's child b has its bone from 3 up
        // (0.81 away, 8 times), a's parent root its bones up to 2 (0.22 away, 2.2 times).
        let s = skeleton();
        let mut init = [0.0; 5];
        init[1] = 1.0;
        let at = [Vec3::new(0.1, 2.2, 0.0)];
        assert_eq!(candidate_sets(&init, &s, &at, 8, 2.0)[0], vec![1]);
        assert_eq!(candidate_sets(&init, &s, &at, 8, 3.0)[0], vec![0, 1]);
        assert_eq!(candidate_sets(&init, &s, &at, 8, 9.0)[0], vec![0, 1, 2]);
        assert_eq!(
            candidate_sets(&init, &s, &at, 8, f32::INFINITY)[0],
            vec![0, 1, 2]
        );
    }

    #[test]
    fn the_mask_is_zero_on_candidates() {
        let m = additive_mask(&[vec![0, 2], vec![1]], 3);
        assert_eq!(m[0], 0.0);
        assert_eq!(m[1], f32::NEG_INFINITY);
        assert_eq!(m[2], 0.0);
        assert_eq!(&m[3..], &[f32::NEG_INFINITY, 0.0, f32::NEG_INFINITY]);
    }
}
