//! One frame's least-squares problem (the keypoint, prior, temporal and silhouette residuals
//! under fixed robust weights) and the Levenberg–Marquardt loop that minimises it.

use glam::{DMat4, DQuat, DVec2, DVec3};
use skinfield_formats::JointDofs;

use super::{BEHIND_CAMERA_PX, FrameFit, JacobianMethod, Observation, TRANSLATION_PRIOR, Tracker};
use crate::template::hull::HullView;
use crate::track::alignment::{Alignment, Ray, global_alignment};
use crate::track::dense::{cholesky_solve, normal_equations};
use crate::track::kinematics::rotvec_to_dquat;
use crate::track::silhouette::{TrackingBody, outline_residual};

/// Buffers reused by every residual evaluation of a frame.
pub(super) struct Workspace {
    pub(super) worlds: Vec<DMat4>,
    pub(super) points: Vec<DVec3>,
    pub(super) obs_points: Vec<DVec3>,
    pub(super) rays: Vec<Ray>,
    pub(super) posed: Vec<DVec3>,
    pub(super) skinning: Vec<DMat4>,
}

impl Workspace {
    pub(super) fn new(t: &Tracker<'_>, obs: usize) -> Self {
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
pub(super) struct Problem<'t, 'a> {
    pub(super) tracker: &'t Tracker<'a>,
    pub(super) obs: &'t [Observation],
    pub(super) robust: &'t [f64],
    pub(super) hierarchical: bool,
    pub(super) root0: DQuat,
    pub(super) previous: Option<&'t FrameFit>,
    pub(super) silhouette: Option<&'t SilhouetteTerm<'t>>,
}

/// The silhouette residuals of a refinement: outline vertices fixed per view.
pub(super) struct SilhouetteTerm<'t> {
    pub(super) body: &'t TrackingBody,
    pub(super) masks: &'t [HullView],
    pub(super) outline: &'t [Vec<u32>],
    pub(super) weight_sqrt: f64,
}

impl SilhouetteTerm<'_> {
    pub(super) fn count(&self) -> usize {
        self.outline.iter().map(Vec::len).sum()
    }
}

impl<'t, 'a> Problem<'t, 'a> {
    /// The keypoint and limit terms (with the temporal term when `previous` is given) under
    /// the fixed weights `robust`, without the hierarchical weights or the silhouette term.
    pub(super) fn keypoints(
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

    pub(super) fn keypoint_weight(&self, o: &Observation, robust: f64) -> f64 {
        let lambda = if self.hierarchical {
            1.0 / (1.0 + self.tracker.depth[o.landmark] as f64)
        } else {
            1.0
        };
        o.confidence * lambda * robust
    }

    /// [`Self::jacobian`] under [`TrackOptions::jacobian`](super::TrackOptions::jacobian):
    /// `false` (`jac` unspecified) where the chain rule does not apply or differences were
    /// asked for.
    pub(super) fn jacobian_by_chain_rule(
        &self,
        params: &[f64],
        ws: &mut Workspace,
        jac: &mut [f64],
    ) -> bool {
        self.tracker.options.jacobian == JacobianMethod::ChainRule && self.jacobian(params, ws, jac)
    }

    /// Root rotation and alignment-layer shift for `params` (landmarks left in `ws.points`).
    pub(super) fn root_and_shift(
        &self,
        params: &[f64],
        ws: &mut Workspace,
    ) -> (DQuat, Option<DVec3>) {
        let (root, alignment) = self.root_and_alignment(params, ws);
        (root, alignment.map(|a| a.translation))
    }

    /// The root rotation of `params` (their first three entries, a rotation vector applied
    /// before `root0`).
    pub(super) fn root(&self, params: &[f64]) -> DQuat {
        (rotvec_to_dquat(DVec3::new(params[0], params[1], params[2])) * self.root0).normalize()
    }

    /// Root rotation and the alignment layer's solution for `params` (landmarks left in
    /// `ws.points`, world matrices in `ws.worlds`, rays in `ws.rays`).
    pub(super) fn root_and_alignment(
        &self,
        params: &[f64],
        ws: &mut Workspace,
    ) -> (DQuat, Option<Alignment>) {
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

    pub(super) fn project(&self, o: &Observation, x: DVec3) -> DVec2 {
        self.tracker.cameras[o.view]
            .project_f64(x)
            .unwrap_or(DVec2::splat(BEHIND_CAMERA_PX))
    }

    /// Reprojection error (pixels) of every observation.
    pub(super) fn errors(&self, params: &[f64], ws: &mut Workspace) -> Vec<f64> {
        let (_, shift) = self.root_and_shift(params, ws);
        let shift = shift.unwrap_or(DVec3::ZERO);
        self.obs
            .iter()
            .map(|o| (self.project(o, ws.points[o.landmark] + shift) - o.pixel).length())
            .collect()
    }

    pub(super) fn residual_count(&self) -> usize {
        let a = self.tracker.kinematics.param_count();
        let temporal = if self.previous.is_some() { 3 + a } else { 0 };
        let silhouette = self.silhouette.map_or(0, SilhouetteTerm::count);
        2 * self.obs.len() + a + temporal + silhouette
    }

    /// RMS distance (pixels) of the outline vertices to the mask outlines at `params`.
    pub(super) fn silhouette_rms(&self, params: &[f64], ws: &mut Workspace) -> f64 {
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
    pub(super) fn residuals(&self, params: &[f64], ws: &mut Workspace, out: &mut [f64]) {
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
    pub(super) fn prior_count(&self) -> usize {
        let a = self.tracker.kinematics.param_count();
        a + if self.previous.is_some() { 3 + a } else { 0 }
    }

    /// The limit excesses (Eq. 7), the translating joints' prior and the temporal changes at
    /// `params` (whose root rotation is `root`), into `out` ([`Self::prior_count`] rows).
    pub(super) fn prior_residuals(&self, params: &[f64], root: DQuat, out: &mut [f64]) {
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
pub(super) fn levenberg_marquardt(
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
                super::jacobian::STEP,
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
