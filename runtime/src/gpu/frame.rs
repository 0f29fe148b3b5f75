//! One frame: the pose's inputs uploaded from the CPU's frame state, and the pose terms,
//! SkinNet, softmax and LBS or DQS recorded into the caller's encoder.

use glam::Mat4;

use super::GpuError;
use super::layout::{SKINNET_TILE, WORKGROUP_THREADS};
use super::mesh::GpuMesh;
use super::skinner::GpuSkinner;
use crate::{FrameState, Method, RuntimeError};

impl GpuSkinner {
    /// Writes one frame's inputs from a posed [`FrameState`] (the same
    /// [`FrameState::set_pose`] / [`FrameState::set_engine_pose`] as the CPU path): its skinning
    /// matrices and pose features. A frame without a pose is refused.
    pub fn upload_frame(
        &self,
        queue: &wgpu::Queue,
        mesh: &GpuMesh,
        frame: &FrameState,
    ) -> Result<(), GpuError> {
        if !frame.is_ready() {
            return Err(GpuError::Input(RuntimeError::NoPose));
        }
        self.upload_raw(queue, mesh, frame.palette().matrices(), frame.features())
    }

    /// Writes one frame's inputs given directly: the skinning matrices (`world · inverse_bind`,
    /// one per joint) and the pose features (`skinfield_formats::pose_features`, 3 per joint).
    pub fn upload_raw(
        &self,
        queue: &wgpu::Queue,
        mesh: &GpuMesh,
        skinning: &[Mat4],
        features: &[f32],
    ) -> Result<(), GpuError> {
        if skinning.len() != mesh.joint_count {
            return Err(GpuError::Input(RuntimeError::BufferLength {
                field: "skinning matrices",
                len: skinning.len(),
                expected: mesh.joint_count,
            }));
        }
        if features.len() != mesh.pose_width {
            return Err(GpuError::Input(RuntimeError::BufferLength {
                field: "pose features",
                len: features.len(),
                expected: mesh.pose_width,
            }));
        }
        queue.write_buffer(&mesh.joint_mats, 0, bytemuck::cast_slice(skinning));
        if !features.is_empty() {
            queue.write_buffer(&mesh.features, 0, bytemuck::cast_slice(features));
        }
        Ok(())
    }

    /// Records one frame into the caller's encoder: pose terms, SkinNet and softmax, then LBS or
    /// DQS into [`GpuMesh::output`]. The frame's inputs come from the last
    /// [`GpuSkinner::upload_frame`] (queue writes land before the next submission).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, mesh: &GpuMesh, method: Method) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("skinfield frame"),
            timestamp_writes: None,
        });
        self.encode_weights(&mut pass, mesh);
        let vertex_groups = mesh.vertex_count.div_ceil(WORKGROUP_THREADS);
        match method {
            Method::Lbs => {
                pass.set_pipeline(&self.lbs);
                pass.set_bind_group(0, &mesh.bind_lbs, &[]);
                self.dispatch(&mut pass, vertex_groups);
            }
            Method::Dqs => {
                pass.set_pipeline(&self.joint_dqs);
                pass.set_bind_group(0, &mesh.bind_joint_dqs, &[]);
                self.dispatch(
                    &mut pass,
                    (mesh.joint_count as u32).div_ceil(WORKGROUP_THREADS),
                );
                pass.set_pipeline(&self.dqs);
                pass.set_bind_group(0, &mesh.bind_dqs, &[]);
                self.dispatch(&mut pass, vertex_groups);
            }
        }
    }

    /// Records the pose terms and SkinNet with softmax over `mesh`'s vertices into `pass`.
    pub(super) fn encode_weights(&self, pass: &mut wgpu::ComputePass<'_>, mesh: &GpuMesh) {
        let pipes = self.pipelines(mesh.format);
        pass.set_pipeline(&pipes.pose_terms);
        pass.set_bind_group(0, &mesh.bind_pose_terms, &[]);
        self.dispatch(pass, mesh.term_count.div_ceil(WORKGROUP_THREADS));
        pass.set_pipeline(&pipes.skinnet);
        pass.set_bind_group(0, &mesh.bind_skinnet, &[]);
        self.dispatch(pass, mesh.vertex_count.div_ceil(SKINNET_TILE));
    }

    /// Uploads a frame, records it in a new encoder and submits it on `queue`.
    pub fn skin(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mesh: &GpuMesh,
        frame: &FrameState,
        method: Method,
    ) -> Result<wgpu::SubmissionIndex, GpuError> {
        self.upload_frame(queue, mesh, frame)?;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("skinfield frame"),
        });
        self.encode(&mut encoder, mesh, method);
        Ok(queue.submit([encoder.finish()]))
    }
}
