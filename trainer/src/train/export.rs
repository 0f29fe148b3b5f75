//! What a run hands over: the weight average adopted (or the best-validated one), the
//! validation scores, the model, static weights, pose range and candidate lists to export, and
//! the run's configuration, progress and step profile.

use super::*;

impl Trainer {
    /// Replaces the parameters by their running average over the image iterations so far
    /// ([`TrainConfig::ema_half_life`]) and drops the average: what is exported, and where the
    /// later stages continue from (stage 4 starts an average of its own). A no-op without one.
    ///
    /// With validation snapshots ([`Trainer::validate_average`]), the best-scoring one is
    /// adopted instead; it is one of the averages, so the rule is "the best average seen".
    pub fn adopt_average(&mut self) -> Result<(), TrainError> {
        if let Some(mut a) = self.average.take() {
            a.swap()?;
        }
        if let Some((_, _, params)) = self.best.take() {
            let vars = self
                .varmap
                .data()
                .lock()
                .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))?;
            for (name, value) in &params {
                if let Some(var) = vars.get(name) {
                    var.set(value)?;
                }
            }
        }
        Ok(())
    }

    /// Scores the current parameters on the validation frames (the training frames when none
    /// are held out).
    pub fn validate(&self) -> Result<validation::ValidationScore, TrainError> {
        let frames = self.validation_frames();
        let poses: Vec<f32> = frames
            .iter()
            .flat_map(|f| f.pose_features.iter().copied())
            .collect();
        let w = self.weights_for_poses(poses, frames.len(), None)?;
        self.score_on_validation_frames(&w.flatten_all()?.to_vec1()?)
    }

    /// The initial weights' validation score: as scored at the start, or with learned outline
    /// offsets against the masks moved by the offsets learned so far, so that the guard
    /// compares both against the same outlines.
    fn initial_validation_now(&self) -> Result<validation::ValidationScore, TrainError> {
        match &self.initial_validation_weights {
            Some(dense) => self.score_on_validation_frames(dense),
            None => Ok(self.initial_score),
        }
    }

    /// The frames validation scores: the held-out ones, or the training frames when none are.
    fn validation_frames(&self) -> &[Frame] {
        if self.validation.is_empty() {
            &self.data.frames
        } else {
            &self.validation
        }
    }

    /// Scores dense weights (one `[V][J]` set per [`Trainer::validation_frames`] frame) against
    /// the masks moved by the outline offsets learned so far, if any.
    fn score_on_validation_frames(
        &self,
        dense: &[f32],
    ) -> Result<validation::ValidationScore, TrainError> {
        let offsets = self.outline_offsets()?;
        Ok(validation::score(
            &self.data,
            self.validation_frames(),
            dense,
            &self.edges,
            offsets.as_deref(),
        ))
    }

    /// Scores the running parameter average (the current parameters without one), logs the
    /// score and keeps a copy of the parameters when they are the best so far; returns the
    /// score.
    pub fn validate_average(&mut self) -> Result<validation::ValidationScore, TrainError> {
        if let Some(a) = &mut self.average {
            a.swap()?;
        }
        // Scored and copied while the average is in place; swapped back whatever happened.
        let scored = self.validate().and_then(|score| {
            let better = self
                .best
                .as_ref()
                .is_none_or(|(best, _, _)| !score.is_worse_than(best));
            let params = if better {
                Some(self.parameter_copies()?)
            } else {
                None
            };
            Ok((score, params))
        });
        if let Some(a) = &mut self.average {
            a.swap()?;
        }
        let (score, params) = scored?;
        self.validation_log.push((self.done, score));
        if let Some(params) = params {
            self.best = Some((score, self.done, params));
        }
        Ok(score)
    }

    /// Copies of every parameter, by name.
    pub(super) fn parameter_copies(&self) -> Result<NamedTensors, TrainError> {
        let vars = self
            .varmap
            .data()
            .lock()
            .map_err(|_| TrainError::Data("VarMap lock poisoned".into()))?;
        vars.iter()
            .map(|(name, var)| Ok((name.clone(), var.as_tensor().copy()?)))
            .collect()
    }

    /// The initial weights' validation score at the start (against the masks as they are) and
    /// the number of held-out frames.
    #[must_use]
    pub fn initial_validation(&self) -> (validation::ValidationScore, usize) {
        (self.initial_score, self.validation.len())
    }

    /// Every validation so far: `(image iteration, score)`.
    #[must_use]
    pub fn validation_log(&self) -> &[(u64, validation::ValidationScore)] {
        &self.validation_log
    }

    /// The iteration and score of the best average so far (what [`Trainer::adopt_average`]
    /// exports).
    #[must_use]
    pub fn best_validation(&self) -> Option<(u64, validation::ValidationScore)> {
        self.best.as_ref().map(|(s, i, _)| (*i, *s))
    }

    /// The validation report of the current parameters against the initial weights.
    pub fn validation_report(&self) -> Result<validation::ValidationReport, TrainError> {
        let learned_offset_px = self
            .outline_offsets()?
            .map(|o| o.iter().map(|&b| f64::from(b)).sum::<f64>() / o.len().max(1) as f64);
        Ok(validation::ValidationReport {
            learned_offset_px,
            initial: self.initial_validation_now()?,
            model: self.validate()?,
            held_out_frames: self.validation.len(),
        })
    }

    /// Where the iterations run so far spent their time ([`profile`]).
    #[must_use]
    pub fn profile(&self) -> &StepProfile {
        &self.profile
    }

    /// The network as `.skf` content with its candidate joints (the `CAND` section) and the
    /// range of its training poses (`PRNG`): what `trainer train` writes. Exporting the network
    /// alone would let every joint back into a softmax that was trained over the candidates
    /// only, and let the runtime ask it about poses it never saw.
    pub fn skf_model(&self) -> Result<skinfield_formats::skf::SkfModel, TrainError> {
        let net = self
            .net()
            .ok_or_else(|| TrainError::Data("the static baseline has no network".into()))?;
        let mut model = crate::skinnet::export::to_skf_model(net, &self.data.skeleton)?;
        model.candidates = self.export_candidates();
        model.pose_range = self.export_pose_range();
        Ok(model)
    }

    /// The network (`None` for the static baseline).
    #[must_use]
    pub fn net(&self) -> Option<&TrainableSkinNet> {
        match &self.model {
            Model::Net { net, .. } => Some(net),
            Model::Static { .. } => None,
        }
    }

    /// The static baseline's weights `[V, J]` (`None` for SkinNet).
    pub fn static_weights(&self) -> Result<Option<Vec<f32>>, TrainError> {
        match &self.model {
            Model::Static { .. } => Ok(Some(self.weights(&[0])?.flatten_all()?.to_vec1()?)),
            Model::Net { .. } => Ok(None),
        }
    }

    /// The per-feature range of the training frames' pose features (validation frames
    /// included, so what validation scored is what the runtime evaluates), or `None` when
    /// [`TrainConfig::clamp_pose_features`] is off.
    #[must_use]
    pub fn export_pose_range(&self) -> Option<skinfield_formats::skf::PoseRange> {
        let features = skinfield_formats::pose_feature_count(self.data.skeleton.len());
        self.config
            .clamp_pose_features
            .then(|| {
                skinfield_formats::skf::PoseRange::of(
                    features,
                    self.data
                        .frames
                        .iter()
                        .chain(&self.validation)
                        .map(|f| &f.pose_features[..]),
                )
            })
            .flatten()
    }

    /// The anchors and candidate joints to store in the exported `.skf` (the training template's
    /// vertices and their lists), or `None` when candidates are off.
    #[must_use]
    pub fn export_candidates(&self) -> Option<skinfield_formats::skf::Candidates> {
        self.candidates
            .as_ref()
            .map(|c| skinfield_formats::skf::Candidates {
                positions: self
                    .data
                    .template
                    .positions
                    .iter()
                    .map(|p| p.to_array())
                    .collect(),
                lists: c.lists.clone(),
                k: self.config.candidate_joints,
            })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// Vertex count of the training template the run trains on.
    #[must_use]
    pub fn training_vertex_count(&self) -> usize {
        self.data.template.vertex_count()
    }

    /// `(warm-start iterations done, image iterations done)`.
    #[must_use]
    pub fn progress(&self) -> (u64, u64) {
        (self.warm_done, self.done)
    }
}
