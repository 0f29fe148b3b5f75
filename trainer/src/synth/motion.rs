//! The procedural motion library of the built-in character, as joint angles within the
//! skeleton's limits.
//!
//! Training clips: walk, squat, arm raises with forearm twist (|twist| ≤ 0.8 rad), a lunge on
//! the left leg, a low kick. Test clips are other motions or ranges never seen in training: a
//! high kick (hip flexion up to 1.9 rad; training stays ≤ 1.0), a turn with strongly twisted
//! forearms (|twist| up to 1.5 rad) and a deep lunge on the right leg.
//!
//! [`TestMotions::HeldOutPhases`] replaces the test clips by the training clips sampled halfway
//! between the training frames: poses from the training distribution that training never saw.
//! Comparing a model on both splits separates overfitting the pose dependence (novel poses get
//! worse, held-out phases do not) from a model that is wrong everywhere.

use glam::{Quat, Vec3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_chacha::rand_core::SeedableRng;
use skinfield_formats::{JointDofs, Pose, Skeleton, SkeletonError};

use super::character::joint;

/// Whether a clip is for training or for testing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Training frames.
    Train,
    /// Held-out test frames.
    Test,
}

/// The clips of the library, in the order they are laid out in a capture.
pub const CLIPS: [(&str, Split); 8] = [
    ("walk", Split::Train),
    ("squat", Split::Train),
    ("arm_raise_twist", Split::Train),
    ("lunge_left", Split::Train),
    ("kick_low", Split::Train),
    ("high_kick", Split::Test),
    ("turn_twist", Split::Test),
    ("lunge_right_deep", Split::Test),
];

/// Which poses the test frames hold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TestMotions {
    /// The three test clips, beyond the training ranges (the paper's protocol).
    #[default]
    Novel,
    /// The five training clips at phases halfway between the training frames, with the
    /// training clips' amplitudes: in-distribution, unseen poses.
    HeldOutPhases,
}

/// Joint angles of one frame, addressed by joint and axis index, clamped to the limits.
struct Angles<'a> {
    skeleton: &'a Skeleton,
    offsets: Vec<usize>,
    values: Vec<f32>,
}

impl<'a> Angles<'a> {
    fn new(skeleton: &'a Skeleton) -> Self {
        let mut offsets = Vec::with_capacity(skeleton.len());
        let mut k = 0;
        for d in skeleton.dofs() {
            offsets.push(k);
            k += d.count();
        }
        Self {
            skeleton,
            offsets,
            values: vec![0.0; k],
        }
    }

    /// Sets angle `axis` (index into the joint's axes) of joint `j`, clamped to its limits.
    fn set(&mut self, j: usize, axis: usize, value: f32) {
        let v = match &self.skeleton.dofs()[j] {
            JointDofs::Euler { limits, .. } => value.clamp(limits[axis][0], limits[axis][1]),
            _ => value,
        };
        self.values[self.offsets[j] + axis] = v;
    }

    /// Sets a left/right pair with mirrored sign (the right side's axes point the other way
    /// for arm raises, swings and elbow bends; for legs `mirror` is false).
    fn pair(&mut self, left: usize, right: usize, axis: usize, l: f32, r: f32, mirror: bool) {
        self.set(left, axis, l);
        self.set(right, axis, if mirror { -r } else { r });
    }
}

/// Arms relaxed: lowered by `down` radians from the T-pose, elbows a little bent.
fn rest_arms(a: &mut Angles<'_>, down: f32) {
    use joint::*;
    a.pair(L_SHOULDER, R_SHOULDER, 0, -down, -down, true);
    a.pair(L_ELBOW, R_ELBOW, 0, -0.25, -0.25, true);
}

