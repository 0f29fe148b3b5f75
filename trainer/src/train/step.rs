//! One iteration: the warm start's regression to the initial weights, and the image-loss
//! step (silhouettes, Laplacian and the optional regularisers), forward, backward and Adam.

use super::*;

impl Trainer {
    /// One warm-start iteration on a random batch of frames; returns the objective's terms
    /// before the step. A no-op for the static baseline.
    ///
    /// The objective is `KL(w_init ‖ w) + λ_pos · ‖x(w) − x(w_init)‖² / D²`, both averaged over
    /// the batch's vertices: the Kullback–Leibler divergence from the initial weights to
    /// SkinNet's, plus the squared distance between the vertex skinned with SkinNet's weights
    /// and with the initial ones in the batch's poses, relative to the squared diagonal `D` of
    /// the template's bounding box, so the term does not depend on the file's unit of length
    /// (`warm_start_position_weight` = λ_pos).
    ///
    /// Why these: the squared error of the weights (the first version) has a gradient that
    /// passes through the softmax Jacobian and vanishes as the weights saturate; KL's gradient
    /// with respect to the logits is `w − w_init`. But KL ignores the joints a vertex has no
    /// initial weight on, and a small leak onto a far joint moves the vertex by centimetres; the
    /// position term weighs every weight error by how far it moves the vertex (off by default:
    /// it did not help in the runs measured, see `TrainConfig::warm_start_position_weight`). On
    /// the built-in capture (Chamfer after the warm start alone; bone heat 1.003 cm): 300
    /// squared-error iterations 1.161 cm, 300 KL iterations 1.059 cm.
    pub fn warm_step(&mut self) -> Result<WarmRecord, TrainError> {
        if matches!(self.model, Model::Static { .. }) {
            self.warm_done += 1;
            return Ok(WarmRecord::default());
        }
        self.optimiser.set_lr(self.warm_lr(self.warm_done));
        const KIND: IterationKind = IterationKind::Warm;
        let mut timer = Timer::start();
        let frames = self.sample(PHASE_WARM, self.warm_done);
        let query = self.draw_queries(PHASE_WARM, self.warm_done)?;
        let w = self.weights_at(&frames, query.as_ref())?;
        timer.lap(&mut self.profile, KIND, Phase::Forward);
        let v = self.data.template.vertex_count();
        let b = frames.len();
        let skinning = self.frame_skinning(&frames)?;
        let rest = self.rest_at(query.as_ref())?;
        // The target: the initial weights, or with teachers their mean in these poses.
        let (cross, init_entropy, target_posed) = if self.is_distilling() {
            let target = self.teacher_mean(&frames, query.as_ref())?;
            let cross = (crate::losses::prior::cross_entropy(&w, &target)? / ((b * v) as f64))?;
            let neg_entropy = crate::losses::prior::neg_entropy(&target.flatten_all()?.to_vec1()?)
                / (b * v).max(1) as f64;
            (cross, neg_entropy, lbs(&target, &skinning, &rest)?)
        } else {
            let init = self.init_at(query.as_ref())?;
            let (cross, neg_entropy) = self.prior_cross_entropy(&w, &init, query.as_ref(), None)?;
            let posed = self.initial_posing(&init, &skinning, &rest, b)?;
            (cross, neg_entropy, posed)
        };
        timer.lap(&mut self.profile, KIND, Phase::Regularisers);
        // At weight 0 (the default) the position error is only measured, for the convergence
        // test: from detached weights and outside the total, so the backward pass does not run
        // through the skinning of every frame for a zero gradient (the model is the same to the
        // byte).
        let position_weight = self.warm_settings().position_weight;
        let skinned = if position_weight == 0.0 {
            lbs(&w.detach(), &skinning, &rest)?
        } else {
            lbs(&w, &skinning, &rest)?
        };
        let offset = (skinned - target_posed)?;
        let position =
            (offset.sqr()?.sum_all()? / ((b * v) as f64 * self.diagonal * self.diagonal))?;
        let total = if position_weight == 0.0 {
            cross.clone()
        } else {
            (&cross + (&position * position_weight)?)?
        };
        let kl = f64::from(cross.to_vec0::<f32>()?) + init_entropy;
        let position_relative = f64::from(position.to_vec0::<f32>()?).max(0.0).sqrt();
        timer.lap(&mut self.profile, KIND, Phase::Skinning);
        let grads = total.backward()?;
        timer.lap(&mut self.profile, KIND, Phase::Backward);
        self.optimiser.step(&grads)?;
        timer.lap(&mut self.profile, KIND, Phase::Optimiser);
        self.profile.finish_iteration(KIND);
        self.warm_done += 1;
        let record = WarmRecord {
            iteration: self.warm_done,
            kl,
            position_relative,
        };
        self.note_warm(&record);
        Ok(record)
    }

