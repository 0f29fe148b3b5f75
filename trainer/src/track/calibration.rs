//! Skeleton calibration: the length of every bone, shared by every frame, fitted to the
//! keypoints.
//!
//! Why: the tracker poses the template's skeleton, whose bones have the lengths of its bind
//! pose, and the person (or the clip) may not. CesiumMan's only clip moves both shoulders 3 mm
//! towards the spine and the second spine joint 1 mm forward, in every frame, relative to the
//! bind pose. Joint angles cannot shorten a bone, so the per-frame fit spreads that error over
//! the arms' rotations the same way in every frame, and SkinNet trained on such motion learns
//! weights that explain it and do not transfer (`docs/experiments/tracking.md`).
//!
//! Formulation: the bone lengths (each non-root joint's bind-pose local translation lengthened
//! or shortened along itself) and the poses of up to
//! [`TrackOptions::calibration_frames`](super::TrackOptions::calibration_frames) frames spread
//! over the capture minimise together the frames' keypoint losses (confidence- and
//! robust-weighted reprojection errors, Eq. 6, and the joint-limit prior, Eq. 7; no temporal
//! term, so the frames are independent given the lengths), plus a weak quadratic prior,
//! [`BONE_PRIOR`] px² per (1 % of the skeleton's size)², that keeps lengths the detections do
//! not see at the template's and makes the problem well posed.
//!
//! - *Together, not in alternation*: with the poses held, the fits have already absorbed the
//!   lengths' error into the angles; alternating recovered half of CesiumMan's shoulders in
//!   four rounds. The normal equations have the bundle-adjustment structure (a block per
//!   frame, coupled only through the lengths), solved by the Schur complement on the lengths:
//!   Levenberg–Marquardt with the tracker's chain-rule Jacobian for the poses and an exact one
//!   for the lengths (a length moves its whole subtree by one world vector), the robust
//!   (Geman–McClure) weights at the tracker's final scale recomputed once.
//! - *Only lengths*: an offset across a bone is, but for the side points, a constant turn of
//!   its parent, which the per-frame angles already have. Free 3D offsets traded with those
//!   turns on CesiumMan (exact detections: the elbows moved 2 mm across their bones while the
//!   shoulders' 3 mm came back as 2.5 mm), and lengths are what a person's skeleton differs in.
//! - Each frame's root translation comes from the alignment layer at every evaluation, so a
//!   length a root translation can explain (a bone from a root that does not turn) stays with
//!   the root. Translating joints ([`super::Kinematics::with_translating_joints`]) have no
//!   length.
//!
//! `track_capture` fits the frames to the keypoints, calibrates, and fits again (with the
//! temporal and silhouette terms) on the calibrated skeleton.

use glam::{DQuat, DVec3};

use super::dense::{cholesky_factor, cholesky_substitute, normal_equations};
use super::solve::{Detection, FrameFit, Observation, TrackError, Tracker};

/// Frames a calibration uses at most by default (evenly spread): 32 frames of a dozen views see
/// every bone hundreds of times, enough from exact detections; with noisy detections the
/// lengths' error shrinks with more (`docs/experiments/tracking.md`).
pub const DEFAULT_CALIBRATION_FRAMES: usize = 32;
/// Weight of the prior that holds each bone's change of length at zero: px² per (1 % of the
/// skeleton's bind-pose size)². From exact detections of eight frames it pulls a changed
/// length back by about 0.1 % of the change (1.0 pulled by 0.5–1 %).
pub const BONE_PRIOR: f64 = 0.1;
/// Levenberg–Marquardt iterations per reweighting round (cap).
const ITERATIONS: usize = 30;
/// Central-difference step of the lengths (1 % of the skeleton's size) where the alignment
/// layer has no solution and their exact derivatives do not exist.
const STEP: f64 = 1e-6;

/// The result of [`Tracker::calibrate_bones`].
#[derive(Clone, Debug, PartialEq)]
pub struct BoneCalibration {
    /// One offset per joint (in its parent's frame, along its bone, skeleton units; zero for
    /// the roots): the tracker's offsets plus the change this calibration found.
    pub offsets: Vec<DVec3>,
    /// RMS reprojection error (pixels) of the calibration frames at their fits, weighted by
    /// confidence and the final robust weights.
    pub rms_before_px: f64,
    /// The same at the calibrated lengths and the poses refitted with them.
    pub rms_after_px: f64,
    /// Frames used.
    pub frames: usize,
    /// Wall-clock seconds of the calibration (the joint fit of lengths and poses, not the
    /// tracking before and after it).
    pub seconds: f64,
}