/// A clip's frame as (root yaw, root offset, angles).
fn frame(skeleton: &Skeleton, clip: &str, s: f32, amp: f32) -> (f32, Vec3, Vec<f32>) {
    use joint::*;
    use std::f32::consts::{PI, TAU};
    let mut a = Angles::new(skeleton);
    let mut yaw = 0.0;
    let mut root = Vec3::ZERO;
    let e = 0.5 - 0.5 * (TAU * s).cos(); // 0 → 1 → 0 envelope
    match clip {
        "walk" => {
            let w = (TAU * s).sin() * 0.5 * amp;
            a.pair(L_HIP, R_HIP, 0, -w, w, false);
            a.pair(
                L_KNEE,
                R_KNEE,
                0,
                0.7 * (TAU * s + 0.6).sin().max(0.0),
                0.7 * (TAU * s + 0.6 + PI).sin().max(0.0),
                false,
            );
            rest_arms(&mut a, 1.25);
            a.pair(L_SHOULDER, R_SHOULDER, 1, 0.35 * w, -0.35 * w, true);
            a.set(SPINE1, 1, 0.15 * w);
            root = Vec3::new(0.0, -0.02 * (2.0 * TAU * s).cos().abs(), 0.4 * s - 0.2);
        }
        "squat" => {
            let d = e * 0.8 * amp;
            a.pair(L_HIP, R_HIP, 0, -1.2 * d, -1.2 * d, false);
            a.pair(L_KNEE, R_KNEE, 0, 2.0 * d, 2.0 * d, false);
            a.pair(L_ANKLE, R_ANKLE, 0, -0.6 * d, -0.6 * d, false);
            a.set(SPINE, 0, 0.4 * d);
            a.pair(L_SHOULDER, R_SHOULDER, 0, -0.3, -0.3, true);
            a.pair(L_SHOULDER, R_SHOULDER, 1, -1.3 * d, -1.3 * d, true);
            root = Vec3::new(0.0, -0.33 * d, -0.08 * d);
        }
        "arm_raise_twist" => {
            let raise = -1.25 + 2.4 * e * amp;
            a.pair(L_SHOULDER, R_SHOULDER, 0, raise, raise, true);
            a.pair(L_ELBOW, R_ELBOW, 0, -0.9 * e, -0.9 * e, true);
            let twist = 0.8 * (TAU * s).sin();
            a.pair(L_FOREARM, R_FOREARM, 0, twist, -twist, false);
            a.pair(L_WRIST, R_WRIST, 0, 0.3 * twist, 0.3 * twist, true);
        }
        "lunge_left" => {
            let d = e * amp;
            a.pair(L_HIP, R_HIP, 0, -d, 0.35 * d, false);
            a.pair(L_KNEE, R_KNEE, 0, 1.2 * d, 0.9 * d, false);
            rest_arms(&mut a, 1.0);
            root = Vec3::new(0.0, -0.2 * d, 0.12 * d);
        }
        "kick_low" => {
            let d = e * amp;
            a.pair(L_HIP, R_HIP, 0, -0.9 * d, 0.0, false);
            a.pair(L_KNEE, R_KNEE, 0, 0.5 * (1.0 - d), 0.1, false);
            rest_arms(&mut a, 0.5);
            a.set(SPINE, 0, -0.1 * d);
        }
        "high_kick" => {
            let d = e * amp;
            a.pair(L_HIP, R_HIP, 0, 0.15 * d, -(1.1 + 0.8 * d) * d, false);
            a.pair(L_KNEE, R_KNEE, 0, 0.2 * d, 0.3 * (1.0 - d), false);
            a.set(SPINE, 0, -0.25 * d);
            a.pair(L_SHOULDER, R_SHOULDER, 0, 0.2, 0.2, true);
            a.pair(L_ELBOW, R_ELBOW, 0, -1.2 * d, -1.2 * d, true);
        }
        "turn_twist" => {
            yaw = 0.9 * PI * s;
            a.pair(L_SHOULDER, R_SHOULDER, 0, -0.4, -0.4, true);
            a.pair(L_SHOULDER, R_SHOULDER, 1, -1.1, -1.1, true);
            a.pair(L_ELBOW, R_ELBOW, 0, -1.3 * e, -1.3 * e, true);
            let twist = 1.5 * (TAU * s).sin() * amp;
            a.pair(L_FOREARM, R_FOREARM, 0, twist, -twist, false);
            a.set(SPINE1, 1, 0.3 * (TAU * s).sin());
            a.pair(L_KNEE, R_KNEE, 0, 0.3 * e, 0.3 * e, false);
        }
        _ => {
            // lunge_right_deep
            let d = e * amp;
            a.pair(L_HIP, R_HIP, 0, 0.5 * d, -1.4 * d, false);
            a.pair(L_KNEE, R_KNEE, 0, 1.3 * d, 1.9 * d, false);
            a.pair(L_SHOULDER, R_SHOULDER, 0, 0.0, 0.0, true);
            a.pair(L_ELBOW, R_ELBOW, 0, -1.6 * d, -1.6 * d, true);
            root = Vec3::new(0.0, -0.33 * d, 0.15 * d);
        }
    }
    (yaw, root, a.values)
}

/// One frame of the motion: its clip, split and pose.
#[derive(Clone, Debug)]
pub struct MotionFrame {
    /// Clip index into [`CLIPS`].
    pub clip: usize,
    /// Training or test frame (a training clip's held-out phases are test frames).
    pub split: Split,
    /// The pose.
    pub pose: Pose,
}

