//! A zero-phase Gaussian filter over a tracked motion, clip by clip.
//!
//! Why: the tracker fits every frame on its own (its temporal term only looks back one frame),
//! so the detections' noise reaches each frame's pose independently, and SkinNet trained on
//! noisy poses learns weights blurred by that noise, a bias that more frames do not average
//! away (`docs/experiments/tracking.md`: CesiumMan at 2 px on 256² images, 160 training frames,
//! 1.31× the true-motion model; the same motion filtered with σ = 2 frames, 1.07×). A video
//! samples a movement many times, so neighbouring frames see nearly the same pose with
//! independent noise, and averaging them removes most of it.
//!
//! Formulation, and why each choice:
//! - *Zero phase*: a symmetric window about each frame, so a pose is never pulled towards the
//!   past (the causal temporal term's lag) and a motion linear in time (a constant turn rate, a
//!   constant velocity) passes unchanged.
//! - *Shrinking windows at a clip's ends*: at `k` frames from an end the window's radius is
//!   `k`, so it stays symmetric and linear motion passes unchanged there too; the first and
//!   last frames of a clip are kept as tracked. A window never crosses a clip boundary (clips
//!   are different movements).
//! - *Rotations*: the normalised weighted sum of the window's quaternions, each signed towards
//!   the centre frame's (the chordal mean). For the spread of a window (a few degrees) it
//!   equals the geodesic mean to second order, and for rotations about one axis at a constant
//!   rate it is exact by symmetry. Translations and scales: the weighted mean.
//! - *Weights*: `exp(−k² / 2σ²)` for `|k| ≤ ⌈3σ⌉` (then the window's radius), normalised.
//!
//! Only for captures whose consecutive frames are close in time (a video's frames, dozens per
//! movement): on a capture of sparse frames a tenth of a second apart the window would average
//! different poses.

use std::ops::Range;

use glam::{DQuat, DVec3};
use skinfield_formats::Pose;
use skinfield_formats::math::Transform;

/// The largest σ accepted, in frames: far beyond any useful filter, and a bound on the window.
pub const MAX_FILTER_SIGMA_FRAMES: f64 = 1000.0;

/// Why a filter or its input was refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FilterError {
    /// σ is not a finite number in `[0, MAX_FILTER_SIGMA_FRAMES]`.
    #[error("filter σ {0} frames: must be finite, ≥ 0 and ≤ {MAX_FILTER_SIGMA_FRAMES}")]
    Sigma(f64),
    /// A run of frames reaches beyond the motion.
    #[error("clip frames {first}..{end} beyond the motion's {frames} frames")]
    Run {
        /// First frame of the run.
        first: usize,
        /// One past its last frame.
        end: usize,
        /// Frames in the motion.
        frames: usize,
    },
    /// A pose has another joint count than the first.
    #[error("frame {frame} has {found} joints, frame 0 has {expected}")]
    JointCount {
        /// The frame.
        frame: usize,
        /// The first frame's joint count.
        expected: usize,
        /// This frame's.
        found: usize,
    },
}

/// A zero-phase Gaussian filter of a motion over time (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionFilter {
    sigma_frames: f64,
}

impl MotionFilter {
    /// A filter of standard deviation `sigma_frames` frames; 0 leaves every pose as it is.
    ///
    /// # Errors
    /// [`FilterError::Sigma`] when σ is not finite, negative or above
    /// [`MAX_FILTER_SIGMA_FRAMES`].
    pub fn new(sigma_frames: f64) -> Result<Self, FilterError> {
        if !(0.0..=MAX_FILTER_SIGMA_FRAMES).contains(&sigma_frames) {
            return Err(FilterError::Sigma(sigma_frames));
        }
        Ok(Self { sigma_frames })
    }

    /// The standard deviation, in frames.
    #[must_use]
    pub fn sigma_frames(&self) -> f64 {
        self.sigma_frames
    }

    /// The window's radius away from a clip's ends: `⌈3σ⌉` frames.
    #[must_use]
    pub fn radius(&self) -> usize {
        // σ ≤ MAX_FILTER_SIGMA_FRAMES, so the cast is exact.
        (3.0 * self.sigma_frames).ceil() as usize
    }

