//! Per-frame pose refinement: a small rigid correction of every joint of every training frame,
//! trained together with SkinNet by the same image losses ([`PoseRefinementConfig`]).
//!
//! Why: a capture whose motion was tracked from 2D keypoints (`trainer track`) carries pose
//! errors of a few millimetres and degrees. SkinNet cannot undo a frame's own error (its
//! weights are shared by every frame), so fitted to silhouettes posed with those errors it learns
//! weights that explain them on average, and is then worse at the true poses (CesiumMan: 0.421
//! cm Chamfer trained on the tracked motion against 0.217 on the true one,
//! `docs/experiments/tracking.md`). The images themselves are exact, so the poses that explain
//! them best, given the weights being learned, are closer to the truth than the tracker's fit,
//! which used a fixed body (bone heat) for its silhouette term.
//!
//! The parametrisation: joint `j` of frame `f` is turned by `ΔR_j` about its own world position
//! `p_j` (in world axes, so no local frame is needed), and its descendants follow:
//! `C_j = C_parent(j) · T(p_j) · ΔR_j · T(−p_j)`; a root also moves by `t` (the frame's
//! translation correction); the corrected skinning matrix is `C_j · S_j`. This is the same set of
//! poses as a local rotation correction `L_j · M_j⁻¹ ΔR_j M_j` (`M_j` the linear part of the
//! joint's world matrix): bone lengths stay, and a rigid bone moves rigidly. `ΔR` is the Gibbs
//! (Cayley) vector `g = tan(θ/2)·axis`, `R = ((1 − |g|²) I + 2 g gᵀ + 2 [g]×) / (1 + |g|²)`:
//! rational, smooth at zero and free of the `sin x / x` of a rotation vector. `t` is stored
//! divided by the template's diagonal so one learning rate suits any unit of length.
//!
//! Each frame has its own Adam: a frame is in a batch only now and then, and a shared Adam would
//! keep moving a frame on the momentum of its last visit and bias-correct with the global step.
//! A quadratic prior `λ · (Σ_j |g_j|² + |t / D|²)` per frame (averaged over the batch) keeps the
//! corrections where the images have nothing to say. The exported model does not contain them:
//! `trainer train` writes the corrected motion (`refined_motion.json`) and each joint's correction
//! angle (`pose_refinement.csv`) to the work folder.
//!
//! Measured (`docs/experiments/tracking.md`): CesiumMan's tracked-motion model 0.421 → 0.343 cm;
//! from the true motion the poses drift by 0.14 cm and the model loses 10 % (0.217 → 0.240),
//! since the images fix the posed surface, not how it splits into poses and weights. Hence off
//! by default.

use candle_core::{DType, Device, Tensor, Var};
use glam::{DMat4, Mat4};
use serde::{Deserialize, Serialize};
use skinfield_formats::{Pose, Skeleton, Transform};

use crate::optim::{Adam, AdamConfig};

/// Pose refinement settings (a [`super::TrainConfig`] field; off by default).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseRefinementConfig {
    /// Train a correction of every training frame's pose with the image losses. For captures
    /// whose motion was tracked (`trainer track`); a capture with exact motion gains nothing.
    pub enabled: bool,
    /// Adam's learning rate of the corrections (Gibbs-vector units, about radians / 2; the
    /// translation in units of the template's diagonal), scaled by the image iterations'
    /// schedule (warm-up and cosine decay). CesiumMan's tracked motion, SkinNet's Chamfer at the
    /// true test poses: 0.348 cm at 1e-3, 0.343 at 3e-3 (`docs/experiments/tracking.md`).
    pub lr: f64,
    /// λ of the quadratic prior on the corrections. Same capture: 0.351 cm at 0, 0.343 at 0.1,
    /// 0.355 at 3.
    pub prior_weight: f64,
}

impl Default for PoseRefinementConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            lr: 3e-3,
            prior_weight: 0.1,
        }
    }
}

impl PoseRefinementConfig {
    /// The first invalid field's name.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return Err("pose_refinement.lr");
        }
        if !(self.prior_weight.is_finite() && self.prior_weight >= 0.0) {
            return Err("pose_refinement.prior_weight");
        }
        Ok(())
    }
}