/// One frame of a calibration: its observations, robust weights and pose parameters (the
/// root's rotation vector relative to `root0`, then the angles).
struct Frame {
    obs: Vec<Observation>,
    robust: Vec<f64>,
    root0: DQuat,
    params: Vec<f64>,
}

/// The lengths' parametrisation: one parameter per non-root joint with a bone, in units of
/// 1 % of the skeleton's size, along the bone.
struct Lengths {
    /// Joint and the bone's unit direction in the parent's frame.
    movable: Vec<(usize, DVec3)>,
    unit: f64,
    base: Vec<DVec3>,
}

impl Lengths {
    /// Every bone of `tracker`'s skeleton that has a length, from its current offsets.
    fn of(tracker: &Tracker<'_>) -> Self {
        let k = &tracker.kinematics;
        // A joint that translates per frame has no fixed length.
        let translating = k.translating_joints();
        Self {
            movable: (0..k.joint_count())
                .filter(|&j| k.parents()[j].is_some())
                .filter(|j| !translating.contains(j))
                .filter_map(|j| {
                    let bone = k.bind_translation(j);
                    (bone.length() > 1e-12).then(|| (j, bone.normalize()))
                })
                .collect(),
            unit: 0.01 * k.bind_size(),
            base: k.bone_offsets().to_vec(),
        }
    }

    fn offsets(&self, params: &[f64]) -> Vec<DVec3> {
        let mut out = self.base.clone();
        for (&(j, direction), p) in self.movable.iter().zip(params) {
            out[j] += direction * (p * self.unit);
        }
        out
    }
}

impl Frame {
    /// Residuals at `params` on `tracker`'s skeleton.
    fn residuals(&self, tracker: &Tracker<'_>, params: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; tracker.frame_residual_count(&self.obs)];
        tracker.frame_residuals(&self.obs, &self.robust, self.root0, params, &mut out, None);
        out
    }

    /// Sum of the squared keypoint residuals in `r` and of their weights.
    fn keypoint_energy(&self, r: &[f64]) -> (f64, f64) {
        let sum = r[..2 * self.obs.len()].iter().map(|x| x * x).sum();
        let weight = self
            .obs
            .iter()
            .zip(&self.robust)
            .map(|(o, w)| o.confidence * w)
            .sum();
        (sum, weight)
    }

    /// Geman–McClure weights, at the tracker's final scale, of the reprojection errors at the
    /// frame's parameters.
    fn reweigh(&mut self, tracker: &Tracker<'_>) {
        let errors = tracker.frame_errors(&self.obs, self.root0, &self.params);
        self.robust = tracker.robust_weights(&errors, tracker.options.robust_scale_px);
    }
}

/// One frame's linearisation: `U = JₓᵀJₓ`, `W = JₓᵀJ_b`, `Jₓᵀr`, and its share of `J_bᵀJ_b`,
/// `J_bᵀr`.
struct Block {
    u: Vec<f64>,
    w: Vec<f64>,
    gx: Vec<f64>,
    v: Vec<f64>,
    gb: Vec<f64>,
}

