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
//! centimetres they took off those vertices (`docs/experiments/fidelity.md`).
//!
//! The runtime must rebuild the lists for meshes of any resolution, so the `.skf` stores the
//! training template's vertices as anchors with their lists, and every point takes the list of
//! its nearest anchor (`skinfield_runtime::candidates::nearest_anchors`); training uses the same
//! function for its query points.

use rayon::prelude::*;
use skinfield_formats::Skeleton;

/// Most candidate joints per point.
pub const DEFAULT_CANDIDATES: usize = 8;
/// Initial weights from this up count as support.
pub const SUPPORT_THRESHOLD: f32 = 0.01;

/// The candidate joints of every vertex of dense initial weights `init` (`[V, J]` row-major):
/// each list sorted ascending, between 1 and `k` joints (see the module docs).
#[must_use]
pub fn candidate_sets(init: &[f32], skeleton: &Skeleton, k: usize) -> Vec<Vec<u16>> {
    let j = skeleton.len();
    let k = k.clamp(1, j.max(1));
    let parents = skeleton.parents();
    let children: Vec<Vec<usize>> = (0..j).map(|p| skeleton.children(p).collect()).collect();
    init.par_chunks(j.max(1))
        .map(|w| {
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
            for &s in &support {
                let near = parents[s].into_iter().chain(children[s].iter().copied());
                for n in near {
                    if list.len() >= k {
                        break;
                    }
                    if !list.contains(&n) {
                        list.push(n);
                    }
                }
            }
            list.sort_unstable();
            list.into_iter().map(|i| i as u16).collect()
        })
        .collect()
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
        let sets = candidate_sets(&init, &s, 8);
        assert_eq!(sets[0], vec![1, 2, 3]);
        assert_eq!(sets[1], vec![0, 1, 2, 4]);
        // With k = 2 only the support survives.
        let sets = candidate_sets(&init, &s, 2);
        assert_eq!(sets[0], vec![1, 2]);
        assert_eq!(sets[1], vec![0, 1]);
        // A vertex without any weight above the threshold keeps its strongest joint.
        let flat = [0.2; 5];
        let sets = candidate_sets(&flat, &s, 1);
        assert_eq!(sets[0], vec![0]);
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
