//! The Jacobian of a frame's residuals by the chain rule through the alignment layer, with
//! differences taken only where they are cheap.
//!
//! Central differences of the whole residual cost `2n` evaluations of everything: forward
//! kinematics, every detection's ray and projection, the alignment layer, and with the
//! silhouette term the skinning and the masks' distances of every outline vertex. On a 62-joint
//! rig with side points (about 200 parameters, 1,500 detections, 1,100 outline vertices) that
//! made the silhouette refinement of one clip take over an hour. Here:
//!
//! - the parameters are differenced through forward kinematics only: each column gives every
//!   landmark's and every joint's derivative (`∂X_l/∂p`, `∂S_j/∂p` for the skinning matrices);
//! - the alignment layer's translation follows analytically, `∂t/∂p = Σ_r (∂t/∂X_r) ∂X_r/∂p`
//!   ([`Alignment::jacobian`]);
//! - a detection's rows are `s_i Jπ_i (∂X_l/∂p + ∂t/∂p)`, with `Jπ_i` the projection's
//!   derivative at the current point, taken once per detection;
//! - an outline vertex's row is `∇r_v · (Σ_j w_j ∂S_j/∂p x̄_v + ∂t/∂p)`, with `∇r_v` the bounded
//!   residual's gradient ([`outline_residual_gradient`]: the mask outline's distance gradient
//!   through the projection), taken once per vertex;
//! - the limit, translation-prior and temporal rows, which cost nothing to evaluate, are
//!   differenced directly.
//!
//! Every piece is exact up to the differences of forward kinematics (f64, step 1e-6).
//! `the_chain_rule_jacobian_matches_central_differences` holds the keypoint, limit and temporal
//! rows to the central differences of the whole residual (within 1e-6 of the largest entry),
//! and the silhouette rows to differences with a step of 1e-4 (within 1e-2): the masks'
//! distances are single precision, so differences with the tracker's step of 1e-6 move a
//! projection by about their rounding and are off by tens of percent there.
//! Where the alignment layer has no solution the caller falls back to differencing everything.
//!
//! The skeleton calibration's bone-length columns ([`Problem::length_jacobian`]) need no
//! differences at all: a length moves its whole subtree by one world vector.

use glam::{DMat4, DVec3};

use super::{Problem, Workspace};
use crate::track::alignment::Alignment;
use crate::track::silhouette::{outline_residual_gradient, projection_jacobian};

/// What every column of one detection's two rows shares ([`Problem::detection_derivatives`]).
struct DetectionDerivative {
    /// Square root of its weight (confidence, hierarchical and robust).
    weight_sqrt: f64,
    /// The projection's derivative (pixels per world unit) at its aligned landmark.
    projection: [glam::DVec2; 3],
    /// The alignment translation's derivative with respect to its landmark.
    alignment: glam::DMat3,
}

/// Step of the differences (parameters are radians, or tenths of the skeleton's size).
pub(super) const STEP: f64 = 1e-6;

