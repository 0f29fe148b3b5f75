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

use glam::{DMat4, DQuat, DVec2, DVec3};
use skinfield_formats::{Camera, JointDofs};

use super::alignment::{Alignment, Ray, global_alignment};
use super::kinematics::{Kinematics, Landmark, rotvec_to_dquat};
use super::silhouette::{TrackingBody, outline_residual};
use crate::template::hull::HullView;

mod jacobian;

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

/// Buffers reused by every residual evaluation of a frame.
struct Workspace {
    worlds: Vec<DMat4>,
    points: Vec<DVec3>,
    obs_points: Vec<DVec3>,
    rays: Vec<Ray>,
    posed: Vec<DVec3>,
    skinning: Vec<DMat4>,
}

impl Workspace {
    fn new(t: &Tracker<'_>, obs: usize) -> Self {
        Self {
            worlds: vec![DMat4::IDENTITY; t.kinematics.joint_count()],
            points: vec![DVec3::ZERO; t.landmarks.len()],
            obs_points: vec![DVec3::ZERO; obs],
            rays: Vec::with_capacity(obs),
            posed: Vec::new(),
            skinning: Vec::new(),
        }
    }
}

/// One least-squares problem: a frame's observations under fixed robust weights.
struct Problem<'t, 'a> {
    tracker: &'t Tracker<'a>,
    obs: &'t [Observation],
    robust: &'t [f64],
    hierarchical: bool,
    root0: DQuat,
    previous: Option<&'t FrameFit>,
    silhouette: Option<&'t SilhouetteTerm<'t>>,
}

/// The silhouette residuals of a refinement: outline vertices fixed per view.
struct SilhouetteTerm<'t> {
    body: &'t TrackingBody,
    masks: &'t [HullView],
    outline: &'t [Vec<u32>],
    weight_sqrt: f64,
}

impl SilhouetteTerm<'_> {
    fn count(&self) -> usize {
        self.outline.iter().map(Vec::len).sum()
    }
}

impl<'t, 'a> Problem<'t, 'a> {
    /// The keypoint and limit terms (with the temporal term when `previous` is given) under
    /// the fixed weights `robust`, without the hierarchical weights or the silhouette term.
    fn keypoints(
        tracker: &'t Tracker<'a>,
        obs: &'t [Observation],
        robust: &'t [f64],
        root0: DQuat,
        previous: Option<&'t FrameFit>,
    ) -> Self {
        Self {
            tracker,
            obs,
            robust,
            hierarchical: false,
            root0,
            previous,
            silhouette: None,
        }
    }

    fn keypoint_weight(&self, o: &Observation, robust: f64) -> f64 {
        let lambda = if self.hierarchical {
            1.0 / (1.0 + self.tracker.depth[o.landmark] as f64)
        } else {
            1.0
        };
        o.confidence * lambda * robust
    }

    /// [`Self::jacobian`] under [`TrackOptions::jacobian`]: `false` (`jac` unspecified) where
    /// the chain rule does not apply or differences were asked for.
    fn jacobian_by_chain_rule(&self, params: &[f64], ws: &mut Workspace, jac: &mut [f64]) -> bool {
        self.tracker.options.jacobian == JacobianMethod::ChainRule && self.jacobian(params, ws, jac)
    }

    /// Root rotation and alignment-layer shift for `params` (landmarks left in `ws.points`).
    fn root_and_shift(&self, params: &[f64], ws: &mut Workspace) -> (DQuat, Option<DVec3>) {
        let (root, alignment) = self.root_and_alignment(params, ws);
        (root, alignment.map(|a| a.translation))
    }

    /// The root rotation of `params` (their first three entries, a rotation vector applied
    /// before `root0`).
    fn root(&self, params: &[f64]) -> DQuat {
        (rotvec_to_dquat(DVec3::new(params[0], params[1], params[2])) * self.root0).normalize()
    }

    /// Root rotation and the alignment layer's solution for `params` (landmarks left in
    /// `ws.points`, world matrices in `ws.worlds`, rays in `ws.rays`).
    fn root_and_alignment(&self, params: &[f64], ws: &mut Workspace) -> (DQuat, Option<Alignment>) {
        let t = self.tracker;
        let root = self.root(params);
        t.kinematics.landmarks(
            root,
            &params[3..],
            &t.landmarks,
            &mut ws.worlds,
            &mut ws.points,
        );
        ws.rays.clear();
        for (i, o) in self.obs.iter().enumerate() {
            ws.obs_points[i] = ws.points[o.landmark];
            ws.rays.push(Ray {
                origin: o.origin,
                direction: o.direction,
                weight: self.keypoint_weight(o, self.robust[i]),
            });
        }
        (root, global_alignment(&ws.obs_points, &ws.rays))
    }

    fn project(&self, o: &Observation, x: DVec3) -> DVec2 {
        self.tracker.cameras[o.view]
            .project_f64(x)
            .unwrap_or(DVec2::splat(BEHIND_CAMERA_PX))
    }

