//! A learned outline offset per camera: how far the masks' outlines lie outside the true
//! silhouette, estimated with the weights so that a biased segmentation does not bend them.
//!
//! Real masks come from a segmentation (a matting network, a chroma key) whose outline sits a
//! fraction of a pixel to a pixel outside or inside the subject's, much the same all round.
//! On the built-in capture such a margin costs the trained model a third of its gain over bone
//! heat at ±0.5 px and all of it at +1 px (`docs/experiments/fidelity.md`, *Masks with a
//! margin*): the silhouette terms can only meet a grown outline by bulging the mesh, which LBS
//! weights do by collapsing and swelling joints, the very artefacts training should remove.
//!
//! Here every camera `c` has an offset `b_c` (pixels, positive: the mask lies outside the
//! mesh's outline), and the silhouette terms compare the mesh's outline with the mask's moved
//! inwards by `b_c` ([`crate::losses::silhouette::view_terms_with_offset`]). Weights cannot fit
//! a uniform margin: the middle of a limb is carried by one bone, so its cross-section does not
//! change with the weights, and only `b_c` can take the margin up there. One offset per camera,
//! not per view: a segmentation's bias depends on the camera (resolution, focus, background)
//! far more than on the frame, and a per-view offset could also absorb a pose's real errors.
//!
//! The offsets start at zero and take Adam steps of their own learning rate (pixels per step)
//! under the image iterations' schedule. They fit the silhouette *distances* (L1), not the
//! Huber terms the weights fit: the distances of a uniform shift are smallest at the median of
//! the signed margins, the Huber terms (sub-pixel residuals lie within their width) at the mean.
//! A trained LBS model is thinner than exact masks at bent joints, on a small part of its
//! outline: the mean (+0.047 px on the built-in capture's exact masks, +1.085 on masks grown by
//! one pixel) takes that shortfall for a margin, the median does not (+0.003 and +1.003 px).
//!
//! On by default (since 2026-12-07; [`OutlineOffsetConfig`]): a user's masks come from a
//! segmentation, and on exact masks the offsets stay within 0.05 px of zero and cost nothing
//! one run's noise resolves (`docs/experiments/fidelity.md`, *Outline offsets as the default*).
//! `"outline_offset": {"enabled": false}` (`trainer train --no-outline-offsets`) trains on the
//! masks as they are.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor, Var};
use serde::{Deserialize, Serialize};

use crate::optim::{Adam, AdamConfig};

/// Learned outline offsets (a [`super::TrainConfig`] field; on by default).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutlineOffsetConfig {
    /// Learn one outline offset per camera with the weights (for masks from a segmentation
    /// that may grow or shrink every outline); `false` trusts the masks' outlines as they are.
    pub enabled: bool,
    /// Adam's learning rate of the offsets (pixels per step), scaled by the image iterations'
    /// schedule (warm-up and cosine decay).
    pub lr: f64,
}

impl Default for OutlineOffsetConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            lr: 1e-2,
        }
    }
}

impl OutlineOffsetConfig {
    /// The first invalid field's name.
    pub fn validate(&self) -> Result<(), &'static str> {
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return Err("outline_offset.lr");
        }
        Ok(())
    }
}

/// The offsets of every camera and their optimiser.
pub(crate) struct OutlineOffsets {
    offsets: Var,
    optimiser: Adam,
    config: OutlineOffsetConfig,
}

/// The checkpoint name of the offsets; their optimiser's state is under `outline_adam.`.
const NAME: &str = "outline_offset";

impl OutlineOffsets {
    /// Zero offsets for `cameras` cameras.
    pub(crate) fn new(cameras: usize, config: OutlineOffsetConfig) -> candle_core::Result<Self> {
        let offsets = Var::zeros(cameras, DType::F32, &Device::Cpu)?;
        let adam = AdamConfig {
            lr: config.lr,
            clip: None,
            ..AdamConfig::default()
        };
        let optimiser = Adam::new(vec![(NAME.to_string(), offsets.clone())], adam)?;
        Ok(Self {
            offsets,
            optimiser,
            config,
        })
    }

    /// The offset of each view, `[views]`, for views seen by cameras `cameras` (differentiable
    /// with respect to the offsets).
    pub(crate) fn per_view(&self, cameras: &[u32]) -> candle_core::Result<Tensor> {
        let index = Tensor::new(cameras, &Device::Cpu)?;
        self.offsets.as_tensor().index_select(&index, 0)
    }

    /// One Adam step at learning rate `lr` from the gradients of a step whose loss took
    /// [`OutlineOffsets::per_view`].
    pub(crate) fn step(
        &mut self,
        grads: &candle_core::backprop::GradStore,
        lr: f64,
    ) -> candle_core::Result<()> {
        self.optimiser.set_lr(lr);
        self.optimiser.step(grads)
    }

    /// The configured learning rate (before the schedule).
    pub(crate) fn lr(&self) -> f64 {
        self.config.lr
    }

    /// Every camera's offset (pixels).
    pub(crate) fn values(&self) -> candle_core::Result<Vec<f32>> {
        self.offsets.as_tensor().to_vec1()
    }

    /// Sets every camera's offset (pixels), leaving the optimiser's moments as they are.
    pub(crate) fn set_values(&mut self, values: &[f32]) -> Result<(), String> {
        let cameras = self.offsets.elem_count();
        if values.len() != cameras {
            return Err(format!(
                "{} outline offsets for {cameras} cameras",
                values.len()
            ));
        }
        let t = Tensor::new(values, &Device::Cpu).map_err(|e| e.to_string())?;
        self.offsets.set(&t).map_err(|e| e.to_string())
    }

    /// The state for a checkpoint: the offsets and their optimiser's moments.
    pub(crate) fn state_tensors(&self) -> candle_core::Result<HashMap<String, Tensor>> {
        let mut out = HashMap::new();
        out.insert(NAME.to_string(), self.offsets.as_tensor().clone());
        for (k, v) in self.optimiser.state_tensors()? {
            out.insert(format!("outline_adam.{k}"), v);
        }
        Ok(out)
    }

    /// Restores what [`OutlineOffsets::state_tensors`] wrote.
    pub(crate) fn load_state_tensors(
        &mut self,
        state: &HashMap<String, Tensor>,
    ) -> Result<(), String> {
        let t = state
            .get(NAME)
            .ok_or_else(|| format!("`{NAME}` is missing"))?;
        if t.shape() != self.offsets.shape() {
            return Err(format!("`{NAME}` has shape {:?}", t.dims()));
        }
        self.offsets
            .set(&t.to_dtype(DType::F32).map_err(|e| e.to_string())?)
            .map_err(|e| format!("`{NAME}`: {e}"))?;
        let own: HashMap<String, Tensor> = state
            .iter()
            .filter_map(|(k, v)| Some((k.strip_prefix("outline_adam.")?.to_string(), v.clone())))
            .collect();
        self.optimiser
            .load_state_tensors(&own)
            .map_err(|e| format!("`outline_adam.*`: {e}"))
    }
}