/// The corrections of every training frame, their optimisers and what posing them needs.
pub(crate) struct PoseRefinement {
    parents: Vec<Option<usize>>,
    /// `[1, J, 1]`: 1 at the roots (which take the translation), 0 elsewhere.
    root_mask: Tensor,
    /// Per training frame, each joint's world position `[J, 3]` (the pivot of its correction).
    pivots: Vec<Tensor>,
    /// Per training frame `[J + 1, 3]`: the joints' Gibbs vectors, then the roots'
    /// translation divided by `diagonal`.
    corrections: Vec<Var>,
    optimisers: Vec<Adam>,
    diagonal: f64,
    config: PoseRefinementConfig,
}

impl PoseRefinement {
    /// Zero corrections for frames with skinning matrices `frames` (`[F][J]`) of a skeleton
    /// with `parents` (parents before children) and inverse bind matrices `inverse_bind`.
    pub(crate) fn new(
        frames: &[&[Mat4]],
        parents: &[Option<usize>],
        inverse_bind: &[Mat4],
        diagonal: f64,
        config: PoseRefinementConfig,
    ) -> candle_core::Result<Self> {
        let dev = Device::Cpu;
        let j = parents.len();
        let bind: Vec<DMat4> = inverse_bind
            .iter()
            .map(|m| m.as_dmat4().inverse())
            .collect();
        let pivots = frames
            .iter()
            .map(|skinning| {
                let p: Vec<f32> = skinning
                    .iter()
                    .zip(&bind)
                    .flat_map(|(s, b)| {
                        let w = s.as_dmat4() * *b;
                        w.w_axis.truncate().as_vec3().to_array()
                    })
                    .collect();
                Tensor::from_vec(p, (j, 3), &dev)
            })
            .collect::<candle_core::Result<Vec<_>>>()?;
        let mask: Vec<f32> = parents
            .iter()
            .map(|p| if p.is_none() { 1.0 } else { 0.0 })
            .collect();
        let adam = AdamConfig {
            lr: config.lr,
            clip: None,
            ..AdamConfig::default()
        };
        let mut corrections = Vec::with_capacity(frames.len());
        let mut optimisers = Vec::with_capacity(frames.len());
        for f in 0..frames.len() {
            let var = Var::zeros((j + 1, 3), DType::F32, &dev)?;
            optimisers.push(Adam::new(vec![(format!("pose.{f}"), var.clone())], adam)?);
            corrections.push(var);
        }
        Ok(Self {
            parents: parents.to_vec(),
            root_mask: Tensor::from_vec(mask, (1, j, 1), &dev)?,
            pivots,
            corrections,
            optimisers,
            diagonal,
            config,
        })
    }

    /// The corrected skinning matrices `[B, J, 12]` of training frames `frames`, from their
    /// uncorrected ones `base` (`[B, J, 12]`, [`crate::losses::lbs::skinning_tensor`]);
    /// differentiable with respect to the corrections.
    pub(crate) fn apply(&self, frames: &[usize], base: &Tensor) -> candle_core::Result<Tensor> {
        let (b, j) = (frames.len(), self.parents.len());
        let dev = base.device();
        let c: Vec<Tensor> = frames
            .iter()
            .map(|&f| self.corrections[f].as_tensor().clone())
            .collect();
        let c = Tensor::stack(&c, 0)?; // [B, J + 1, 3]
        let g = c.narrow(1, 0, j)?;
        let t = (c.narrow(1, j, 1)? * self.diagonal)?; // [B, 1, 3]
        let r = gibbs_rotation(&g)?; // [B, J, 3, 3]
        let p: Vec<Tensor> = frames.iter().map(|&f| self.pivots[f].clone()).collect();
        let p = Tensor::stack(&p, 0)?; // [B, J, 3]
        let rp = r.matmul(&p.unsqueeze(3)?.contiguous()?)?.squeeze(3)?;
        let column = ((&p - rp)? + t.broadcast_mul(&self.root_mask)?)?;
        let top = Tensor::cat(&[r, column.unsqueeze(3)?], 3)?; // [B, J, 3, 4]
        let bottom = Tensor::new(&[0f32, 0.0, 0.0, 1.0], dev)?
            .reshape((1, 1, 1, 4))?
            .broadcast_as((b, j, 1, 4))?
            .contiguous()?;
        let a = Tensor::cat(&[&top, &bottom], 2)?; // [B, J, 4, 4]
        let mut chain: Vec<Tensor> = Vec::with_capacity(j);
        for k in 0..j {
            let ak = a.narrow(1, k, 1)?.squeeze(1)?.contiguous()?;
            let ck = match self.parents[k] {
                Some(parent) => chain[parent].matmul(&ak)?,
                None => ak,
            };
            chain.push(ck);
        }
        let corr = Tensor::stack(&chain, 1)?; // [B, J, 4, 4]
        let s = base.reshape((b, j, 3, 4))?;
        let s = Tensor::cat(&[&s, &bottom], 2)?;
        corr.matmul(&s)?.narrow(2, 0, 3)?.reshape((b, j, 12))
    }

