//! Per-frame skeleton fitting to multi-view 2D detections (DeepCap §3.2 turned into an
//! optimisation): Levenberg–Marquardt over the root rotation and the joint angles, the root
//! translation from the global alignment layer at every evaluation, the confidence-weighted
//! keypoint reprojection loss (Eq. 6), the joint-limit prior (Eq. 7), temporal smoothness, and
//! robust reweighting against outlier detections.
//!
//! Robustness: iteratively reweighted least squares with Geman–McClure weights
//! `(s² / (s² + e²))²` of each detection's reprojection error `e` (pixels), the scale `s` halved
//! every round from [`TrackOptions::robust_start_px`] down to [`TrackOptions::robust_scale_px`]
//! (graduated non-convexity: the first rounds see every detection and settle the body, the last
//! ones ignore what no pose explains, such as a left/right swap in one view). The weights also
//! scale the rays of the alignment layer, so an outlier moves neither the pose nor `t`.
//!
//! Keypoint weights `λ_m` (DeepCap's kinematic-chain-based hierarchical weights, which vary
//! during training): in the first round `1 / (1 + depth)` of the landmark's joint below the
//! root, so the torso settles before the limbs; 1 afterwards.
//!
//! The Jacobian follows the chain rule through the alignment layer's analytic derivative, with
//! differences taken through forward kinematics only (the `jacobian` submodule); central
//! differences of the whole residual remain as the fallback where the alignment layer has no
//! solution.

use glam::{DQuat, DVec2, DVec3};
use skinfield_formats::{Camera, JointDofs};

use super::kinematics::{Kinematics, Landmark};
use super::silhouette::TrackingBody;
use crate::template::hull::HullView;

mod jacobian;
mod problem;

use problem::{Problem, SilhouetteTerm, Workspace, levenberg_marquardt};

/// One 2D detection of a landmark in one view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// Pixel coordinates (the capture's convention: pixel centres at integer + 0.5).
    pub pixel: DVec2,
    /// Detector confidence in `[0, 1]`.
    pub confidence: f64,
}

/// Settings of the tracker.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackOptions {
    /// Detections below this confidence are ignored (DeepCap: 0.4).
    pub min_confidence: f64,
    /// Weight of the joint-limit prior, in px² per rad² of excess.
    pub limit_weight: f64,
    /// Weight of the temporal term (change from the previous frame of the clip), px² per rad².
    pub smooth_weight: f64,
    /// Final Geman–McClure scale (pixels).
    pub robust_scale_px: f64,
    /// First-round Geman–McClure scale (pixels).
    pub robust_start_px: f64,
    /// Reweighting rounds.
    pub rounds: usize,
    /// Levenberg–Marquardt iterations per round (cap).
    pub iterations: usize,
    /// Root headings tried (about the up axis) when a frame has no predecessor.
    pub headings: usize,
    /// Weight of the silhouette term ([`super::silhouette`]) relative to the keypoints: the
    /// outline residuals together weigh this many times the keypoint residuals. 0 turns the
    /// refinement off. Default 1: on the built-in capture it halved the joint error and made
    /// SkinNet trained on the tracked motion as good as on the true motion
    /// (`docs/experiments/tracking.md`).
    pub silhouette_weight: f64,
    /// Rounds of skeleton calibration before the final fit ([`super::calibration`]): each fits
    /// every frame to the keypoints alone, then the bone lengths together with those frames'
    /// poses. 0 (the default) keeps the template's bones: on CesiumMan one round makes the
    /// tracked motion exact from exact detections (SkinNet trained on it within 3 % of the
    /// true-motion model, against 0.356 cm without), but at 2 px of noise the lengths' own
    /// noise (about 2 mm per bone) costs as much as the 3 mm mismatch it removes
    /// (`docs/experiments/tracking.md`).
    pub calibration_rounds: usize,
    /// Frames the calibration fits (evenly spread over the capture; 0: every frame). The
    /// lengths' noise is shared by every frame, which trained weights learn as they would a
    /// wrong skeleton, so a long capture is worth calibrating on all its frames (the cost grows
    /// linearly). Default [`super::calibration::DEFAULT_CALIBRATION_FRAMES`].
    pub calibration_frames: usize,
    /// σ, in frames, of the zero-phase Gaussian filter over each clip's tracked poses
    /// ([`super::filter`]); 0 (the default) turns it off. For captures of consecutive video
    /// frames only: it averages neighbouring frames' independent noise, which SkinNet would
    /// otherwise learn as blurred weights (CesiumMan at 2 px, 160 frames a clip: σ = 2 takes
    /// the tracked-motion model from 1.31× to 1.07× the true-motion model).
    pub filter_sigma_frames: f64,
    /// The clips (by name) the filter runs on; empty: every clip. A synthetic capture's
    /// held-out phases, or any clip of frames far apart in time, should be left out.
    pub filter_clips: Vec<String>,
    /// Joints (by name) whose local translation is fitted per frame, for rigs whose animation
    /// translates them (inverse-kinematics feet parented to the root, a pelvis moved relative
    /// to a root that stays put); see [`Kinematics::with_translating_joints`].
    pub translating_joints: Vec<String>,
    /// How the residuals are differentiated.
    pub jacobian: JacobianMethod,
}

