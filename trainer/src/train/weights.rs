//! The model's weights for training frames: at the training vertices or at drawn query points,
//! for the frames' own poses or for given ones, with the initial weights and the skinning
//! matrices they are compared with.

use super::*;

impl Trainer {
    /// Weights `[B, V, J]` for the given frames, queried at the training vertices.
    pub fn weights(&self, frames: &[usize]) -> Result<Tensor, TrainError> {
        self.weights_at(frames, None)
    }

    /// Weights `[B, V, J]` for the given frames, SkinNet queried at rows `query` (`[V]`) of the
    /// full-resolution query points, or at the training vertices themselves (`None`).
    pub(super) fn weights_at(
        &self,
        frames: &[usize],
        query: Option<&Tensor>,
    ) -> Result<Tensor, TrainError> {
        self.weights_for_poses(self.pose_rows(frames), frames.len(), query)
    }

    /// SkinNet's weights `[B, V, J]` for the current image iteration: [`Self::weights_at`], with
    /// each row's pose input made local ([`pose_locality`]) when [`TrainConfig::pose_locality`]
    /// is on and the run has candidate joints.
    pub(super) fn image_weights(
        &self,
        frames: &[usize],
        query: Option<&Tensor>,
    ) -> Result<Tensor, TrainError> {
        if !self.config.pose_locality {
            return self.weights_at(frames, query);
        }
        let Model::Net { net, .. } = &self.model else {
            return self.weights_at(frames, query);
        };
        let (rows, Some(mask)) = self.net_rows(query)? else {
            return self.weights_at(frames, query);
        };
        let j = self.data.skeleton.len();
        let relevant: Vec<bool> = mask
            .flatten_all()?
            .to_vec1::<f32>()?
            .iter()
            .map(|&m| m == 0.0)
            .collect();
        let poses: Vec<&[f32]> = frames
            .iter()
            .map(|&f| &self.data.frames[f].pose_features[..])
            .collect();
        let pool: Vec<&[f32]> = self
            .data
            .frames
            .iter()
            .map(|f| &f.pose_features[..])
            .collect();
        let phase = PHASE_POSE_LOCALITY_OFFSET + PHASE_IMAGE;
        let mut rng = frame_rng(self.config.seed, phase, self.done);
        let local = pose_locality::LocalPoses::draw(&poses, &pool, &relevant, j, &mut rng)
            .map_err(|e| TrainError::Data(format!("pose locality: {e}")))?;
        Ok(net.forward_local(&rows, &Arc::new(local), Some(&mask))?)
    }

    /// The concatenated pose features of training frames `frames`.
    pub(super) fn pose_rows(&self, frames: &[usize]) -> Vec<f32> {
        frames
            .iter()
            .flat_map(|&f| self.data.frames[f].pose_features.iter().copied())
            .collect()
    }

    /// The pose features `[B, 3J]` of training frames `frames`.
    pub(super) fn pose_tensor(&self, frames: &[usize]) -> Result<Tensor, TrainError> {
        let j = self.data.skeleton.len();
        Ok(Tensor::from_vec(
            self.pose_rows(frames),
            (frames.len(), 3 * j),
            &Device::Cpu,
        )?)
    }

    /// SkinNet's encoded input rows and candidate mask at query rows `query` of the
    /// full-resolution query points, or at the training vertices (`None`).
    pub(super) fn net_rows(
        &self,
        query: Option<&Tensor>,
    ) -> Result<(Tensor, Option<Tensor>), TrainError> {
        let Model::Net {
            encoded,
            query_encoded,
            ..
        } = &self.model
        else {
            return Err(TrainError::Data(
                "the static baseline has no network".into(),
            ));
        };
        Ok(match (query, query_encoded) {
            (Some(q), Some(points)) => (
                points.index_select(q, 0)?,
                self.candidates
                    .as_ref()
                    .map(|c| c.query_mask.index_select(q, 0))
                    .transpose()?,
            ),
            _ => (
                encoded.clone(),
                self.candidates.as_ref().map(|c| c.mask.clone()),
            ),
        })
    }

    /// Weights `[B, V, J]` for `b` poses given by their concatenated pose features.
    pub(super) fn weights_for_poses(
        &self,
        poses: Vec<f32>,
        b: usize,
        query: Option<&Tensor>,
    ) -> Result<Tensor, TrainError> {
        let j = self.data.skeleton.len();
        Ok(match &self.model {
            Model::Net { net, .. } => {
                let (rows, mask) = self.net_rows(query)?;
                net.forward_masked(
                    &rows,
                    &Tensor::from_vec(poses, (b, 3 * j), &Device::Cpu)?,
                    mask.as_ref(),
                )?
            }
            Model::Static { logits } => {
                let logits = match &self.candidates {
                    Some(c) => logits.as_tensor().broadcast_add(&c.mask)?,
                    None => logits.as_tensor().clone(),
                };
                let w = softmax_last(&logits)?;
                let (v, _) = w.dims2()?;
                w.unsqueeze(0)?.broadcast_as((b, v, j))?.contiguous()?
            }
        })
    }

    /// The query rows of one iteration of `phase`: a seeded member of every training vertex's
    /// cell ([`queries::QueryCells::draw`]), or `None` (query the training vertices) without
    /// query cells or with `full_resolution_queries` off.
    pub(super) fn draw_queries(
        &self,
        phase: u64,
        iteration: u64,
    ) -> Result<Option<Tensor>, TrainError> {
        match (&self.data.queries, &self.query_init) {
            (Some(q), Some(_)) if self.config.full_resolution_queries => {
                let mut rng = frame_rng(self.config.seed, PHASE_QUERY_OFFSET + phase, iteration);
                let rows = q.draw(&mut rng);
                let v = rows.len();
                Ok(Some(Tensor::from_vec(rows, v, &Device::Cpu)?))
            }
            _ => Ok(None),
        }
    }

    /// The initial weights `[1, V, J]` at query rows `query`, or at the training vertices
    /// (`None`).
    pub(super) fn init_at(&self, query: Option<&Tensor>) -> Result<Tensor, TrainError> {
        match (&self.query_init, query) {
            (Some(full), Some(q)) => Ok(full.index_select(q, 0)?.unsqueeze(0)?),
            _ => Ok(self.init.clone()),
        }
    }

    /// Skinning matrices `[B, J, 12]` of training frames `frames`, with their pose
    /// corrections when [`PoseRefinementConfig::enabled`] (differentiable in them).
    pub(super) fn frame_skinning(&self, frames: &[usize]) -> Result<Tensor, TrainError> {
        let mats: Vec<Vec<Mat4>> = frames
            .iter()
            .map(|&f| self.data.frames[f].skinning.clone())
            .collect();
        let base = skinning_tensor(&mats, &Device::Cpu)?;
        Ok(match &self.pose_refinement {
            Some(r) => r.apply(frames, &base)?,
            None => base,
        })
    }

    /// The homogeneous rest positions `[V, 4]` the batch is skinned from: the query rows' own
    /// positions with [`TrainConfig::consistent_queries`], else the training vertices'.
    pub(super) fn rest_at(&self, query: Option<&Tensor>) -> Result<Tensor, TrainError> {
        match (&self.query_rest, query) {
            (Some(rest), Some(q)) => Ok(rest.index_select(q, 0)?),
            _ => Ok(self.rest.clone()),
        }
    }
}
