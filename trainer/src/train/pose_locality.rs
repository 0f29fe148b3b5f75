//! Pose locality: a vertex's weights may depend only on the joints that can move it.
//!
//! SkinNet takes the whole pose as input, so nothing stops a foot vertex's weights from
//! following the arms: in the training motions the arms and legs move together (a walk swings
//! both), and whatever the network picked up from that correlation is free to change the foot's
//! weights when a test motion pairs the legs with an arm pose the training never showed. Found
//! on the built-in capture (2026-12-05, `docs/experiments/fidelity.md`): at the near-rest first
//! frame of the high kick, a foot vertex of the model took 0.095 of its weight from the hip
//! (truth: 0); giving the same pose the arms of a training frame instead, and nothing else,
//! took that to 0.020. That vertex was the frame's worst, 1.3 cm from the truth where bone
//! heat's worst was 0.66.
//!
//! The fix, as an augmentation of the training data (the network and the runtime stay as they
//! are): during the image iterations, the input of training vertex `v` in frame `f` holds `f`'s
//! pose features for `v`'s candidate joints ([`crate::candidates`]: the only joints whose
//! transforms move `v`, since every other joint weighs exactly zero there) and, for every
//! other joint, the features of another training frame drawn at random per row. The images
//! are `f`'s and so is the skinning, which the other joints do not enter, so the loss is the
//! same as without the augmentation wherever the weights do not depend on those joints: the
//! augmentation only takes away the freedom to depend on them. STAR (Osman et al., ECCV 2020)
//! makes the same point for pose-corrective blend shapes and restricts each vertex's pose
//! input by construction; doing it by augmentation keeps the `.skf` and every runtime path
//! unchanged. The donors are training frames, so every feature stays inside the range the
//! runtime clamps to ([`super::TrainConfig::clamp_pose_features`]).
//!
//! What it does not do: an augmentation acts only where a loss has a gradient, so vertices that
//! neither the outline nor the Laplacian constrain keep part of what the shared network gives
//! them. Measured with the `pose_leak` example (the weights' change when every vertex's
//! non-candidate joints take other frames' poses), it removes about two fifths of that
//! dependence on the built-in capture (0.096 → 0.054). The exact alternative, masking each
//! vertex's pose input inside the network (a per-vertex pose term in every runtime path), was
//! built and measured: Chamfer 0.631 ± 0.024 cm against the augmentation's 0.613 ± 0.003 on
//! the built-in capture's novel motions and 0.530 against 0.512 on its held-out phases, at
//! 1.3–1.5 times the runtime's MLP time, so it was not kept (`docs/experiments/fidelity.md`).
//! The features of joints outside a point's list carry something the training images reward.

use rand::Rng;

/// The pose input `[B, V, Q]` (row-major, `Q = 3J`) of one image iteration: row `(b, v)`
/// holds `poses[b]`'s features of the joints `relevant` marks for `v` (`[V, J]`) and, for every
/// other joint, those of a donor from `pool` drawn uniformly per row with `rng`.
///
/// # Panics
/// If `relevant` is not `V × J` for some `V`, if a pose or a donor is not `3J` long, or if the
/// pool is empty.
#[must_use]
pub fn local_pose_rows<R: Rng>(
    poses: &[&[f32]],
    pool: &[&[f32]],
    relevant: &[bool],
    joints: usize,
    rng: &mut R,
) -> Vec<f32> {
    let q = 3 * joints;
    assert!(
        joints > 0 && relevant.len().is_multiple_of(joints),
        "relevant is [V, J]"
    );
    assert!(!pool.is_empty(), "no donor frames");
    assert!(
        poses.iter().chain(pool).all(|p| p.len() == q),
        "pose features are 3J long"
    );
    let vertices = relevant.len() / joints;
    let mut rows = Vec::with_capacity(poses.len() * vertices * q);
    for pose in poses {
        for keep in relevant.chunks_exact(joints) {
            let donor = pool[rng.random_range(0..pool.len())];
            for (j, &k) in keep.iter().enumerate() {
                let source = if k { pose } else { donor };
                rows.extend_from_slice(&source[3 * j..3 * j + 3]);
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;

    #[test]
    fn relevant_joints_keep_the_frames_features_and_the_others_come_from_one_donor() {
        let joints = 3;
        let frame: Vec<f32> = (0..9).map(|i| i as f32).collect();
        let donors: Vec<Vec<f32>> = (1..=4)
            .map(|d| (0..9).map(|i| (100 * d + i) as f32).collect())
            .collect();
        let pool: Vec<&[f32]> = donors.iter().map(Vec::as_slice).collect();
        // Vertex 0 moves with joints 0 and 2, vertex 1 with joint 1, vertex 2 with all three.
        let relevant = [
            true, false, true, //
            false, true, false, //
            true, true, true,
        ];
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let rows = local_pose_rows(&[&frame, &frame], &pool, &relevant, joints, &mut rng);
        assert_eq!(rows.len(), 2 * 3 * 9);
        for (r, row) in rows.chunks_exact(9).enumerate() {
            let keep = &relevant[(r % 3) * 3..(r % 3) * 3 + 3];
            for j in 0..joints {
                for a in 0..3 {
                    let got = row[3 * j + a];
                    if keep[j] {
                        assert_eq!(got, (3 * j + a) as f32, "row {r} joint {j}");
                    } else {
                        // A donor's feature of the same joint and axis.
                        assert!(got >= 100.0, "row {r} joint {j}");
                        assert_eq!(got as usize % 100, 3 * j + a);
                    }
                }
            }
            // Every swapped joint of a row comes from the same donor.
            let swapped: std::collections::BTreeSet<usize> = row
                .iter()
                .filter(|&&x| x >= 100.0)
                .map(|&x| x as usize / 100)
                .collect();
            assert!(swapped.len() <= 1, "{row:?}");
        }
        // The same seed draws the same donors; another seed other donors somewhere.
        let again = local_pose_rows(
            &[&frame, &frame],
            &pool,
            &relevant,
            joints,
            &mut ChaCha8Rng::seed_from_u64(7),
        );
        assert_eq!(rows, again);
        let other = (8..40u64).any(|s| {
            local_pose_rows(
                &[&frame, &frame],
                &pool,
                &relevant,
                joints,
                &mut ChaCha8Rng::seed_from_u64(s),
            ) != rows
        });
        assert!(other);
    }
}