/// All clips, `train_frames` frames per training clip and `test_frames` per test clip (with
/// [`TestMotions::HeldOutPhases`], per training clip), training frames first; `seed` varies
/// each clip's amplitude by ±8 % and the subject's starting heading. The training frames do not
/// depend on `test_motions`.
pub fn library(
    skeleton: &Skeleton,
    train_frames: usize,
    test_frames: usize,
    test_motions: TestMotions,
    seed: u64,
) -> Result<Vec<MotionFrame>, SkeletonError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let heading: f32 = rng.random_range(-0.3..0.3);
    // Drawn for every clip in order, whatever the split, so both test choices share the
    // training clips' amplitudes.
    let amplitudes: Vec<f32> = CLIPS.iter().map(|_| rng.random_range(0.92..1.08)).collect();
    let sample = |c: usize, s: f32, split: Split| -> Result<MotionFrame, SkeletonError> {
        let (yaw, root, angles) = frame(skeleton, CLIPS[c].0, s, amplitudes[c]);
        let pose =
            skeleton.pose_from_angles(Quat::from_rotation_y(heading + yaw), root, &angles)?;
        Ok(MotionFrame {
            clip: c,
            split,
            pose,
        })
    };
    let clips_of = |split: Split| (0..CLIPS.len()).filter(move |&c| CLIPS[c].1 == split);
    // Phases sample a clip's cycle without repeating its first frame at the end.
    let spread = |i: usize, n: usize| (i as f32 + 0.5) / n as f32;
    // Training phase k sits at (k + ½)/T; (k + 1)/T is midway to the next. Distinct while
    // `test_frames ≤ train_frames` (checked by the config).
    let between = |i: usize, n: usize| (i * train_frames / n + 1) as f32 / train_frames as f32;
    let (test_clips, test_phase): (Split, &dyn Fn(usize, usize) -> f32) = match test_motions {
        TestMotions::Novel => (Split::Test, &spread),
        TestMotions::HeldOutPhases => (Split::Train, &between),
    };
    let mut out = Vec::new();
    for (clips, n, phase, split) in [
        (
            Split::Train,
            train_frames,
            &spread as &dyn Fn(usize, usize) -> f32,
            Split::Train,
        ),
        (test_clips, test_frames, test_phase, Split::Test),
    ] {
        for c in clips_of(clips) {
            for i in 0..n {
                out.push(sample(c, phase(i, n), split)?);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::character::build_skeleton;
    use skinfield_formats::math::quat_to_rotvec;

    fn max_flexion(frames: &[MotionFrame], skeleton: &Skeleton, j: usize, split: Split) -> f32 {
        frames
            .iter()
            .filter(|f| f.split == split)
            .map(|f| {
                quat_to_rotvec(
                    skeleton.bind_local()[j].rotation.inverse() * f.pose.locals[j].rotation,
                )
                .length()
            })
            .fold(0.0, f32::max)
    }

    #[test]
    fn test_poses_go_beyond_the_training_ranges() {
        let s = build_skeleton().unwrap();
        let frames = library(&s, 12, 8, TestMotions::Novel, 5).unwrap();
        assert_eq!(frames.len(), 5 * 12 + 3 * 8);
        for j in [joint::R_HIP, joint::L_FOREARM] {
            let train = max_flexion(&frames, &s, j, Split::Train);
            let test = max_flexion(&frames, &s, j, Split::Test);
            assert!(
                test > train + 0.3,
                "joint {j}: test {test} vs train {train}"
            );
        }
        // Same seed, same poses.
        let again = library(&s, 12, 8, TestMotions::Novel, 5).unwrap();
        assert!(frames.iter().zip(&again).all(|(a, b)| a.pose == b.pose));
    }

    #[test]
    fn held_out_phases_share_the_training_frames_and_stay_in_range() {
        let s = build_skeleton().unwrap();
        let novel = library(&s, 16, 8, TestMotions::Novel, 3).unwrap();
        let held = library(&s, 16, 8, TestMotions::HeldOutPhases, 3).unwrap();
        let train = |f: &[MotionFrame]| -> Vec<Pose> {
            f.iter()
                .filter(|f| f.split == Split::Train)
                .map(|f| f.pose.clone())
                .collect()
        };
        assert_eq!(train(&novel), train(&held));
        let tests: Vec<&MotionFrame> = held.iter().filter(|f| f.split == Split::Test).collect();
        assert_eq!(tests.len(), 5 * 8);
        assert!(tests.iter().all(|f| CLIPS[f.clip].1 == Split::Train));
        // Unseen: no test pose equals a training pose.
        for t in &tests {
            assert!(held.iter().take(5 * 16).all(|f| f.pose != t.pose));
        }
        // In range: a held-out phase flexes no joint beyond the training maximum (its
        // neighbours bracket it), unlike the novel clips.
        for j in [joint::R_HIP, joint::L_FOREARM] {
            let train_max = max_flexion(&held, &s, j, Split::Train);
            let held_max = max_flexion(&held, &s, j, Split::Test);
            let novel_max = max_flexion(&novel, &s, j, Split::Test);
            assert!(
                held_max <= train_max + 0.1,
                "joint {j}: {held_max} vs {train_max}"
            );
            assert!(
                novel_max > train_max + 0.3,
                "joint {j}: {novel_max} vs {train_max}"
            );
        }
    }
}