/// How the tracker differentiates its residuals with respect to the pose (and, in the skeleton
/// calibration, the bone lengths).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JacobianMethod {
    /// The chain rule through the alignment layer (`track/solve/jacobian.rs`), falling back
    /// to differences where the layer has no solution.
    #[default]
    ChainRule,
    /// Central differences of the whole residual: the slower reference the chain rule is
    /// tested and benchmarked against.
    Differences,
}

impl Default for TrackOptions {
    fn default() -> Self {
        Self {
            min_confidence: 0.4,
            limit_weight: 1e4,
            smooth_weight: 25.0,
            robust_scale_px: 6.0,
            robust_start_px: 64.0,
            rounds: 5,
            iterations: 40,
            headings: 8,
            silhouette_weight: 1.0,
            calibration_rounds: 0,
            calibration_frames: super::calibration::DEFAULT_CALIBRATION_FRAMES,
            filter_sigma_frames: 0.0,
            filter_clips: Vec::new(),
            translating_joints: Vec::new(),
            jacobian: JacobianMethod::default(),
        }
    }
}

/// A fitted frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameFit {
    /// Root rotation (applied before the root's bind rotation, as `Skeleton::pose_from_angles`).
    pub root_rotation: DQuat,
    /// World-space shift of the skeleton from the alignment layer.
    pub world_shift: DVec3,
    /// The pose parameters ([`Kinematics::param_count`]): the joint angles
    /// (`Skeleton::angle_count`), then the translating joints' translations.
    pub angles: Vec<f64>,
    /// Per-frame report.
    pub report: FrameReport,
}

/// How well a frame was explained.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameReport {
    /// Detections at or above the confidence threshold.
    pub detections: usize,
    /// Of those, the ones the final reweighting kept (weight ≥ 0.5).
    pub inliers: usize,
    /// Root mean square reprojection error over the inliers (pixels).
    pub rms_inlier_px: f64,
    /// Median reprojection error over all used detections (pixels).
    pub median_px: f64,
    /// Detections more than [`FAR_FACTOR`] × the final robust scale off: a fit in a wrong
    /// minimum leaves many, a good one only the detector's outliers (`track.csv` lists it, so
    /// such frames can be found without ground truth).
    pub far: usize,
    /// Largest joint-limit excess (radians).
    pub limit_excess: f64,
    /// Levenberg–Marquardt iterations run in total.
    pub iterations: usize,
    /// RMS of the outline vertices' distances to the mask outlines after the silhouette
    /// refinement (pixels, unbounded); `None` without it.
    pub silhouette_rms_px: Option<f64>,
}