    /// `poses` with every frame of each run in `runs` filtered within its run; frames outside
    /// every run are copied. Runs should not overlap (a frame in two is filtered in the last).
    ///
    /// # Errors
    /// [`FilterError::Run`] for a run beyond `poses`, [`FilterError::JointCount`] when the
    /// poses' joint counts differ.
    pub fn apply(&self, poses: &[Pose], runs: &[Range<usize>]) -> Result<Vec<Pose>, FilterError> {
        let joints = poses.first().map_or(0, |p| p.locals.len());
        if let Some((frame, p)) = poses
            .iter()
            .enumerate()
            .find(|(_, p)| p.locals.len() != joints)
        {
            return Err(FilterError::JointCount {
                frame,
                expected: joints,
                found: p.locals.len(),
            });
        }
        if let Some(run) = runs.iter().find(|r| r.end > poses.len()) {
            return Err(FilterError::Run {
                first: run.start,
                end: run.end,
                frames: poses.len(),
            });
        }
        let mut out = poses.to_vec();
        let mut weights = Vec::with_capacity(2 * self.radius() + 1);
        for run in runs {
            for t in run.clone() {
                let radius = self.radius().min(t - run.start).min(run.end - 1 - t);
                if radius == 0 {
                    continue;
                }
                weights.clear();
                weights.extend((0..=2 * radius).map(|i| {
                    let k = i as f64 - radius as f64;
                    (-0.5 * k * k / (self.sigma_frames * self.sigma_frames)).exp()
                }));
                let total: f64 = weights.iter().sum();
                weights.iter_mut().for_each(|w| *w /= total);
                let window = &poses[t - radius..=t + radius];
                for (j, local) in out[t].locals.iter_mut().enumerate() {
                    *local = mean_transform(window, j, &weights, &poses[t].locals[j]);
                }
            }
        }
        Ok(out)
    }
}

/// The weighted mean of joint `j`'s local transform over `window` (`weights` sum to 1),
/// rotations signed towards `centre`'s.
fn mean_transform(window: &[Pose], j: usize, weights: &[f64], centre: &Transform) -> Transform {
    let c = centre.rotation.as_dquat();
    let (mut q, mut translation, mut scale) = (
        DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        DVec3::ZERO,
        DVec3::ZERO,
    );
    for (pose, &w) in window.iter().zip(weights) {
        let local = &pose.locals[j];
        let r = local.rotation.as_dquat();
        let signed = if r.dot(c) < 0.0 { -r } else { r };
        q += signed * w;
        translation += local.translation.as_dvec3() * w;
        scale += local.scale.as_dvec3() * w;
    }
    // The signed sum has the centre's own weight along `c`, so it cannot vanish for windows
    // of unit quaternions within a half turn of the centre; a degenerate one keeps the centre.
    let rotation = if q.length() > 1e-9 { q.normalize() } else { c };
    Transform {
        translation: translation.as_vec3(),
        rotation: rotation.as_quat(),
        scale: scale.as_vec3(),
    }
}

