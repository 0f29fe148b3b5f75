//! Per-frame state: the joint palette (skinning matrices and their dual quaternions) and the
//! pose terms of the layers that see the input, computed once per frame, without allocating.

use alloc::vec;
use alloc::vec::Vec;
use core::sync::atomic::{AtomicU64, Ordering};

use glam::Mat4;
use skinfield_formats::{Pose, Skeleton, Transform, pose_features};

use crate::error::RuntimeError;
use crate::joint_map::JointMap;
use crate::model::SkinNet;
use crate::skinning::DualQuat;

/// Skinning matrices `world · inverse_bind` of every joint and their rigid parts as dual
/// quaternions. Buffers are allocated once by [`Palette::new`]; updates never allocate.
#[derive(Clone, Debug)]
pub struct Palette {
    matrices: Vec<Mat4>,
    dual_quats: Vec<DualQuat>,
    ready: bool,
}

impl Palette {
    /// A palette for `joints` joints (not ready until set).
    #[must_use]
    pub fn new(joints: usize) -> Self {
        Self {
            matrices: vec![Mat4::IDENTITY; joints],
            dual_quats: vec![DualQuat::IDENTITY; joints],
            ready: false,
        }
    }

    /// Number of joints.
    #[must_use]
    pub fn joint_count(&self) -> usize {
        self.matrices.len()
    }

    /// Whether a pose or matrices were set successfully.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// Skinning matrices.
    #[must_use]
    pub fn matrices(&self) -> &[Mat4] {
        &self.matrices
    }

    /// Dual quaternions of the skinning matrices.
    #[must_use]
    pub fn dual_quats(&self) -> &[DualQuat] {
        &self.dual_quats
    }

    /// Sets skinning matrices directly (from an engine's own animation system).
    pub fn set_matrices(&mut self, matrices: &[Mat4]) -> Result<(), RuntimeError> {
        self.ready = false;
        if matrices.len() != self.matrices.len() {
            return Err(RuntimeError::BufferLength {
                field: "matrices",
                len: matrices.len(),
                expected: self.matrices.len(),
            });
        }
        if let Some(j) = matrices.iter().position(|m| !m.is_finite()) {
            return Err(RuntimeError::NonFinite {
                field: "matrices",
                index: j,
            });
        }
        self.matrices.copy_from_slice(matrices);
        self.finish()
    }

    /// Forward kinematics of `pose` on `skeleton` (NaN or wrongly sized poses are errors).
    pub fn set_pose(&mut self, skeleton: &Skeleton, pose: &Pose) -> Result<(), RuntimeError> {
        self.ready = false;
        if skeleton.len() != self.matrices.len() {
            return Err(RuntimeError::BufferLength {
                field: "skeleton",
                len: skeleton.len(),
                expected: self.matrices.len(),
            });
        }
        skeleton.skinning_matrices(pose, &mut self.matrices)?;
        if let Some(j) = self.matrices.iter().position(|m| !m.is_finite()) {
            return Err(RuntimeError::NonFinite {
                field: "pose",
                index: j,
            });
        }
        self.finish()
    }

    fn finish(&mut self) -> Result<(), RuntimeError> {
        for (d, m) in self.dual_quats.iter_mut().zip(&self.matrices) {
            *d = DualQuat::from_mat4(m);
        }
        self.ready = true;
        Ok(())
    }
}

static NEXT_POSE: AtomicU64 = AtomicU64::new(1);

/// Everything a SkinNet frame needs besides the mesh: the palette, the pose features and the
/// per-frame bias of every layer.
#[derive(Clone, Debug)]
pub struct FrameState {
    model_id: u64,
    palette: Palette,
    features: Vec<f32>,
    frame_bias: Vec<f32>,
    /// The model pose assembled by [`FrameState::set_engine_pose`] (allocated once).
    mapped: Pose,
    ready: bool,
    /// Unique id of the last successful pose (process-wide), so state derived from a pose (the
    /// fast path's nodes) can tell whether it is current.
    generation: u64,
}