    /// `λ · (Σ_j |g_j|² + |t / D|²)` averaged over the frames `frames` (a scalar).
    pub(crate) fn prior(&self, frames: &[usize]) -> candle_core::Result<Tensor> {
        let c: Vec<Tensor> = frames
            .iter()
            .map(|&f| self.corrections[f].as_tensor().clone())
            .collect();
        let squares = Tensor::stack(&c, 0)?.sqr()?.sum_all()?;
        squares * (self.config.prior_weight / frames.len().max(1) as f64)
    }

    /// One Adam step of the frames `frames`' corrections at learning rate `lr`.
    pub(crate) fn step(
        &mut self,
        frames: &[usize],
        grads: &candle_core::backprop::GradStore,
        lr: f64,
    ) -> candle_core::Result<()> {
        let mut seen = vec![false; self.optimisers.len()];
        for &f in frames {
            // A frame drawn twice into one batch still takes one step (its gradient already
            // sums both).
            if std::mem::replace(&mut seen[f], true) {
                continue;
            }
            self.optimisers[f].set_lr(lr);
            self.optimisers[f].step(grads)?;
        }
        Ok(())
    }

    /// The configured learning rate (before the schedule).
    pub(crate) fn lr(&self) -> f64 {
        self.config.lr
    }

    /// Per training frame, each joint's correction angle (radians) and the roots' translation
    /// correction (the template's units).
    pub(crate) fn summary(&self) -> candle_core::Result<Vec<FrameCorrection>> {
        let j = self.parents.len();
        self.corrections
            .iter()
            .map(|c| {
                let rows = c.as_tensor().to_vec2::<f32>()?;
                let angles = rows[..j]
                    .iter()
                    .map(|g| {
                        let n = g.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>().sqrt();
                        2.0 * n.atan()
                    })
                    .collect();
                let t = &rows[j];
                let translation =
                    t.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>().sqrt() * self.diagonal;
                Ok(FrameCorrection {
                    angles,
                    translation,
                })
            })
            .collect()
    }

    /// The state for a checkpoint: `pose.F` (the corrections) and `pose_adam.F.*` (each
    /// frame's optimiser).
    pub(crate) fn state_tensors(
        &self,
    ) -> candle_core::Result<std::collections::HashMap<String, Tensor>> {
        let mut out = std::collections::HashMap::new();
        for (f, (c, o)) in self.corrections.iter().zip(&self.optimisers).enumerate() {
            out.insert(format!("pose.{f}"), c.as_tensor().clone());
            for (k, v) in o.state_tensors()? {
                out.insert(format!("pose_adam.{f}.{k}"), v);
            }
        }
        Ok(out)
    }

    /// Restores what [`PoseRefinement::state_tensors`] wrote.
    pub(crate) fn load_state_tensors(
        &mut self,
        state: &std::collections::HashMap<String, Tensor>,
    ) -> Result<(), String> {
        for (f, (c, o)) in self
            .corrections
            .iter()
            .zip(&mut self.optimisers)
            .enumerate()
        {
            let key = format!("pose.{f}");
            let t = state
                .get(&key)
                .ok_or_else(|| format!("`{key}` is missing"))?;
            if t.shape() != c.shape() {
                return Err(format!("`{key}` has shape {:?}", t.dims()));
            }
            c.set(&t.to_dtype(DType::F32).map_err(|e| e.to_string())?)
                .map_err(|e| format!("`{key}`: {e}"))?;
            let prefix = format!("pose_adam.{f}.");
            let own: std::collections::HashMap<String, Tensor> = state
                .iter()
                .filter_map(|(k, v)| Some((k.strip_prefix(&prefix)?.to_string(), v.clone())))
                .collect();
            o.load_state_tensors(&own)
                .map_err(|e| format!("`{prefix}*`: {e}"))?;
        }
        Ok(())
    }
}