    /// One image-loss iteration on a seeded batch; returns its losses (before the step).
    ///
    /// The first image iteration starts a fresh Adam state, and the learning rate ramps up over
    /// `config.lr_warmup` iterations. The warm start's moments belong to another objective
    /// whose gradients are much smaller: carried over, the first image-loss step quadrupled the
    /// mean boundary-vertex distance on the built-in capture (0.76 → 2.88 px); with a fresh
    /// state and no ramp it still rose to 1.86 px, since Adam's first step moves every
    /// parameter by lr at once.
    pub fn step(&mut self) -> Result<LossRecord, TrainError> {
        if self.done == 0 {
            self.optimiser = Adam::from_varmap(
                &self.varmap,
                Self::adam_config(&self.config, self.is_static()),
            )?;
        }
        if self.average.is_none() && self.config.ema_half_life > 0.0 {
            self.average = Some(average::ParameterAverage::new(
                &self.varmap,
                self.config.ema_half_life,
            )?);
        }
        self.optimiser.set_lr(self.image_lr(self.done));
        // Stage 4's iterations follow stage 1's and pose the full-resolution template when
        // configured so; they are timed apart.
        let kind = if self.in_stage_one(self.done) {
            IterationKind::Image
        } else {
            IterationKind::Refine
        };
        let mut timer = Timer::start();
        let frames = self.sample(PHASE_IMAGE, self.done);
        let query = self.draw_queries(PHASE_IMAGE, self.done)?;
        let w = self.image_weights(&frames, query.as_ref())?;
        timer.lap(&mut self.profile, kind, Phase::Forward);
        let b = frames.len();
        let skinning = self.frame_skinning(&frames)?;
        let rest = self.rest_at(query.as_ref())?;
        let posed = lbs(&w, &skinning, &rest)?;
        timer.lap(&mut self.profile, kind, Phase::Skinning);
        let views: Vec<BatchView> = frames
            .iter()
            .enumerate()
            .flat_map(|(k, &f)| {
                self.data.frames[f].views.iter().map(move |view| BatchView {
                    frame: k,
                    camera: view.camera.clone(),
                    target: view.target.clone(),
                })
            })
            .collect();
        let loss = SilhouetteLoss::new(
            views,
            self.triangles.clone(),
            self.edges.clone(),
            self.config.silhouette_huber_px,
        );
        let silhouette = match &self.outline_offsets {
            Some(o) => {
                // A frame's views are its capture's cameras in order.
                let cameras: Vec<u32> = frames
                    .iter()
                    .flat_map(|&f| 0..self.data.frames[f].views.len() as u32)
                    .collect();
                loss.apply_with_offsets(&posed, &o.per_view(&cameras)?)?
            }
            None => loss.apply(&posed)?,
        };
        let sb = silhouette.get(0)?;
        let sc = silhouette.get(1)?;
        let (sb_px, sc_px) = (silhouette.get(2)?, silhouette.get(3)?);
        timer.lap(&mut self.profile, kind, Phase::Silhouette);
        let v = self.data.template.vertex_count() as f64;
        let init = self.init_at(query.as_ref())?;
        let lw = self.config.weights;
        let drift_gate = self.hidden_gate.as_ref().filter(|_| lw.hidden_drift > 0.0);
        let initial_posed = match (self.config.laplacian_reference, drift_gate) {
            (LaplacianReference::Absolute, None) => None,
            _ => Some(self.initial_posing(&init, &skinning, &rest, b)?),
        };
        let lap_input = match (self.config.laplacian_reference, &initial_posed) {
            // The operator is linear: δ(x) − δ(x_init) = δ(x − x_init).
            (LaplacianReference::InitialSkinning, Some(initial)) => (&posed - initial)?,
            _ => posed.clone(),
        };
        // Relative to the character's size (`LossWeights::laplacian`).
        let lap =
            (self.laplacian.loss(&lap_input)? / (b as f64 * v * self.diagonal * self.diagonal))?;
        let skin = (self.skinning.loss(&w)? / (b as f64 * v))?;
        let part = (self.partwise.loss(&w)? / (b * self.partwise.count().max(1)) as f64)?;
        let (prior, init_entropy) = self.prior_cross_entropy(&w, &init, query.as_ref(), None)?;
        // The prior restricted to the vertices no training outline shows (SkinNet only).
        let (hidden_prior, hidden_entropy) = match &self.hidden_gate {
            Some(gate) if lw.hidden_prior > 0.0 => {
                self.prior_cross_entropy(&w, &init, query.as_ref(), Some(gate))?
            }
            _ => (Tensor::zeros((), w.dtype(), w.device())?, 0.0),
        };
        // The hinge on their drift beyond the seen vertices' (SkinNet only).
        let hidden_drift = match (drift_gate, &initial_posed) {
            (Some(gate), Some(initial)) => hidden::drift_hinge(
                &posed,
                initial,
                &gate.tensor,
                &gate.seen,
                self.config.hidden_drift_ratio,
                self.diagonal,
            )?,
            _ => Tensor::zeros((), w.dtype(), w.device())?,
        };
        let weighted = [
            (&sb, lw.silhouette_boundary),
            (&sc, lw.silhouette_contour),
            (&lap, lw.laplacian),
            (&skin, lw.skinning),
            (&part, lw.partwise),
            (&prior, lw.prior),
            (&hidden_prior, lw.hidden_prior),
            (&hidden_drift, lw.hidden_drift),
        ];
        // Every term is logged; one of weight 0 stays out of the total, so the backward pass
        // does not run through it (multiplied by 0 it would, for nothing). Only when every
        // weight is 0 do they all enter, as zeros, so the step still has its gradients.
        let any = weighted.iter().any(|&(_, k)| k != 0.0);
        let mut terms = weighted
            .iter()
            .filter(|&&(_, k)| !any || k != 0.0)
            .map(|&(t, k)| t * k)
            .collect::<candle_core::Result<Vec<_>>>()?;
        if let Some(r) = &self.pose_refinement {
            terms.push(r.prior(&frames)?);
        }
        timer.lap(&mut self.profile, kind, Phase::Regularisers);
        terms.extend(self.rendering_term(&frames, &posed)?);
        timer.lap(&mut self.profile, kind, Phase::Rendering);
        let total = Tensor::stack(&terms, 0)?.sum_all()?;
        // The offsets' objective, the silhouette distances, carries no gradient to the weights
        // (`SilhouetteLoss`); the logged total leaves it out.
        let objective = match &self.outline_offsets {
            Some(_) => {
                (((&sb_px * lw.silhouette_boundary)? + (&sc_px * lw.silhouette_contour)?)?
                    + &total)?
            }
            None => total.clone(),
        };
        let val = |t: &Tensor| -> Result<f64, TrainError> { Ok(f64::from(t.to_vec0::<f32>()?)) };
        self.done += 1;
        let record = LossRecord {
            iteration: self.done,
            total: val(&total)?,
            silhouette_boundary: val(&sb_px)?,
            silhouette_contour: val(&sc_px)?,
            laplacian: val(&lap)?,
            skinning: val(&skin)?,
            partwise: val(&part)?,
            prior: val(&prior)? + init_entropy,
            hidden_prior: val(&hidden_prior)? + hidden_entropy,
            hidden_drift: val(&hidden_drift)?,
        };
        let grads = objective.backward()?;
        timer.lap(&mut self.profile, kind, Phase::Backward);
        self.optimiser.step(&grads)?;
        // The corrections follow the image iterations' schedule (warm-up, cosine decay).
        let schedule =
            self.image_lr(self.done - 1) / Self::adam_config(&self.config, self.is_static()).lr;
        if let Some(r) = &mut self.pose_refinement {
            r.step(&frames, &grads, r.lr() * schedule)?;
        }
        if let Some(o) = &mut self.outline_offsets {
            o.step(&grads, o.lr() * schedule)?;
        }
        if let Some(a) = &mut self.average {
            a.update()?;
        }
        timer.lap(&mut self.profile, kind, Phase::Optimiser);
        self.profile.finish_iteration(kind);
        Ok(record)
    }