    /// Reprojection error (pixels) of every observation.
    fn errors(&self, params: &[f64], ws: &mut Workspace) -> Vec<f64> {
        let (_, shift) = self.root_and_shift(params, ws);
        let shift = shift.unwrap_or(DVec3::ZERO);
        self.obs
            .iter()
            .map(|o| (self.project(o, ws.points[o.landmark] + shift) - o.pixel).length())
            .collect()
    }

    fn residual_count(&self) -> usize {
        let a = self.tracker.kinematics.param_count();
        let temporal = if self.previous.is_some() { 3 + a } else { 0 };
        let silhouette = self.silhouette.map_or(0, SilhouetteTerm::count);
        2 * self.obs.len() + a + temporal + silhouette
    }

    /// RMS distance (pixels) of the outline vertices to the mask outlines at `params`.
    fn silhouette_rms(&self, params: &[f64], ws: &mut Workspace) -> f64 {
        let Some(term) = self.silhouette else {
            return 0.0;
        };
        let (_, shift) = self.root_and_shift(params, ws);
        term.body
            .pose(&ws.worlds, shift.unwrap_or(DVec3::ZERO), &mut ws.posed);
        let mut sum = 0.0;
        for (view, vertices) in term.masks.iter().zip(term.outline) {
            for &v in vertices {
                let p = view.camera.project_f64(ws.posed[v as usize]);
                let d = p.map_or(BEHIND_CAMERA_PX, |p| {
                    f64::from(view.signed_pixels(glam::Vec2::new(p.x as f32, p.y as f32)))
                });
                sum += d * d;
            }
        }
        (sum / term.count().max(1) as f64).sqrt()
    }

    /// The residual vector: weighted reprojection errors (Eq. 6), limit excesses (Eq. 7) and
    /// the translating joints' prior, temporal changes, outline distances.
    fn residuals(&self, params: &[f64], ws: &mut Workspace, out: &mut [f64]) {
        let (root, shift) = self.root_and_shift(params, ws);
        let mut k = 0;
        match shift {
            Some(shift) => {
                for (i, o) in self.obs.iter().enumerate() {
                    let s = self.keypoint_weight(o, self.robust[i]).sqrt();
                    let e = self.project(o, ws.points[o.landmark] + shift) - o.pixel;
                    out[k] = s * e.x;
                    out[k + 1] = s * e.y;
                    k += 2;
                }
            }
            None => {
                // The rays do not place the skeleton (every weight collapsed): a flat, large
                // residual that no step prefers.
                for v in &mut out[..2 * self.obs.len()] {
                    *v = BEHIND_CAMERA_PX;
                }
                k = 2 * self.obs.len();
            }
        }
        let priors = self.prior_count();
        self.prior_residuals(params, root, &mut out[k..k + priors]);
        k += priors;
        if let Some(term) = self.silhouette {
            let shift = shift.unwrap_or(DVec3::ZERO);
            term.body.skinning_matrices(&ws.worlds, &mut ws.skinning);
            for (view, vertices) in term.masks.iter().zip(term.outline) {
                for &v in vertices {
                    let x = term.body.skin_vertex(v as usize, &ws.skinning) + shift;
                    out[k] = term.weight_sqrt * outline_residual(view, x);
                    k += 1;
                }
            }
        }
        debug_assert_eq!(k, out.len());
    }

    /// Rows of the limit, translation-prior and temporal terms ([`Self::prior_residuals`]).
    fn prior_count(&self) -> usize {
        let a = self.tracker.kinematics.param_count();
        a + if self.previous.is_some() { 3 + a } else { 0 }
    }

    /// The limit excesses (Eq. 7), the translating joints' prior and the temporal changes at
    /// `params` (whose root rotation is `root`), into `out` ([`Self::prior_count`] rows).
    fn prior_residuals(&self, params: &[f64], root: DQuat, out: &mut [f64]) {
        let t = self.tracker;
        let mut k = 0;
        let angles = &params[3..];
        let lw = t.options.limit_weight.sqrt();
        let mut a = 0;
        for d in t.kinematics.dofs() {
            match d {
                JointDofs::Euler { limits, .. } => {
                    for l in limits {
                        let x = angles[a];
                        let excess =
                            (x - f64::from(l[1])).max(0.0) - (f64::from(l[0]) - x).max(0.0);
                        out[k] = lw * excess;
                        k += 1;
                        a += 1;
                    }
                }
                other => {
                    for _ in 0..other.count() {
                        out[k] = 0.0;
                        k += 1;
                        a += 1;
                    }
                }
            }
        }
        // The translating joints: a weak pull towards the bind pose, which settles what the
        // alignment layer's shift of the whole skeleton could equally explain.
        let tw = TRANSLATION_PRIOR.sqrt();
        for x in &angles[a..] {
            out[k] = tw * x;
            k += 1;
        }
        if let Some(p) = self.previous {
            let sw = t.options.smooth_weight.sqrt();
            let rel = (root * p.root_rotation.inverse()).normalize();
            let rel = if rel.w < 0.0 { -rel } else { rel };
            let rv = rel.to_scaled_axis();
            for c in 0..3 {
                out[k] = sw * rv[c];
                k += 1;
            }
            for (x, y) in angles.iter().zip(&p.angles) {
                out[k] = sw * (x - y);
                k += 1;
            }
        }
        debug_assert_eq!(k, out.len());
    }
}