/// One training frame's correction ([`super::Trainer::pose_corrections`]).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameCorrection {
    /// Each joint's correction angle (radians).
    pub angles: Vec<f64>,
    /// Length of the roots' translation correction (the template's units).
    pub translation: f64,
}

/// The pose whose world matrices ([`Skeleton::world_matrices`]) are `world`: each joint's local
/// transform is its parent's world matrix (the skeleton's base above a root) inverted times its
/// own. Used to write the refined training poses as a motion.
#[must_use]
pub fn pose_from_world(skeleton: &Skeleton, world: &[Mat4]) -> Pose {
    let locals = skeleton
        .parents()
        .iter()
        .zip(world)
        .map(|(parent, w)| {
            let above = parent.map_or(skeleton.base(), |p| world[p]);
            let local = above.as_dmat4().inverse() * w.as_dmat4();
            let (scale, rotation, translation) = local.to_scale_rotation_translation();
            Transform {
                translation: translation.as_vec3(),
                rotation: rotation.as_quat().normalize(),
                scale: scale.as_vec3(),
            }
        })
        .collect();
    Pose { locals }
}

/// Rotation matrices `[…, 3, 3]` of Gibbs vectors `g` (`[B, J, 3]`).
fn gibbs_rotation(g: &Tensor) -> candle_core::Result<Tensor> {
    let (b, j, _) = g.dims3()?;
    let n2 = g.sqr()?.sum_keepdim(2)?.unsqueeze(3)?; // [B, J, 1, 1]
    let (x, y, z) = (g.narrow(2, 0, 1)?, g.narrow(2, 1, 1)?, g.narrow(2, 2, 1)?);
    let zero = x.zeros_like()?;
    let cross = Tensor::cat(
        &[
            &zero,
            &z.neg()?,
            &y,
            &z,
            &zero,
            &x.neg()?,
            &y.neg()?,
            &x,
            &zero,
        ],
        2,
    )?
    .reshape((b, j, 3, 3))?;
    let outer = g.unsqueeze(3)?.broadcast_mul(&g.unsqueeze(2)?)?;
    let eye = Tensor::eye(3, g.dtype(), g.device())?.reshape((1, 1, 3, 3))?;
    let numerator = ((eye.broadcast_mul(&(1.0 - &n2)?)? + (outer * 2.0)?)? + (cross * 2.0)?)?;
    numerator.broadcast_div(&(n2 + 1.0)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::losses::lbs::skinning_tensor;
    use glam::{Quat, Vec3};

    /// A chain root → a → b with a side branch c off the root, bound in a bent pose.
    fn skeleton() -> Skeleton {
        let t = |x: f32, y: f32, z: f32, angle: f32| Transform {
            translation: Vec3::new(x, y, z),
            rotation: Quat::from_rotation_z(angle),
            scale: Vec3::ONE,
        };
        Skeleton::new(
            vec!["root".into(), "a".into(), "b".into(), "c".into()],
            vec![None, Some(0), Some(1), Some(0)],
            vec![
                t(0.1, 1.0, 0.0, 0.1),
                t(0.0, 0.4, 0.0, -0.3),
                t(0.0, 0.3, 0.1, 0.2),
                t(0.2, 0.0, 0.0, 0.5),
            ],
            None,
            None,
            Mat4::IDENTITY,
        )
        .unwrap()
    }

    fn posed(skel: &Skeleton, turns: &[Quat], shift: Vec3) -> Vec<Mat4> {
        let mut pose = skel.bind_pose();
        for (l, q) in pose.locals.iter_mut().zip(turns) {
            l.rotation = (l.rotation * *q).normalize();
        }
        pose.locals[0].translation += shift;
        let mut s = vec![Mat4::IDENTITY; skel.len()];
        skel.skinning_matrices(&pose, &mut s).unwrap();
        s
    }

    fn frame_pose() -> Vec<Quat> {
        vec![
            Quat::from_rotation_y(0.4),
            Quat::from_rotation_x(-0.7),
            Quat::from_rotation_z(0.9),
            Quat::from_rotation_x(0.3),
        ]
    }

    /// Zero corrections of `frames` (skinning matrices of `skel`) with the default settings.
    fn refinement(skel: &Skeleton, frames: &[&[Mat4]], diagonal: f64) -> PoseRefinement {
        PoseRefinement::new(
            frames,
            skel.parents(),
            skel.inverse_bind(),
            diagonal,
            PoseRefinementConfig::default(),
        )
        .unwrap()
    }

    /// The Gibbs vector of `q` (`tan(θ/2) · axis`).
    fn gibbs(q: Quat) -> Vec3 {
        q.xyz() / q.w
    }

    #[test]
    fn corrections_equal_local_rotations_composed_by_forward_kinematics() {
        // Reference: the formats crate's forward kinematics of the pose whose local rotations
        // are corrected by M_j⁻¹ ΔR_j M_j (module docs), M_j the joint's world rotation.
        let skel = skeleton();
        let turns = frame_pose();
        let base = posed(&skel, &turns, Vec3::ZERO);
        let deltas = [
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 0.2),
            Quat::from_axis_angle(Vec3::new(-0.3, 1.0, 0.2).normalize(), -0.15),
            Quat::from_axis_angle(Vec3::Z, 0.3),
            Quat::from_axis_angle(Vec3::X, 0.05),
        ];
        let shift = Vec3::new(0.03, -0.02, 0.05);
        let diagonal = 2.0;
        let refine = refinement(&skel, &[&base], diagonal);
        let mut rows: Vec<f32> = deltas.iter().flat_map(|d| gibbs(*d).to_array()).collect();
        rows.extend((shift / diagonal as f32).to_array());
        refine.corrections[0]
            .set(&Tensor::from_vec(rows, (5, 3), &Device::Cpu).unwrap())
            .unwrap();
        let got = refine
            .apply(
                &[0],
                &skinning_tensor(std::slice::from_ref(&base), &Device::Cpu).unwrap(),
            )
            .unwrap()
            .to_vec3::<f32>()
            .unwrap();

        // World rotations of the uncorrected pose.
        let mut pose: Pose = skel.bind_pose();
        for (l, q) in pose.locals.iter_mut().zip(&turns) {
            l.rotation = (l.rotation * *q).normalize();
        }
        let mut world = vec![Mat4::IDENTITY; skel.len()];
        skel.world_matrices(&pose, &mut world).unwrap();
        let mut corrected = pose.clone();
        for (k, l) in corrected.locals.iter_mut().enumerate() {
            let m = Quat::from_mat4(&world[k]).normalize();
            l.rotation = (l.rotation * (m.inverse() * deltas[k] * m)).normalize();
        }
        // The root's translation correction is in world space, above its parent-less local.
        corrected.locals[0].translation += shift;
        let mut expect = vec![Mat4::IDENTITY; skel.len()];
        skel.skinning_matrices(&corrected, &mut expect).unwrap();
        let reference = skinning_tensor(&[expect], &Device::Cpu)
            .unwrap()
            .to_vec3::<f32>()
            .unwrap();
        for (k, (g, e)) in got[0].iter().zip(&reference[0]).enumerate() {
            for (a, b) in g.iter().zip(e) {
                assert!((a - b).abs() < 1e-5, "joint {k}: {g:?} vs {e:?}");
            }
        }
    }

    #[test]
    fn zero_corrections_keep_the_pose_and_the_gradient_matches_finite_differences() {
        let skel = skeleton();
        let base = posed(&skel, &frame_pose(), Vec3::ZERO);
        let inverse: Vec<Quat> = frame_pose().iter().map(|q| q.inverse()).collect();
        let other = posed(&skel, &inverse, Vec3::X);
        let refine = refinement(&skel, &[&base, &other], 1.5);
        let s = skinning_tensor(&[other.clone(), base.clone()], &Device::Cpu).unwrap();
        let same = refine.apply(&[1, 0], &s).unwrap();
        let diff = (&same - &s).unwrap().abs().unwrap().max_all().unwrap();
        assert!(diff.to_vec0::<f32>().unwrap() < 1e-6);

        // A scalar of the corrected matrices: its gradient with respect to frame 0's corrections
        // against central differences, at a non-zero correction.
        let weights = Tensor::arange(0f32, 48.0, &Device::Cpu)
            .unwrap()
            .affine(0.1, -2.0)
            .unwrap()
            .sin()
            .unwrap()
            .reshape((1, 4, 12))
            .unwrap();
        let start: Vec<f32> = (0..15).map(|i| 0.05 * ((i as f32) * 1.7).cos()).collect();
        let s0 = skinning_tensor(std::slice::from_ref(&base), &Device::Cpu).unwrap();
        let value = |rows: &[f32]| -> (f64, Option<Vec<f32>>) {
            refine.corrections[0]
                .set(&Tensor::from_vec(rows.to_vec(), (5, 3), &Device::Cpu).unwrap())
                .unwrap();
            let out = refine.apply(&[0], &s0).unwrap();
            let loss = (out * &weights).unwrap().sqr().unwrap().sum_all().unwrap();
            let grads = loss.backward().unwrap();
            let g = grads
                .get(refine.corrections[0].as_tensor())
                .map(|g| g.flatten_all().unwrap().to_vec1::<f32>().unwrap());
            (f64::from(loss.to_vec0::<f32>().unwrap()), g)
        };
        let (_, grad) = value(&start);
        let grad = grad.expect("a gradient for the frame's corrections");
        let h = 1e-3f32;
        for i in 0..15 {
            let mut plus = start.clone();
            plus[i] += h;
            let mut minus = start.clone();
            minus[i] -= h;
            let fd = (value(&plus).0 - value(&minus).0) / (2.0 * f64::from(h));
            let g = f64::from(grad[i]);
            assert!(
                (fd - g).abs() <= 2e-2 * fd.abs().max(1.0),
                "entry {i}: finite difference {fd} vs gradient {g}"
            );
        }
    }

    #[test]
    fn pose_from_world_inverts_forward_kinematics() {
        let base = Mat4::from_scale_rotation_translation(
            Vec3::splat(0.5),
            Quat::from_rotation_x(-0.4),
            Vec3::new(1.0, 0.0, 2.0),
        );
        let s = skeleton();
        let skel = Skeleton::new(
            s.names().to_vec(),
            s.parents().to_vec(),
            s.bind_pose().locals,
            None,
            None,
            base,
        )
        .unwrap();
        let mut pose = skel.bind_pose();
        for (l, q) in pose.locals.iter_mut().zip(frame_pose()) {
            l.rotation = (l.rotation * q).normalize();
        }
        pose.locals[2].scale = Vec3::new(1.0, 1.2, 1.0);
        let mut world = vec![Mat4::IDENTITY; skel.len()];
        skel.world_matrices(&pose, &mut world).unwrap();
        let back = pose_from_world(&skel, &world);
        for (a, b) in back.locals.iter().zip(&pose.locals) {
            assert!(
                a.translation.abs_diff_eq(b.translation, 1e-5),
                "{a:?} vs {b:?}"
            );
            assert!(
                a.rotation.dot(b.rotation).abs() > 1.0 - 1e-6,
                "{a:?} vs {b:?}"
            );
            assert!(a.scale.abs_diff_eq(b.scale, 1e-5), "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn each_frame_steps_only_when_in_the_batch_and_the_state_round_trips() {
        let skel = skeleton();
        let base = posed(&skel, &frame_pose(), Vec3::ZERO);
        let mut refine = refinement(&skel, &[&base, &base, &base], 1.0);
        let s = skinning_tensor(&[base.clone(), base.clone()], &Device::Cpu).unwrap();
        let out = refine.apply(&[2, 0], &s).unwrap();
        // Pull every matrix entry up: every frame in the batch must move, the other not.
        let loss =
            (out.sum_all().unwrap().neg().unwrap() + refine.prior(&[2, 0]).unwrap()).unwrap();
        let grads = loss.backward().unwrap();
        refine.step(&[2, 0], &grads, 1e-2).unwrap();
        let moved: Vec<f64> = refine
            .summary()
            .unwrap()
            .iter()
            .map(|c| c.angles.iter().sum::<f64>() + c.translation)
            .collect();
        assert!(
            moved[0] > 0.0 && moved[2] > 0.0 && moved[1] == 0.0,
            "{moved:?}"
        );

        let state = refine.state_tensors().unwrap();
        let mut other = refinement(&skel, &[&base, &base, &base], 1.0);
        other.load_state_tensors(&state).unwrap();
        assert_eq!(other.summary().unwrap(), refine.summary().unwrap());
        let mut missing = state.clone();
        missing.remove("pose.1");
        assert!(
            other
                .load_state_tensors(&missing)
                .unwrap_err()
                .contains("pose.1")
        );
    }
}