impl Tracker<'_> {
    /// The bone lengths (as offsets) that best explain the detections of `frames` (each
    /// frame's detections, one row per view as [`Self::fit`] takes them, and its fit), fitted
    /// together with the frames' poses, starting from the tracker's current offsets and the
    /// fits. See the [module docs](self).
    ///
    /// # Errors
    /// A frame's detections do not match the tracker's cameras or landmarks
    /// ([`TrackError::ViewCount`], [`TrackError::LandmarkCount`], [`TrackError::NonFinite`]).
    pub fn calibrate_bones(
        &self,
        frames: &[(&[Vec<Option<Detection>>], &FrameFit)],
    ) -> Result<BoneCalibration, TrackError> {
        let start_time = std::time::Instant::now();
        let wanted = self.options.calibration_frames;
        let picked: Vec<usize> = if wanted == 0 || frames.len() <= wanted {
            (0..frames.len()).collect()
        } else {
            (0..wanted).map(|i| i * frames.len() / wanted).collect()
        };
        let mut data = Vec::with_capacity(picked.len());
        for &i in &picked {
            let (detections, fit) = frames[i];
            let obs = self.observations(detections)?;
            let mut params = vec![0.0; 3];
            params.extend_from_slice(&fit.angles);
            data.push(Frame {
                robust: vec![1.0; obs.len()],
                obs,
                root0: fit.root_rotation,
                params,
            });
        }
        let lengths = Lengths::of(self);
        let start: Vec<Vec<f64>> = data.iter().map(|f| f.params.clone()).collect();
        let mut b = vec![0.0; lengths.movable.len()];
        for frame in &mut data {
            frame.reweigh(self);
        }
        for round in 0..2 {
            self.joint_solve(&lengths, &mut data, &mut b);
            if round == 0 {
                let calibrated = self.clone().with_bone_offsets(&lengths.offsets(&b));
                for frame in &mut data {
                    frame.reweigh(&calibrated);
                }
            }
        }
        let rms = |tracker: &Tracker<'_>, params: &[Vec<f64>]| {
            let (mut sum, mut weight) = (0.0, 0.0);
            for (frame, p) in data.iter().zip(params) {
                let (s, w) = frame.keypoint_energy(&frame.residuals(tracker, p));
                sum += s;
                weight += w;
            }
            (sum / f64::max(weight, 1e-300)).sqrt()
        };
        let calibrated = self.clone().with_bone_offsets(&lengths.offsets(&b));
        let fitted: Vec<Vec<f64>> = data.iter().map(|f| f.params.clone()).collect();
        Ok(BoneCalibration {
            offsets: lengths.offsets(&b),
            rms_before_px: rms(self, &start),
            rms_after_px: rms(&calibrated, &fitted),
            frames: picked.len(),
            seconds: start_time.elapsed().as_secs_f64(),
        })
    }

    /// Levenberg–Marquardt on the lengths `b` and every frame's pose together, by the Schur
    /// complement on the lengths.
    fn joint_solve(&self, lengths: &Lengths, data: &mut [Frame], b: &mut [f64]) {
        let nb = b.len();
        let with = |b: &[f64]| self.clone().with_bone_offsets(&lengths.offsets(b));
        let cost_of = |data: &[Frame], tracker: &Tracker<'_>, b: &[f64], params: &[&[f64]]| {
            let mut c = BONE_PRIOR * b.iter().map(|x| x * x).sum::<f64>();
            for (frame, p) in data.iter().zip(params) {
                c += frame
                    .residuals(tracker, p)
                    .iter()
                    .map(|x| x * x)
                    .sum::<f64>();
            }
            0.5 * c
        };
        let mut mu = 1e-3;
        let mut tracker = with(b);
        let mut cost = cost_of(
            data,
            &tracker,
            b,
            &data.iter().map(|f| f.params.as_slice()).collect::<Vec<_>>(),
        );
        for _ in 0..ITERATIONS {
            let blocks: Vec<Block> = data
                .iter()
                .map(|frame| self.linearise(frame, &tracker, lengths, b))
                .collect();
            let mut v = vec![0.0; nb * nb];
            let mut gb: Vec<f64> = b.iter().map(|x| BONE_PRIOR * x).collect();
            for block in &blocks {
                for (a, x) in v.iter_mut().zip(&block.v) {
                    *a += x;
                }
                for (a, x) in gb.iter_mut().zip(&block.gb) {
                    *a += x;
                }
            }
            for i in 0..nb {
                v[i * nb + i] += BONE_PRIOR;
            }
            let gradient = gb
                .iter()
                .chain(blocks.iter().flat_map(|k| k.gx.iter()))
                .map(|g| g.abs())
                .fold(0.0, f64::max);
            if gradient < 1e-12 {
                return;
            }
            let mut improved = false;
            for _ in 0..12 {
                match self.damped_step(&blocks, &v, &gb, mu) {
                    Some((db, dx)) => {
                        let b_try: Vec<f64> = b.iter().zip(&db).map(|(x, d)| x - d).collect();
                        let p_try: Vec<Vec<f64>> = data
                            .iter()
                            .zip(&dx)
                            .map(|(f, d)| f.params.iter().zip(d).map(|(x, d)| x - d).collect())
                            .collect();
                        let t_try = with(&b_try);
                        let c = cost_of(
                            data,
                            &t_try,
                            &b_try,
                            &p_try.iter().map(Vec::as_slice).collect::<Vec<_>>(),
                        );
                        if c < cost {
                            let rel = (cost - c) / cost.max(1e-300);
                            b.copy_from_slice(&b_try);
                            for (f, p) in data.iter_mut().zip(p_try) {
                                f.params = p;
                            }
                            tracker = t_try;
                            cost = c;
                            mu = (mu * 0.3).max(1e-12);
                            improved = true;
                            if rel < 1e-12 {
                                return;
                            }
                            break;
                        }
                        mu *= 10.0;
                    }
                    None => mu *= 10.0,
                }
            }
            if !improved {
                return;
            }
        }
    }

    /// One frame's [`Block`] at its parameters on `tracker` (this tracker at lengths `b`).
    /// The lengths' derivatives are exact ([`Tracker::frame_length_jacobian`]); where the
    /// alignment layer has no solution they are central differences of the skeletons with one
    /// length moved either way.
    fn linearise(
        &self,
        frame: &Frame,
        tracker: &Tracker<'_>,
        lengths: &Lengths,
        b: &[f64],
    ) -> Block {
        let p = frame.params.len();
        let nb = b.len();
        let m = tracker.frame_residual_count(&frame.obs);
        let (mut r, mut jx) = (vec![0.0; m], vec![0.0; m * p]);
        tracker.frame_residuals(
            &frame.obs,
            &frame.robust,
            frame.root0,
            &frame.params,
            &mut r,
            Some(&mut jx),
        );
        let mut jb = vec![0.0; m * nb];
        let exact = tracker.frame_length_jacobian(
            (&frame.obs, &frame.robust, frame.root0),
            &frame.params,
            &lengths.movable,
            lengths.unit,
            &mut jb,
        );
        if !exact {
            let with = |k: usize, h: f64| {
                let mut moved = b.to_vec();
                moved[k] += h;
                self.clone().with_bone_offsets(&lengths.offsets(&moved))
            };
            for k in 0..nb {
                let plus = frame.residuals(&with(k, STEP), &frame.params);
                let minus = frame.residuals(&with(k, -STEP), &frame.params);
                for row in 0..m {
                    jb[row * nb + k] = (plus[row] - minus[row]) / (2.0 * STEP);
                }
            }
        }
        let (u, gx) = normal_equations(&jx, &r, p);
        let (v, gb) = normal_equations(&jb, &r, nb);
        let mut w = vec![0.0; p * nb];
        for row in 0..m {
            let a = &jx[row * p..(row + 1) * p];
            let c = &jb[row * nb..(row + 1) * nb];
            for i in 0..p {
                if a[i] == 0.0 {
                    continue;
                }
                for k in 0..nb {
                    w[i * nb + k] += a[i] * c[k];
                }
            }
        }
        Block { u, w, gx, v, gb }
    }

    /// The damped Gauss–Newton step (lengths, then each frame's) by the Schur complement;
    /// `None` when a system is not positive definite.
    fn damped_step(
        &self,
        blocks: &[Block],
        v: &[f64],
        gb: &[f64],
        mu: f64,
    ) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
        let nb = gb.len();
        let mut s = v.to_vec();
        for i in 0..nb {
            s[i * nb + i] += mu * v[i * nb + i].max(1e-9);
        }
        let mut rhs = gb.to_vec();
        // Per frame: U⁻¹ W (column by column) and U⁻¹ gₓ.
        let mut solved = Vec::with_capacity(blocks.len());
        for block in blocks {
            let p = block.gx.len();
            let mut l = block.u.clone();
            for i in 0..p {
                l[i * p + i] += mu * block.u[i * p + i].max(1e-9);
            }
            if !cholesky_factor(&mut l, p) {
                return None;
            }
            let mut uw = vec![0.0; p * nb];
            let mut col = vec![0.0; p];
            for k in 0..nb {
                for (i, c) in col.iter_mut().enumerate() {
                    *c = block.w[i * nb + k];
                }
                cholesky_substitute(&l, p, &mut col);
                for (i, c) in col.iter().enumerate() {
                    uw[i * nb + k] = *c;
                }
            }
            let mut ug = block.gx.clone();
            cholesky_substitute(&l, p, &mut ug);
            // S -= Wᵀ U⁻¹ W; rhs -= Wᵀ U⁻¹ gₓ.
            for a in 0..nb {
                for c in 0..nb {
                    let mut sum = 0.0;
                    for i in 0..p {
                        sum += block.w[i * nb + a] * uw[i * nb + c];
                    }
                    s[a * nb + c] -= sum;
                }
                rhs[a] -= ug
                    .iter()
                    .enumerate()
                    .map(|(i, g)| block.w[i * nb + a] * g)
                    .sum::<f64>();
            }
            solved.push((l, ug));
        }
        if !cholesky_factor(&mut s, nb) {
            return None;
        }
        cholesky_substitute(&s, nb, &mut rhs);
        let db = rhs;
        // Each frame's step: U⁻¹ (gₓ − W δb).
        let dx = blocks
            .iter()
            .zip(solved)
            .map(|(block, (l, _))| {
                let p = block.gx.len();
                let mut x: Vec<f64> = (0..p)
                    .map(|i| {
                        block.gx[i] - (0..nb).map(|k| block.w[i * nb + k] * db[k]).sum::<f64>()
                    })
                    .collect();
                cholesky_substitute(&l, p, &mut x);
                x
            })
            .collect();
        Some((db, dx))
    }
}