impl Problem<'_, '_> {
    /// Fills `jac` (row-major, [`Self::residual_count`] × `params.len()`) by the chain rule
    /// (see the module docs); `false`, with `jac` unspecified, when the alignment layer has no
    /// solution at `params`.
    pub(super) fn jacobian(&self, params: &[f64], ws: &mut Workspace, jac: &mut [f64]) -> bool {
        let t = self.tracker;
        let n = params.len();
        let (_, alignment) = self.root_and_alignment(params, ws);
        let Some(alignment) = alignment else {
            return false;
        };
        let shift = alignment.translation;
        jac.fill(0.0);

        // What the columns share: each detection's weight, projection derivative and the
        // alignment layer's derivative for its ray; each outline vertex's residual gradient.
        let detections = self.detection_derivatives(ws, &alignment);
        let outline: Vec<(usize, DVec3)> = match self.silhouette {
            Some(term) => {
                term.body.skinning_matrices(&ws.worlds, &mut ws.skinning);
                term.masks
                    .iter()
                    .zip(term.outline)
                    .flat_map(|(view, vertices)| {
                        let skinning = &ws.skinning;
                        vertices.iter().map(move |&v| {
                            let x = term.body.skin_vertex(v as usize, skinning) + shift;
                            let g = outline_residual_gradient(view, x) * term.weight_sqrt;
                            (v as usize, g)
                        })
                    })
                    .collect()
            }
            None => Vec::new(),
        };

        let joints = t.kinematics.joint_count();
        let landmarks = t.landmarks.len();
        let priors = self.prior_count();
        let (mut worlds_plus, mut worlds_minus) =
            (vec![DMat4::IDENTITY; joints], vec![DMat4::IDENTITY; joints]);
        let (mut points_plus, mut points_minus) =
            (vec![DVec3::ZERO; landmarks], vec![DVec3::ZERO; landmarks]);
        let (mut prior_plus, mut prior_minus) = (vec![0.0; priors], vec![0.0; priors]);
        let mut d_points = vec![DVec3::ZERO; landmarks];
        let mut d_skinning = vec![DMat4::ZERO; joints];
        let inverse_bind = self.silhouette.map(|term| term.body.inverse_bind());
        let mut probe = params.to_vec();
        let prior_row = 2 * self.obs.len();
        for c in 0..n {
            let x = params[c];
            probe[c] = x + STEP;
            let root_plus = self.root(&probe);
            t.kinematics.landmarks(
                root_plus,
                &probe[3..],
                &t.landmarks,
                &mut worlds_plus,
                &mut points_plus,
            );
            self.prior_residuals(&probe, root_plus, &mut prior_plus);
            probe[c] = x - STEP;
            let root_minus = self.root(&probe);
            t.kinematics.landmarks(
                root_minus,
                &probe[3..],
                &t.landmarks,
                &mut worlds_minus,
                &mut points_minus,
            );
            self.prior_residuals(&probe, root_minus, &mut prior_minus);
            probe[c] = x;

            for ((d, a), b) in d_points.iter_mut().zip(&points_plus).zip(&points_minus) {
                *d = (*a - *b) / (2.0 * STEP);
            }
            let d_shift = self.keypoint_column(&d_points, &detections, jac, n, c);
            for (k, (a, b)) in prior_plus.iter().zip(&prior_minus).enumerate() {
                jac[(prior_row + k) * n + c] = (a - b) / (2.0 * STEP);
            }
            if let (Some(term), Some(inverse_bind)) = (self.silhouette, inverse_bind) {
                for (((d, a), b), ib) in d_skinning
                    .iter_mut()
                    .zip(&worlds_plus)
                    .zip(&worlds_minus)
                    .zip(inverse_bind)
                {
                    *d = (*a - *b) * (1.0 / (2.0 * STEP)) * *ib;
                }
                let first = prior_row + priors;
                for (k, &(v, g)) in outline.iter().enumerate() {
                    let dx = term.body.skin_vertex(v, &d_skinning) + d_shift;
                    jac[(first + k) * n + c] = g.dot(dx);
                }
            }
        }
        true
    }

    /// Fills `jac` (row-major, [`Self::residual_count`] × `lengths.len()`) with the residuals'
    /// derivatives with respect to bone lengths at `params`: column `k` lengthens joint
    /// `lengths[k].0`'s local translation along the unit direction `lengths[k].1` (its parent's
    /// frame) by `unit` per unit of the parameter, as the skeleton calibration parametrises
    /// them. `false`, with `jac` unspecified, when the alignment layer has no solution.
    ///
    /// Exact and without differences: a bone's length moves every joint below it by the same
    /// world vector, `∂X_l/∂b_k = unit · R_parent(k) d_k` for the landmarks of that subtree and
    /// zero elsewhere; the alignment layer and the projections follow as in [`Self::jacobian`].
    /// The limit, translation-prior and temporal rows do not depend on the lengths. Keypoint
    /// problems only: a silhouette term's rows are left zero (the calibration has none).
    pub(super) fn length_jacobian(
        &self,
        params: &[f64],
        ws: &mut Workspace,
        lengths: &[(usize, DVec3)],
        unit: f64,
        jac: &mut [f64],
    ) -> bool {
        debug_assert!(self.silhouette.is_none(), "keypoint problems only");
        let t = self.tracker;
        let n = lengths.len();
        let (_, alignment) = self.root_and_alignment(params, ws);
        let Some(alignment) = alignment else {
            return false;
        };
        jac.fill(0.0);
        let parents = t.kinematics.parents();
        let detections = self.detection_derivatives(ws, &alignment);
        let mut d_points = vec![DVec3::ZERO; t.landmarks.len()];
        for (c, &(joint, direction)) in lengths.iter().enumerate() {
            let Some(parent) = parents[joint] else {
                continue;
            };
            let moved = ws.worlds[parent].transform_vector3(direction) * unit;
            for (d, l) in d_points.iter_mut().zip(&t.landmarks) {
                let mut a = Some(l.joint);
                *d = DVec3::ZERO;
                while let Some(x) = a {
                    if x == joint {
                        *d = moved;
                        break;
                    }
                    a = parents[x];
                }
            }
            self.keypoint_column(&d_points, &detections, jac, n, c);
        }
        true
    }