/// Why a frame could not be fitted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrackError {
    /// The detections per view do not match the landmark count.
    #[error("view {view} has {got} landmark slots, expected {expected}")]
    LandmarkCount {
        /// View index.
        view: usize,
        /// Slots given.
        got: usize,
        /// Landmarks.
        expected: usize,
    },
    /// More views of detections than cameras.
    #[error("{views} views of detections for {cameras} cameras")]
    ViewCount {
        /// Views given.
        views: usize,
        /// Cameras.
        cameras: usize,
    },
    /// Too few confident detections to place the skeleton (need two views of something).
    #[error("too few confident detections ({0}) to place the skeleton")]
    TooFewDetections(usize),
    /// A detection is NaN or infinite.
    #[error("view {view}, landmark {landmark}: non-finite detection")]
    NonFinite {
        /// View index.
        view: usize,
        /// Landmark index.
        landmark: usize,
    },
}

/// One used detection, with its ray.
#[derive(Clone, Copy, Debug)]
pub(super) struct Observation {
    pub(super) view: usize,
    pub(super) landmark: usize,
    pub(super) pixel: DVec2,
    pub(super) confidence: f64,
    pub(super) origin: DVec3,
    pub(super) direction: DVec3,
}

/// Fits skeletons to detections, frame by frame.
#[derive(Clone, Debug)]
pub struct Tracker<'a> {
    pub(super) kinematics: Kinematics,
    pub(super) landmarks: Vec<Landmark>,
    pub(super) cameras: &'a [Camera],
    depth: Vec<usize>,
    up: DVec3,
    pub(super) options: TrackOptions,
    body: Option<&'a TrackingBody>,
}

/// Weight of the pull of a translating joint's translation towards the bind pose: px² per
/// (10 % of the skeleton's size)² ([`Kinematics::with_translating_joints`]).
pub const TRANSLATION_PRIOR: f64 = 1.0;
/// A detection this many final robust scales off counts as far ([`FrameReport::far`]).
pub const FAR_FACTOR: f64 = 5.0;
/// Projection when a point falls behind a camera: a constant far from any image, so the
/// residual is large and flat there.
pub(super) const BEHIND_CAMERA_PX: f64 = 1e4;

impl<'a> Tracker<'a> {
    /// A tracker for `landmarks` of `kinematics` seen by `cameras`; `up` is the world's up axis
    /// (the axis of the heading search).
    #[must_use]
    pub fn new(
        kinematics: Kinematics,
        landmarks: Vec<Landmark>,
        cameras: &'a [Camera],
        up: DVec3,
        options: TrackOptions,
    ) -> Self {
        let parents = kinematics.parents();
        let depth = landmarks
            .iter()
            .map(|l| {
                let (mut d, mut j) = (0, l.joint);
                while let Some(p) = parents[j] {
                    d += 1;
                    j = p;
                }
                d
            })
            .collect();
        Self {
            kinematics,
            landmarks,
            cameras,
            depth,
            up,
            options,
            body: None,
        }
    }

    /// The tracker with a skinned body for the silhouette term (used by
    /// [`Self::fit_with_masks`] when [`TrackOptions::silhouette_weight`] is positive).
    #[must_use]
    pub fn with_body(mut self, body: &'a TrackingBody) -> Self {
        self.body = Some(body);
        self
    }

    /// The tracker with its skeleton's bones moved by `offsets`
    /// ([`Kinematics::with_bone_offsets`], e.g. from [`Self::calibrate_bones`]).
    #[must_use]
    pub fn with_bone_offsets(mut self, offsets: &[DVec3]) -> Self {
        self.kinematics = self.kinematics.with_bone_offsets(offsets);
        self
    }

    /// The kinematics layer.
    #[must_use]
    pub fn kinematics(&self) -> &Kinematics {
        &self.kinematics
    }