#[cfg(test)]
mod tests {
    use glam::{DMat4, DQuat, DVec3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use skinfield_formats::{Camera, Skeleton};

    use super::*;
    use crate::synth::character::build_skeleton;
    use crate::synth::rig::camera_rig;
    use crate::track::landmarks::{joint_side_landmark_map, landmarks_of};
    use crate::track::tests::{exact_detections, random_angles};
    use crate::track::{Kinematics, Landmark, TrackOptions};

    /// Detections of every frame, one row per view.
    type Frames = Vec<Vec<Vec<Option<Detection>>>>;

    /// Exact detections by a joint + side-point detector of `person` (the built-in skeleton with
    /// changed bones) in `frames` random poses, and the template skeleton's tracker with its
    /// fits of them.
    fn track<'a>(
        skeleton: &Skeleton,
        person: &Kinematics,
        cameras: &'a [Camera],
        frames: usize,
        seed: u64,
    ) -> (Tracker<'a>, Frames, Vec<FrameFit>) {
        let landmarks: Vec<Landmark> = landmarks_of(&joint_side_landmark_map(skeleton), skeleton)
            .into_iter()
            .map(|(_, l)| l)
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut worlds = vec![DMat4::IDENTITY; skeleton.len()];
        let mut points = vec![DVec3::ZERO; landmarks.len()];
        let detections: Vec<_> = (0..frames)
            .map(|_| {
                let root = DQuat::from_rotation_y(rng.random_range(-3.0..3.0));
                let angles: Vec<f64> = random_angles(skeleton, &mut rng)
                    .iter()
                    .map(|&a| f64::from(a))
                    .collect();
                let shift = DVec3::new(rng.random_range(-0.2..0.2), 0.0, 0.1);
                person.landmarks(root, &angles, &landmarks, &mut worlds, &mut points);
                let world: Vec<DVec3> = points.iter().map(|p| *p + shift).collect();
                exact_detections(cameras, &world, 1.0)
            })
            .collect();
        let tracker = Tracker::new(
            Kinematics::new(skeleton),
            landmarks,
            cameras,
            DVec3::Y,
            TrackOptions::default(),
        );
        let fits = detections
            .iter()
            .map(|d| tracker.fit(d, None).unwrap())
            .collect();
        (tracker, detections, fits)
    }

