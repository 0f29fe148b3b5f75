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
//!
//! The input is drawn as a [`LocalPoses`]: the frames' poses, the donor pool, a donor per row
//! and each vertex's relevant joints, which the fused op multiplies without writing the
//! `[B, V, 3J]` rows out ([`crate::skinnet::local_poses`]).

pub use crate::skinnet::local_poses::{LocalPoses, LocalPosesError};