    /// The prior's cross-entropy ([`crate::losses::prior`]) summed over the batch's vertices
    /// (`w` is `[B, V, J]`, `init` `[1, V, J]`, at query rows `query` or at the training
    /// vertices), or with `gate` over the vertices it marks ([`super::hidden`]), divided by
    /// `B·V` either way; and the initial weights'
    /// negative entropy over the same rows divided by `V`: their sum is `KL(w_init ‖ w)` per
    /// vertex.
    fn prior_cross_entropy(
        &self,
        w: &Tensor,
        init: &Tensor,
        query: Option<&Tensor>,
        gate: Option<&HiddenGate>,
    ) -> Result<(Tensor, f64), TrainError> {
        let (b, v) = (w.dim(0)?, self.data.template.vertex_count());
        let target = match gate {
            Some(g) => init.broadcast_mul(&g.tensor)?,
            None => init.clone(),
        };
        let cross = (crate::losses::prior::cross_entropy(w, &target)? / ((b * v) as f64))?;
        let entropy = match (query, gate) {
            (Some(rows), _) => {
                let kept = |i: usize| gate.is_none_or(|g| g.gate[i] > 0.0);
                let total: f64 = rows
                    .to_vec1::<u32>()?
                    .iter()
                    .enumerate()
                    .filter(|&(i, _)| kept(i))
                    .map(|(_, &r)| self.query_neg_entropy[r as usize])
                    .sum();
                total / v.max(1) as f64
            }
            (None, None) => self.init_entropy,
            (None, Some(g)) => g.init_entropy,
        };
        Ok((cross, entropy))
    }
}