    pub(super) fn observations(
        &self,
        detections: &[Vec<Option<Detection>>],
    ) -> Result<Vec<Observation>, TrackError> {
        if detections.len() > self.cameras.len() {
            return Err(TrackError::ViewCount {
                views: detections.len(),
                cameras: self.cameras.len(),
            });
        }
        let mut out = Vec::new();
        for (view, (slots, camera)) in detections.iter().zip(self.cameras).enumerate() {
            if slots.len() != self.landmarks.len() {
                return Err(TrackError::LandmarkCount {
                    view,
                    got: slots.len(),
                    expected: self.landmarks.len(),
                });
            }
            for (landmark, d) in slots.iter().enumerate() {
                let Some(d) = d else { continue };
                if !(d.pixel.is_finite() && d.confidence.is_finite()) {
                    return Err(TrackError::NonFinite { view, landmark });
                }
                if d.confidence < self.options.min_confidence {
                    continue;
                }
                let (origin, direction) = camera.ray_f64(d.pixel);
                out.push(Observation {
                    view,
                    landmark,
                    pixel: d.pixel,
                    confidence: d.confidence,
                    origin,
                    direction,
                });
            }
        }
        Ok(out)
    }

    /// Fits one frame. `previous`: the fit of the preceding frame of the same clip (start and
    /// temporal anchor); without one, [`TrackOptions::headings`] root headings are tried from
    /// the rest pose and the best kept.
    pub fn fit(
        &self,
        detections: &[Vec<Option<Detection>>],
        previous: Option<&FrameFit>,
    ) -> Result<FrameFit, TrackError> {
        self.fit_with_masks(detections, previous, None)
    }

    /// [`Self::fit`], then, with `masks` (one per camera, in order), a body
    /// ([`Self::with_body`]) and a positive silhouette weight, the pose refined with the
    /// silhouette term ([`super::silhouette`]).
    pub fn fit_with_masks(
        &self,
        detections: &[Vec<Option<Detection>>],
        previous: Option<&FrameFit>,
        masks: Option<&[HullView]>,
    ) -> Result<FrameFit, TrackError> {
        let obs = self.observations(detections)?;
        if obs.len() < 2 {
            return Err(TrackError::TooFewDetections(obs.len()));
        }
        let a = self.kinematics.param_count();
        let headings = || -> Vec<(DQuat, Vec<f64>)> {
            let h = self.options.headings.max(1);
            (0..h)
                .map(|i| {
                    let yaw = core::f64::consts::TAU * i as f64 / h as f64;
                    (DQuat::from_axis_angle(self.up, yaw), vec![0.0; a])
                })
                .collect()
        };
        let starts = match previous {
            Some(p) => vec![(p.root_rotation, p.angles.clone())],
            None => headings(),
        };
        let fit = self.best_of(&obs, starts, previous)?;
        match (self.body, masks) {
            (Some(body), Some(masks)) if self.options.silhouette_weight > 0.0 => {
                Ok(self.refine_with_silhouettes(&obs, fit, previous, body, masks))
            }
            _ => Ok(fit),
        }
    }

    /// The silhouette refinement of a keypoint fit (see [`super::silhouette`]).
    fn refine_with_silhouettes(
        &self,
        obs: &[Observation],
        fit: FrameFit,
        previous: Option<&FrameFit>,
        body: &TrackingBody,
        masks: &[HullView],
    ) -> FrameFit {
        let root0 = fit.root_rotation;
        let mut params = vec![0.0; 3];
        params.extend_from_slice(&fit.angles);
        let mut ws = Workspace::new(self, obs.len());
        let unit = vec![1.0; obs.len()];
        let plain = Problem::keypoints(self, obs, &unit, root0, previous);
        let robust = self.robust_weights(
            &plain.errors(&params, &mut ws),
            self.options.robust_scale_px,
        );
        let (_, shift) = plain.root_and_shift(&params, &mut ws);
        body.pose(&ws.worlds, shift.unwrap_or(DVec3::ZERO), &mut ws.posed);
        let outline = body.outline_vertices(masks, &ws.posed);
        let count: usize = outline.iter().map(Vec::len).sum();
        if count == 0 {
            return fit;
        }
        let keypoints = 2.0 * obs.len() as f64;
        let term = SilhouetteTerm {
            body,
            masks,
            outline: &outline,
            weight_sqrt: (self.options.silhouette_weight * keypoints / count as f64).sqrt(),
        };
        let problem = Problem {
            robust: &robust,
            silhouette: Some(&term),
            ..plain
        };
        let (_, its) = levenberg_marquardt(&problem, &mut params, self.options.iterations, &mut ws);
        let mut refined = self.finish(
            obs,
            &robust,
            &params,
            root0,
            previous,
            fit.report.iterations + its,
        );
        refined.report.silhouette_rms_px = Some(problem.silhouette_rms(&params, &mut ws));
        refined
    }