#[cfg(test)]
// A list of one run (one clip) is what these tests mean, not a range in a Vec by mistake.
#[allow(clippy::single_range_in_vec_init)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;

    fn pose(rotations: &[Quat], translation: Vec3) -> Pose {
        Pose {
            locals: rotations
                .iter()
                .map(|&rotation| Transform {
                    translation,
                    rotation,
                    scale: Vec3::ONE,
                })
                .collect(),
        }
    }

    fn assert_close(a: &Pose, b: &Pose, tolerance: f32) {
        for (x, y) in a.locals.iter().zip(&b.locals) {
            assert!(
                x.translation.distance(y.translation) < tolerance,
                "{x:?} {y:?}"
            );
            assert!(
                x.rotation.dot(y.rotation).abs() > 1.0 - tolerance,
                "{x:?} {y:?}"
            );
            assert!(x.scale.distance(y.scale) < tolerance, "{x:?} {y:?}");
        }
    }

    /// Filtering `poses` as one clip with σ = `sigma` leaves every frame within `tolerance`.
    fn assert_passes_unchanged(poses: &[Pose], sigma: f64, tolerance: f32) {
        let out = MotionFilter::new(sigma)
            .unwrap()
            .apply(poses, &[0..poses.len()])
            .unwrap();
        for (a, b) in out.iter().zip(poses) {
            assert_close(a, b, tolerance);
        }
    }

    #[test]
    fn a_constant_motion_is_unchanged_whatever_the_quaternions_signs() {
        let q = Quat::from_axis_angle(Vec3::new(0.3, -0.8, 0.5).normalize(), 0.7);
        let poses: Vec<Pose> = (0..20)
            .map(|t| {
                let signed = if t % 3 == 0 { -q } else { q };
                pose(&[signed, Quat::IDENTITY], Vec3::new(0.1, 0.9, -0.2))
            })
            .collect();
        assert_passes_unchanged(&poses, 2.0, 1e-6);
    }

    #[test]
    fn linear_motion_passes_unchanged_up_to_the_clips_ends() {
        // A constant turn rate about a fixed axis and a constant velocity.
        let axis = Vec3::new(1.0, 2.0, -0.5).normalize();
        let poses: Vec<Pose> = (0..30)
            .map(|t| {
                let a = 0.05 * t as f32;
                pose(
                    &[
                        Quat::from_axis_angle(axis, a),
                        Quat::from_rotation_y(-2.0 * a),
                    ],
                    Vec3::new(0.01 * t as f32, 1.0, -0.02 * t as f32),
                )
            })
            .collect();
        assert_passes_unchanged(&poses, 3.0, 2e-6);
    }

    #[test]
    fn an_impulse_comes_out_as_the_gaussian_kernel() {
        let sigma = 2.0_f64;
        let mut poses = vec![pose(&[Quat::IDENTITY], Vec3::ZERO); 41];
        poses[20].locals[0].translation = Vec3::X;
        let filter = MotionFilter::new(sigma).unwrap();
        assert_eq!(filter.radius(), 6);
        let out = filter.apply(&poses, &[0..41]).unwrap();
        let total: f64 = (-6..=6_i32)
            .map(|k| (-f64::from(k * k) / (2.0 * sigma * sigma)).exp())
            .sum();
        for (t, p) in out.iter().enumerate() {
            let k = t as f64 - 20.0;
            let expected = if k.abs() <= 6.0 {
                (-k * k / (2.0 * sigma * sigma)).exp() / total
            } else {
                0.0
            };
            let got = f64::from(p.locals[0].translation.x);
            assert!(
                (got - expected).abs() < 1e-6,
                "frame {t}: {got} vs {expected}"
            );
        }
    }

    #[test]
    fn clips_are_filtered_apart_and_other_frames_copied() {
        let a = pose(&[Quat::from_rotation_x(0.4)], Vec3::X);
        let b = pose(&[Quat::from_rotation_z(-1.1)], Vec3::Y);
        let c = pose(&[Quat::from_rotation_y(2.0)], Vec3::Z);
        let mut poses = vec![a.clone(); 10];
        poses.extend(vec![b.clone(); 10]);
        poses.push(c.clone());
        let out = MotionFilter::new(4.0)
            .unwrap()
            .apply(&poses, &[0..10, 10..20])
            .unwrap();
        for (t, p) in out.iter().enumerate() {
            let expected = match t {
                0..10 => &a,
                10..20 => &b,
                _ => &c,
            };
            assert_close(p, expected, 1e-6);
        }
    }

    #[test]
    fn noise_shrinks_and_zero_sigma_changes_nothing() {
        // Offsets of ±0.05 rad and ±1 cm in a fixed pattern (two up, three down in every five
        // frames): the filter must take most of them out.
        let truth = Quat::from_rotation_x(0.3);
        let poses: Vec<Pose> = (0..60)
            .map(|t| {
                let sign = if (t * 7919) % 5 < 2 { 1.0 } else { -1.0 };
                pose(
                    &[truth * Quat::from_rotation_z(sign * 0.05)],
                    Vec3::splat(sign * 0.01),
                )
            })
            .collect();
        let error = |ps: &[Pose]| -> f32 {
            ps[10..50]
                .iter()
                .map(|p| p.locals[0].rotation.angle_between(truth))
                .sum::<f32>()
                / 40.0
        };
        let out = MotionFilter::new(2.0)
            .unwrap()
            .apply(&poses, &[0..60])
            .unwrap();
        assert!(
            error(&out) < 0.5 * error(&poses),
            "{} vs {}",
            error(&out),
            error(&poses)
        );
        let same = MotionFilter::new(0.0)
            .unwrap()
            .apply(&poses, &[0..60])
            .unwrap();
        assert_eq!(same, poses);
    }

    #[test]
    fn bad_settings_and_inputs_are_refused() {
        for sigma in [f64::NAN, -0.5, f64::INFINITY, 1e4] {
            assert!(matches!(
                MotionFilter::new(sigma),
                Err(FilterError::Sigma(_))
            ));
        }
        let filter = MotionFilter::new(1.0).unwrap();
        let poses = vec![pose(&[Quat::IDENTITY], Vec3::ZERO); 5];
        assert_eq!(
            filter.apply(&poses, &[0..6]),
            Err(FilterError::Run {
                first: 0,
                end: 6,
                frames: 5
            })
        );
        let mut uneven = poses.clone();
        uneven[3].locals.push(Transform::default());
        assert_eq!(
            filter.apply(&uneven, &[0..5]),
            Err(FilterError::JointCount {
                frame: 3,
                expected: 1,
                found: 2
            })
        );
    }
}