    /// Per detection, what every column of its rows shares: the square root of its weight, the
    /// projection's derivative at its landmark (shifted by the alignment layer's translation)
    /// and the alignment layer's derivative for its ray (`ws` as [`Self::root_and_alignment`]
    /// left it).
    fn detection_derivatives(
        &self,
        ws: &Workspace,
        alignment: &Alignment,
    ) -> Vec<DetectionDerivative> {
        let t = self.tracker;
        self.obs
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let x = ws.points[o.landmark] + alignment.translation;
                DetectionDerivative {
                    weight_sqrt: self.keypoint_weight(o, self.robust[i]).sqrt(),
                    projection: projection_jacobian(&t.cameras[o.view], x),
                    alignment: alignment.jacobian(&ws.rays[i]),
                }
            })
            .collect()
    }

    /// Writes column `c` of the keypoint rows (of a row-major `jac` with `n` columns) from the
    /// landmarks' derivatives `d_points`, the alignment layer's response included; returns that
    /// response, the translation's derivative `∂t/∂p`.
    fn keypoint_column(
        &self,
        d_points: &[DVec3],
        detections: &[DetectionDerivative],
        jac: &mut [f64],
        n: usize,
        c: usize,
    ) -> DVec3 {
        let mut d_shift = DVec3::ZERO;
        for (o, det) in self.obs.iter().zip(detections) {
            d_shift += det.alignment * d_points[o.landmark];
        }
        for (i, (o, det)) in self.obs.iter().zip(detections).enumerate() {
            let dx = d_points[o.landmark] + d_shift;
            let jp = det.projection;
            let dp = jp[0] * dx.x + jp[1] * dx.y + jp[2] * dx.z;
            jac[(2 * i) * n + c] = det.weight_sqrt * dp.x;
            jac[(2 * i + 1) * n + c] = det.weight_sqrt * dp.y;
        }
        d_shift
    }

    /// Fills `jac` by central differences of the whole residual with step `h` ([`STEP`] for
    /// the tracker's own; `plus` and `minus`: scratch of [`Self::residual_count`] entries).
    pub(super) fn jacobian_by_differences(
        &self,
        params: &mut [f64],
        ws: &mut Workspace,
        jac: &mut [f64],
        plus: &mut [f64],
        minus: &mut [f64],
        h: f64,
    ) {
        let n = params.len();
        let m = plus.len();
        for c in 0..n {
            let x = params[c];
            params[c] = x + h;
            self.residuals(params, ws, plus);
            params[c] = x - h;
            self.residuals(params, ws, minus);
            params[c] = x;
            for row in 0..m {
                jac[row * n + c] = (plus[row] - minus[row]) / (2.0 * h);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{DQuat, DVec3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::super::{
        FrameFit, FrameReport, Problem, SilhouetteTerm, TrackOptions, Tracker, Workspace,
    };
    use crate::template::hull::HullView;
    use crate::track::landmarks::{joint_side_landmark_map, landmarks_of};
    use crate::track::silhouette::TrackingBody;
    use crate::track::tests::{exact_detections, random_angles};
    use crate::track::{Detection, Kinematics};

    /// Largest `|a − b|` over `rows` of two row-major `m × n` matrices, relative to the
    /// largest `|b|` there (at least 1).
    fn relative_difference(a: &[f64], b: &[f64], n: usize, rows: std::ops::Range<usize>) -> f64 {
        let range = rows.start * n..rows.end * n;
        let scale = b[range.clone()].iter().fold(1.0f64, |m, x| m.max(x.abs()));
        a[range.clone()]
            .iter()
            .zip(&b[range])
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
            / scale
    }

    #[test]
    fn the_chain_rule_jacobian_matches_central_differences() {
        let dir = tempfile::tempdir().unwrap();
        let capture = crate::track::capture::tests::tiny_capture(dir.path());
        let skeleton = &capture.skeleton;
        let cameras = &capture.rig.cameras;
        let frame = 3;

        // Side-point landmarks, a wrist and an ankle translating, detections of the true pose
        // with 1 px of noise and a few missing.
        let landmarks: Vec<_> = landmarks_of(&joint_side_landmark_map(skeleton), skeleton)
            .into_iter()
            .map(|(_, l)| l)
            .collect();
        let translating = [
            skeleton.find("l_ankle").unwrap(),
            skeleton.find("r_wrist").unwrap(),
        ];
        let kinematics = Kinematics::new(skeleton).with_translating_joints(&translating);
        let mut worlds = vec![glam::Mat4::IDENTITY; skeleton.len()];
        skeleton
            .world_matrices(&capture.poses[frame], &mut worlds)
            .unwrap();
        let points: Vec<DVec3> = landmarks
            .iter()
            .map(|l| worlds[l.joint].as_dmat4().transform_point3(l.offset))
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut detections = exact_detections(cameras, &points, 0.9);
        for (k, d) in detections.iter_mut().flatten().enumerate() {
            if k % 17 == 0 {
                *d = None;
            } else if let Some(Detection { pixel, .. }) = d {
                pixel.x += rng.random_range(-1.0..1.0);
                pixel.y += rng.random_range(-1.0..1.0);
            }
        }
        let skin = crate::train::data::initial_weights(&capture).unwrap();
        let body = TrackingBody::new(&capture.template, &skin, skeleton).unwrap();
        let tracker = Tracker::new(
            kinematics,
            landmarks,
            cameras,
            DVec3::Y,
            TrackOptions::default(),
        )
        .with_body(&body);
        let obs = tracker.observations(&detections).unwrap();
        let masks: Vec<HullView> = (0..cameras.len())
            .map(|c| {
                let mask = capture.load_mask(c, frame).unwrap();
                HullView::new(cameras[c].clone(), mask.coverage).unwrap()
            })
            .collect();

        // A state near the truth, a predecessor elsewhere, uneven robust weights.
        let root0 =
            capture.poses[frame].locals[0].rotation.as_dquat() * DQuat::from_rotation_y(0.05);
        let count = tracker.kinematics().param_count();
        let mut params = vec![0.04, -0.03, 0.02];
        params.extend(
            random_angles(skeleton, &mut rng)
                .iter()
                .map(|&a| f64::from(a) * 0.5),
        );
        params.resize_with(3 + count, || rng.random_range(-0.3..0.3));
        let previous = FrameFit {
            root_rotation: root0 * DQuat::from_rotation_x(0.1),
            world_shift: DVec3::ZERO,
            angles: (0..count).map(|_| rng.random_range(-0.2..0.2)).collect(),
            report: FrameReport::default(),
        };
        let robust: Vec<f64> = (0..obs.len()).map(|i| 0.4 + 0.3 * (i % 3) as f64).collect();
        let mut ws = Workspace::new(&tracker, obs.len());
        let plain = Problem {
            hierarchical: true,
            ..Problem::keypoints(&tracker, &obs, &robust, root0, Some(&previous))
        };
        let (_, shift) = plain.root_and_shift(&params, &mut ws);
        body.pose(&ws.worlds, shift.unwrap(), &mut ws.posed);
        let outline = body.outline_vertices(&masks, &ws.posed);
        let term = SilhouetteTerm {
            body: &body,
            masks: &masks,
            outline: &outline,
            weight_sqrt: 0.7,
        };
        assert!(term.count() > 100, "{} outline vertices", term.count());
        let with_masks = Problem {
            silhouette: Some(&term),
            ..plain
        };

        for problem in [&plain, &with_masks] {
            let (m, n) = (problem.residual_count(), params.len());
            let mut differences_with = |h: f64| {
                let mut jac = vec![0.0; m * n];
                let (mut plus, mut minus) = (vec![0.0; m], vec![0.0; m]);
                let mut probe = params.clone();
                problem.jacobian_by_differences(
                    &mut probe, &mut ws, &mut jac, &mut plus, &mut minus, h,
                );
                jac
            };
            let differences = differences_with(super::STEP);
            // The masks' distances are single precision: over a step of 1e-6 a projection moves
            // by about 1e-4 px, the size of their rounding, and the differences of the whole
            // residual (the tracker's Jacobian before this one) are off by tens of percent per
            // entry. A step of 1e-4 moves it by 0.01 px.
            let coarse = differences_with(1e-4);
            let mut chain = vec![0.0; m * n];
            assert!(problem.jacobian(&params, &mut ws, &mut chain));
            let keypoints = 2 * obs.len();
            let priors = keypoints + problem.prior_count();
            let rk = relative_difference(&chain, &differences, n, 0..keypoints);
            let rp = relative_difference(&chain, &differences, n, keypoints..priors);
            assert!(
                rk < 1e-6 && rp < 1e-6,
                "keypoint rows {rk:e}, prior rows {rp:e}"
            );
            if problem.silhouette.is_some() {
                let rs = relative_difference(&chain, &coarse, n, priors..m);
                assert!(rs < 1e-2, "silhouette rows {rs:e}");
            }
        }
    }
}