    /// Geman–McClure weights of reprojection `errors` at scale `scale` (pixels).
    pub(super) fn robust_weights(&self, errors: &[f64], scale: f64) -> Vec<f64> {
        let s2 = scale * scale;
        errors.iter().map(|e| (s2 / (s2 + e * e)).powi(2)).collect()
    }

    /// The lowest-cost fit over `starts`.
    fn best_of(
        &self,
        obs: &[Observation],
        starts: Vec<(DQuat, Vec<f64>)>,
        previous: Option<&FrameFit>,
    ) -> Result<FrameFit, TrackError> {
        let mut best: Option<(f64, FrameFit)> = None;
        for (root, angles) in starts {
            let (cost, fit) = self.fit_from(obs, root, angles, previous)?;
            if best.as_ref().is_none_or(|(c, _)| cost < *c) {
                best = Some((cost, fit));
            }
        }
        Ok(best.expect("at least one start").1)
    }

    fn fit_from(
        &self,
        obs: &[Observation],
        root0: DQuat,
        angles0: Vec<f64>,
        previous: Option<&FrameFit>,
    ) -> Result<(f64, FrameFit), TrackError> {
        let a = self.kinematics.param_count();
        let n = 3 + a;
        let mut params = vec![0.0; n];
        params[3..].copy_from_slice(&angles0);
        let mut robust = vec![1.0; obs.len()];
        let mut scale = self.options.robust_start_px;
        let mut ctx = Workspace::new(self, obs.len());
        let mut iterations = 0;
        let rounds = self.options.rounds.max(1);
        let mut cost = f64::INFINITY;
        for round in 0..rounds {
            let hierarchical = round == 0 && rounds > 1;
            let problem = Problem {
                tracker: self,
                obs,
                robust: &robust,
                hierarchical,
                root0,
                previous,
                silhouette: None,
            };
            let (c, its) =
                levenberg_marquardt(&problem, &mut params, self.options.iterations, &mut ctx);
            cost = c;
            iterations += its;
            // Reweight from the current errors.
            let errors = problem.errors(&params, &mut ctx);
            if round + 1 < rounds {
                scale = (scale * 0.5).max(self.options.robust_scale_px);
            }
            robust = self.robust_weights(&errors, scale);
        }
        Ok((
            cost,
            self.finish(obs, &robust, &params, root0, previous, iterations),
        ))
    }

    /// The fit of `params` (root rotation relative to `root0`, then the angles) with its
    /// report under the robust weights `robust`.
    fn finish(
        &self,
        obs: &[Observation],
        robust: &[f64],
        params: &[f64],
        root0: DQuat,
        previous: Option<&FrameFit>,
        iterations: usize,
    ) -> FrameFit {
        let mut ctx = Workspace::new(self, obs.len());
        let problem = Problem::keypoints(self, obs, robust, root0, previous);
        let errors = problem.errors(params, &mut ctx);
        let (root, shift) = problem.root_and_shift(params, &mut ctx);
        let inl: Vec<f64> = errors
            .iter()
            .zip(robust)
            .filter(|(_, w)| **w >= 0.5)
            .map(|(e, _)| *e)
            .collect();
        let mut sorted = errors.clone();
        sorted.sort_by(f64::total_cmp);
        let report = FrameReport {
            detections: obs.len(),
            inliers: inl.len(),
            rms_inlier_px: if inl.is_empty() {
                0.0
            } else {
                (inl.iter().map(|e| e * e).sum::<f64>() / inl.len() as f64).sqrt()
            },
            median_px: sorted[sorted.len() / 2],
            far: errors
                .iter()
                .filter(|e| **e > FAR_FACTOR * self.options.robust_scale_px)
                .count(),
            limit_excess: self.limit_excess(&params[3..]),
            iterations,
            silhouette_rms_px: None,
        };
        FrameFit {
            root_rotation: root,
            world_shift: shift.unwrap_or(DVec3::ZERO),
            angles: params[3..].to_vec(),
            report,
        }
    }