/// Minimises `½‖r(p)‖²` from `params` in place; returns the final cost and the iterations run.
fn levenberg_marquardt(
    problem: &Problem<'_, '_>,
    params: &mut [f64],
    max_iterations: usize,
    ws: &mut Workspace,
) -> (f64, usize) {
    let n = params.len();
    let m = problem.residual_count();
    let mut r = vec![0.0; m];
    let mut r_try = vec![0.0; m];
    let mut plus = vec![0.0; m];
    let mut minus = vec![0.0; m];
    let mut jac = vec![0.0; m * n];
    problem.residuals(params, ws, &mut r);
    let mut cost = 0.5 * r.iter().map(|x| x * x).sum::<f64>();
    let mut mu = 1e-3;
    let mut trial = params.to_vec();
    for it in 0..max_iterations {
        if !problem.jacobian_by_chain_rule(params, ws, &mut jac) {
            problem.jacobian_by_differences(
                params,
                ws,
                &mut jac,
                &mut plus,
                &mut minus,
                jacobian::STEP,
            );
        }
        let (jtj, jtr) = normal_equations(&jac, &r, n);
        let gradient = jtr.iter().map(|g| g.abs()).fold(0.0, f64::max);
        if gradient < 1e-14 {
            return (cost, it);
        }
        let mut improved = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[i * n + i] += mu * jtj[i * n + i].max(1e-9);
            }
            let Some(step) = cholesky_solve(&mut a, &jtr, n) else {
                mu *= 10.0;
                continue;
            };
            for i in 0..n {
                trial[i] = params[i] - step[i];
            }
            problem.residuals(&trial, ws, &mut r_try);
            let c = 0.5 * r_try.iter().map(|x| x * x).sum::<f64>();
            if c < cost {
                let step_norm = step.iter().map(|s| s * s).sum::<f64>().sqrt();
                let rel = (cost - c) / cost.max(1e-300);
                params.copy_from_slice(&trial);
                core::mem::swap(&mut r, &mut r_try);
                cost = c;
                mu = (mu * 0.3).max(1e-12);
                improved = true;
                if rel < 1e-12 || step_norm < 1e-12 {
                    return (cost, it + 1);
                }
                break;
            }
            mu *= 10.0;
        }
        if !improved {
            return (cost, it + 1);
        }
    }
    (cost, max_iterations)
}

/// Solves `A x = b` for a symmetric positive definite `A` (`n × n`, overwritten by its
/// Cholesky factor); `None` when `A` is not positive definite.
fn cholesky_solve(a: &mut [f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    if !cholesky_factor(a, n) {
        return None;
    }
    let mut x = b.to_vec();
    cholesky_substitute(a, n, &mut x);
    Some(x)
}

/// Cholesky factor of the symmetric positive definite `a` (`n × n`) in place (lower triangle);
/// `false` when it is not positive definite.
pub(super) fn cholesky_factor(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    true
}

/// Solves `L Lᵀ x = b` in place for the factor `l` of [`cholesky_factor`].
pub(super) fn cholesky_substitute(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        for k in 0..i {
            b[i] -= l[i * n + k] * b[k];
        }
        b[i] /= l[i * n + i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            b[i] -= l[k * n + i] * b[k];
        }
        b[i] /= l[i * n + i];
    }
}

/// `Jᵀ J` (row-major `n × n`), and `Jᵀ r`, of a row-major `m × n` `jac`: faer's blocked
/// matrix product on one thread (its summation order, and so the fit, does not depend on the
/// machine).
pub(super) fn normal_equations(jac: &[f64], r: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    use faer::linalg::matmul::matmul;
    use faer::{Accum, ColRef, Mat, MatRef, Par};
    let m = r.len();
    let j = MatRef::from_row_major_slice(jac, m, n);
    let mut jtj = Mat::<f64>::zeros(n, n);
    matmul(
        jtj.as_mut(),
        Accum::Replace,
        j.transpose(),
        j,
        1.0,
        Par::Seq,
    );
    let mut jtr = Mat::<f64>::zeros(n, 1);
    let rv = ColRef::from_slice(r).as_mat();
    matmul(
        jtr.as_mut(),
        Accum::Replace,
        j.transpose(),
        rv,
        1.0,
        Par::Seq,
    );
    let mut out = vec![0.0; n * n];
    for i in 0..n {
        for k in 0..n {
            // Symmetric by construction up to rounding; take one triangle for exact symmetry.
            out[i * n + k] = if k >= i { jtj[(i, k)] } else { jtj[(k, i)] };
        }
    }
    (out, (0..n).map(|i| jtr[(i, 0)]).collect())
}