impl FrameState {
    /// Buffers sized for `model` (allocates once).
    #[must_use]
    pub fn new<W: AsRef<[f32]>>(model: &SkinNet<W>) -> Self {
        let l = model.layout();
        Self {
            model_id: model.id(),
            palette: Palette::new(model.joint_count()),
            features: vec![0.0; l.pose_w],
            frame_bias: vec![0.0; l.frame_bias_len],
            mapped: model.skeleton().bind_pose(),
            ready: false,
            generation: 0,
        }
    }

    /// Poses the frame: forward kinematics, pose features (clamped into the model's training
    /// range when its file has one, [`SkinNet::pose_range`]), pose terms. Never allocates; a
    /// NaN, infinite or wrongly sized pose is an error and leaves the frame not ready.
    pub fn set_pose<W: AsRef<[f32]>>(
        &mut self,
        model: &SkinNet<W>,
        pose: &Pose,
    ) -> Result<(), RuntimeError> {
        self.ready = false;
        if model.id() != self.model_id {
            return Err(RuntimeError::Mismatch { field: "frame" });
        }
        self.palette.set_pose(model.skeleton(), pose)?;
        pose_features(
            model.skeleton(),
            pose,
            model.config().up_axis,
            &mut self.features,
        )?;
        if let Some(i) = self.features.iter().position(|f| !f.is_finite()) {
            return Err(RuntimeError::NonFinite {
                field: "pose features",
                index: i,
            });
        }
        // Only what the network is asked about is clamped; the skinning matrices above keep the
        // real pose (skinfield_formats::skf::pose_range says why).
        for (f, &(low, high)) in self.features.iter_mut().zip(model.pose_range()) {
            *f = f.clamp(low, high);
        }
        model.frame_bias(&self.features, &mut self.frame_bias);
        if let Some(i) = self.frame_bias.iter().position(|f| !f.is_finite()) {
            return Err(RuntimeError::NonFinite {
                field: "frame bias",
                index: i,
            });
        }
        self.ready = true;
        self.generation = NEXT_POSE.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Poses the frame from an engine's local transforms, in the engine's joint order, through
    /// `map` (built for this model at load time). Never allocates; errors as
    /// [`JointMap::pose_into`] and [`FrameState::set_pose`].
    pub fn set_engine_pose<W: AsRef<[f32]>>(
        &mut self,
        model: &SkinNet<W>,
        map: &JointMap,
        engine_locals: &[Transform],
    ) -> Result<(), RuntimeError> {
        self.ready = false;
        if map.model_joint_count() != model.joint_count() {
            return Err(RuntimeError::Mismatch { field: "joint map" });
        }
        // `Vec::new` does not allocate: the buffer is only moved out and back.
        let mut pose = core::mem::replace(&mut self.mapped, Pose { locals: Vec::new() });
        let result = map
            .pose_into(engine_locals, &mut pose)
            .and_then(|()| self.set_pose(model, &pose));
        self.mapped = pose;
        result
    }

    /// The joint palette.
    #[must_use]
    pub fn palette(&self) -> &Palette {
        &self.palette
    }

    /// The pose features `θ̃` of the last pose.
    #[must_use]
    pub fn features(&self) -> &[f32] {
        &self.features
    }

    /// Whether the last [`FrameState::set_pose`] succeeded.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// Whether this frame state was made for `model` (by [`FrameState::new`]); another model's
    /// jobs refuse it.
    #[must_use]
    pub fn is_for<W: AsRef<[f32]>>(&self, model: &SkinNet<W>) -> bool {
        self.model_id == model.id()
    }

    pub(crate) fn model_id(&self) -> u64 {
        self.model_id
    }

    pub(crate) fn generation(&self) -> u64 {
        self.generation
    }

    pub(crate) fn frame_bias(&self) -> &[f32] {
        &self.frame_bias
    }
}