    /// Number of [`Self::frame_residuals`] entries for `obs`.
    pub(super) fn frame_residual_count(&self, obs: &[Observation]) -> usize {
        2 * obs.len() + self.kinematics.param_count()
    }

    /// One frame's keypoint residuals (Eq. 6 under the fixed weights `robust`) and joint-limit
    /// residuals (Eq. 7) at `params` (the root's rotation vector relative to `root0`, then the
    /// angles), without the temporal and silhouette terms, into `out`; with `jacobian`, also
    /// their derivative with respect to `params` (row-major, one row per residual), by the
    /// tracker's own chain rule. The skeleton calibration's per-frame block.
    pub(super) fn frame_residuals(
        &self,
        obs: &[Observation],
        robust: &[f64],
        root0: DQuat,
        params: &[f64],
        out: &mut [f64],
        jacobian: Option<&mut [f64]>,
    ) {
        let problem = Problem::keypoints(self, obs, robust, root0, None);
        let mut ws = Workspace::new(self, obs.len());
        problem.residuals(params, &mut ws, out);
        if let Some(jac) = jacobian
            && !problem.jacobian_by_chain_rule(params, &mut ws, jac)
        {
            let (mut plus, mut minus) = (vec![0.0; out.len()], vec![0.0; out.len()]);
            problem.jacobian_by_differences(
                &mut params.to_vec(),
                &mut ws,
                jac,
                &mut plus,
                &mut minus,
                jacobian::STEP,
            );
        }
    }

    /// The derivative of [`Self::frame_residuals`] with respect to bone lengths, into `jac`
    /// (row-major, one column per entry of `lengths`: a joint and the unit direction, in its
    /// parent's frame, its local translation lengthens along, by `unit` per unit of the
    /// parameter); `false` where the alignment layer has no solution.
    pub(super) fn frame_length_jacobian(
        &self,
        frame: (&[Observation], &[f64], DQuat),
        params: &[f64],
        lengths: &[(usize, DVec3)],
        unit: f64,
        jac: &mut [f64],
    ) -> bool {
        let (obs, robust, root0) = frame;
        if self.options.jacobian == JacobianMethod::Differences {
            return false;
        }
        let problem = Problem::keypoints(self, obs, robust, root0, None);
        let mut ws = Workspace::new(self, obs.len());
        problem.length_jacobian(params, &mut ws, lengths, unit, jac)
    }

    /// One frame's reprojection error (pixels) of every observation at `params`, the alignment
    /// layer weighted by confidence alone; what the calibration's robust weights come from.
    pub(super) fn frame_errors(
        &self,
        obs: &[Observation],
        root0: DQuat,
        params: &[f64],
    ) -> Vec<f64> {
        let unit = vec![1.0; obs.len()];
        let problem = Problem::keypoints(self, obs, &unit, root0, None);
        problem.errors(params, &mut Workspace::new(self, obs.len()))
    }

    /// Largest excess of any Euler angle over its limits (radians).
    fn limit_excess(&self, angles: &[f64]) -> f64 {
        let mut k = 0;
        let mut worst: f64 = 0.0;
        for d in self.kinematics.dofs() {
            if let JointDofs::Euler { limits, .. } = d {
                for (i, l) in limits.iter().enumerate() {
                    let x = angles[k + i];
                    worst = worst.max(x - f64::from(l[1])).max(f64::from(l[0]) - x);
                }
            }
            k += d.count();
        }
        worst
    }
}