    /// The exact lengths' derivatives against central differences of the residuals on
    /// skeletons with one length moved either way, at lengths and poses away from the fit,
    /// with side points (landmarks off their joints) and uneven robust weights.
    #[test]
    fn the_length_jacobian_matches_central_differences() {
        let skeleton = build_skeleton().unwrap();
        let rig = camera_rig(6, 256, 256, 1);
        let (tracker, frames, fits) =
            track(&skeleton, &Kinematics::new(&skeleton), &rig.cameras, 2, 11);
        let lengths = Lengths::of(&tracker);
        let nb = lengths.movable.len();
        assert!(nb > 10, "{nb} lengths");
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let b: Vec<f64> = (0..nb).map(|_| rng.random_range(-0.5..0.5)).collect();
        let at = |b: &[f64]| tracker.clone().with_bone_offsets(&lengths.offsets(b));
        for (detections, fit) in frames.iter().zip(&fits) {
            let obs = tracker.observations(detections).unwrap();
            let mut params = vec![0.02, -0.01, 0.03];
            params.extend(fit.angles.iter().map(|a| a + rng.random_range(-0.05..0.05)));
            let frame = Frame {
                robust: (0..obs.len()).map(|_| rng.random_range(0.2..1.0)).collect(),
                obs,
                root0: fit.root_rotation,
                params,
            };
            let m = at(&b).frame_residual_count(&frame.obs);
            let mut exact = vec![0.0; m * nb];
            assert!(at(&b).frame_length_jacobian(
                (&frame.obs, &frame.robust, frame.root0),
                &frame.params,
                &lengths.movable,
                lengths.unit,
                &mut exact,
            ));
            let h = 1e-5;
            let mut largest: f64 = 0.0;
            let mut worst: f64 = 0.0;
            for k in 0..nb {
                let mut moved = b.clone();
                moved[k] += h;
                let plus = frame.residuals(&at(&moved), &frame.params);
                moved[k] -= 2.0 * h;
                let minus = frame.residuals(&at(&moved), &frame.params);
                for row in 0..m {
                    let difference = (plus[row] - minus[row]) / (2.0 * h);
                    largest = largest.max(difference.abs());
                    worst = worst.max((exact[row * nb + k] - difference).abs());
                }
            }
            assert!(largest > 1.0, "the lengths move the keypoints: {largest}");
            assert!(worst < 1e-6 * largest, "worst {worst} of {largest}");
        }
    }

    /// A skeleton whose bones differ from the template's is seen in eight frames; the
    /// template's skeleton is tracked and calibrated.
    #[test]
    fn calibration_recovers_changed_bone_lengths_from_exact_detections() {
        let skeleton = build_skeleton().unwrap();
        let template = Kinematics::new(&skeleton);
        // Upper arms 4 % longer, shins 3 % shorter, one shoulder 5 mm closer to the spine.
        let mut truth = vec![DVec3::ZERO; skeleton.len()];
        for (name, change) in [
            ("l_elbow", 0.04),
            ("r_elbow", 0.04),
            ("l_ankle", -0.03),
            ("r_ankle", -0.03),
        ] {
            let j = skeleton.find(name).unwrap();
            truth[j] = template.bind_translation(j) * change;
        }
        let shoulder = skeleton.find("l_shoulder").unwrap();
        truth[shoulder] = template.bind_translation(shoulder).normalize() * -0.005;
        let person = template.with_bone_offsets(&truth);
        let rig = camera_rig(8, 256, 256, 1);
        let (tracker, frames, fits) = track(&skeleton, &person, &rig.cameras, 8, 3);
        let pairs: Vec<_> = frames.iter().map(Vec::as_slice).zip(&fits).collect();
        let calibration = tracker.calibrate_bones(&pairs).unwrap();

        let worst = calibration
            .offsets
            .iter()
            .zip(&truth)
            .map(|(o, t)| o.distance(*t))
            .fold(0.0, f64::max);
        // The largest change is 1.2 cm (a shin); the prior pulls by about 0.1 % of it.
        assert!(
            worst < 3e-5,
            "worst offset error {worst} m: {calibration:?}"
        );
        assert!(
            calibration.rms_before_px > 0.2 && calibration.rms_after_px < 1e-3,
            "{calibration:?}"
        );
        // Refitted on the calibrated skeleton, every frame explains its detections exactly.
        let calibrated = tracker.clone().with_bone_offsets(&calibration.offsets);
        for d in &frames {
            let before = tracker.fit(d, None).unwrap().report.rms_inlier_px;
            let after = calibrated.fit(d, None).unwrap().report.rms_inlier_px;
            assert!(after < 1e-3 && before > 0.05, "{before} → {after} px");
        }
    }

    #[test]
    fn calibration_leaves_a_true_skeleton_alone_and_names_bad_detections() {
        let skeleton = build_skeleton().unwrap();
        let rig = camera_rig(6, 256, 256, 1);
        let (tracker, frames, fits) =
            track(&skeleton, &Kinematics::new(&skeleton), &rig.cameras, 4, 8);
        let pairs: Vec<_> = frames.iter().map(Vec::as_slice).zip(&fits).collect();
        let calibration = tracker.calibrate_bones(&pairs).unwrap();
        let largest = calibration
            .offsets
            .iter()
            .map(|o| o.length())
            .fold(0.0, f64::max);
        assert!(largest < 1e-6, "{calibration:?}");

        // A frame with a landmark slot too few in one view is refused with the view named.
        let mut short = frames[1].clone();
        short[2].pop();
        let pairs = [
            (frames[0].as_slice(), &fits[0]),
            (short.as_slice(), &fits[1]),
        ];
        let err = tracker.calibrate_bones(&pairs).unwrap_err();
        assert!(
            matches!(err, TrackError::LandmarkCount { view: 2, .. }),
            "{err}"
        );
    }
}
