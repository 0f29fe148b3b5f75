//! A mesh bound to a model on the device: rest vertices, the position terms computed once, the
//! per-frame input buffers, the output vertex buffer and every kernel's bind group; and reading
//! results back.

use std::sync::mpsc;

use glam::Vec3;
use skinfield_formats::skf::ModelConfig;
use skinfield_formats::skf::candidates::NO_JOINT;
use wgpu::util::DeviceExt;

use super::GpuError;
use super::layout::{SKINNET_TILE, SkinnedVertex, WeightFormat};
use super::model::GpuModel;
use super::skinner::GpuSkinner;
use crate::RuntimeError;

/// A mesh bound to a model: rest vertices, precomputed position terms, the per-frame inputs and
/// the output vertex buffer, with the bind groups of every kernel.
pub struct GpuMesh {
    pub(super) format: WeightFormat,
    pub(super) vertex_count: u32,
    pub(super) joint_count: usize,
    pub(super) pose_width: usize,
    pub(super) term_count: u32,
    pub(super) features: wgpu::Buffer,
    pub(super) joint_mats: wgpu::Buffer,
    pub(super) joint_dqs: wgpu::Buffer,
    pub(super) skin_weights: wgpu::Buffer,
    pub(super) output: wgpu::Buffer,
    pub(super) bind_pose_terms: wgpu::BindGroup,
    pub(super) bind_joint_dqs: wgpu::BindGroup,
    pub(super) bind_skinnet: wgpu::BindGroup,
    pub(super) bind_lbs: wgpu::BindGroup,
    pub(super) bind_dqs: wgpu::BindGroup,
}

/// `[x̂, γ(x̂)]` of every position ([`ModelConfig::position_input`], the CPU path's and the
/// trainer's encoding) appended to `out`. Done on the CPU because WGSL's `sin`/`cos` are only
/// accurate to about 2⁻¹¹ and only near zero.
pub(crate) fn position_inputs(config: &ModelConfig, positions: &[Vec3], out: &mut Vec<f32>) {
    out.reserve(positions.len() * config.position_width());
    for &p in positions {
        out.extend(config.position_input(p));
    }
}

impl GpuSkinner {
    /// Binds a mesh (canonical positions and normals, one per vertex) to `model`: uploads it,
    /// allocates the per-frame and output buffers, and computes the per-vertex position terms
    /// on the GPU (submitted on `queue`; no wait).
    pub fn bind_mesh(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        model: &GpuModel,
        positions: &[Vec3],
        normals: &[Vec3],
    ) -> Result<GpuMesh, GpuError> {
        let v_count = positions.len();
        if v_count == 0 {
            return Err(GpuError::Input(RuntimeError::VertexCount(0)));
        }
        if normals.len() != v_count {
            return Err(GpuError::Input(RuntimeError::BufferLength {
                field: "normals",
                len: normals.len(),
                expected: v_count,
            }));
        }
        for (field, data) in [("positions", positions), ("normals", normals)] {
            if let Some(index) = data.iter().position(|p| !p.is_finite()) {
                return Err(GpuError::Input(RuntimeError::NonFinite { field, index }));
            }
        }
        let vertex_count = u32::try_from(v_count).map_err(|_| GpuError::TooLarge {
            what: "vertices",
            value: v_count as u64,
            limit: u32::MAX.into(),
        })?;
        let mut params = model.params;
        params.vertex_count = vertex_count;
        let v = v_count as u64;
        let (h0, hs) = (
            u64::from(params.term0_width),
            u64::from(params.term_skip_width),
        );
        let term_count = params.term0_width + params.term_skip_width;
        let joints = params.joint_count as usize;
        let pose_width = params.pose_width as usize;
        let position_groups =
            self.check_groups("position-term workgroups", (v * (h0 + hs)).div_ceil(64))?;
        self.check_groups("SkinNet workgroups", v.div_ceil(SKINNET_TILE.into()))?;

        let mut encoding = Vec::new();
        position_inputs(&model.config, positions, &mut encoding);
        let rest: Vec<SkinnedVertex> = positions
            .iter()
            .zip(normals)
            .map(|(p, n)| SkinnedVertex {
                position: p.extend(1.0).to_array(),
                normal: n.extend(0.0).to_array(),
            })
            .collect();
        let params_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("skinfield params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let none = wgpu::BufferUsages::empty();
        let copy_dst = wgpu::BufferUsages::COPY_DST;
        let copy_src = wgpu::BufferUsages::COPY_SRC;
        let encoding_buf =
            self.storage_init(device, "position encoding", bytemuck::cast_slice(&encoding))?;
        let rest_buf = self.storage_init(device, "rest vertices", bytemuck::cast_slice(&rest))?;
        // Each vertex takes its nearest anchor's list (the CPU path's rule); one unused word
        // without candidates, since the kernel's layout always has the binding.
        let lists: Vec<u32> = match &model.anchors {
            Some(a) => a.lists_for(positions).into_iter().map(u32::from).collect(),
            None => vec![u32::from(NO_JOINT)],
        };
        let candidates =
            self.storage_init(device, "candidate joints", bytemuck::cast_slice(&lists))?;
        let term0 = self.storage(device, "layer-0 position terms", v * h0 * 4, none)?;
        let term_skip = self.storage(device, "skip-layer position terms", v * hs * 4, none)?;
        let features = self.storage(device, "pose features", pose_width as u64 * 4, copy_dst)?;
        let joint_mats = self.storage(device, "skinning matrices", joints as u64 * 64, copy_dst)?;
        let pose_terms = self.storage(device, "pose terms", u64::from(term_count) * 4, none)?;
        let joint_dqs = self.storage(device, "joint dual quaternions", joints as u64 * 32, none)?;
        let skin_weights =
            self.storage(device, "skinning weights", v * joints as u64 * 4, copy_src)?;
        let output = self.storage(
            device,
            "skinned vertices",
            v * size_of::<SkinnedVertex>() as u64,
            wgpu::BufferUsages::VERTEX | copy_src,
        )?;

        let buffers: [(u32, &wgpu::Buffer); 14] = [
            (0, &params_buf),
            (1, &model.weights),
            (2, &model.biases),
            (3, &encoding_buf),
            (4, &term0),
            (5, &term_skip),
            (6, &features),
            (7, &joint_mats),
            (8, &pose_terms),
            (9, &joint_dqs),
            (10, &skin_weights),
            (11, &rest_buf),
            (12, &output),
            (20, &candidates),
        ];
        let group = |pipeline: &wgpu::ComputePipeline, bindings: &[u32]| {
            let entries: Vec<wgpu::BindGroupEntry<'_>> = bindings
                .iter()
                .filter_map(|&b| buffers.iter().find(|(n, _)| *n == b))
                .map(|&(b, buffer)| wgpu::BindGroupEntry {
                    binding: b,
                    resource: buffer.as_entire_binding(),
                })
                .collect();
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            })
        };
        let pipes = self.pipelines(model.format);
        let bind_position_terms = group(&pipes.position_terms, &[0, 1, 3, 4, 5]);
        let mesh = GpuMesh {
            format: model.format,
            vertex_count,
            joint_count: joints,
            pose_width,
            term_count,
            bind_pose_terms: group(&pipes.pose_terms, &[0, 1, 2, 6, 8]),
            bind_joint_dqs: group(&self.joint_dqs, &[0, 7, 9]),
            bind_skinnet: group(&pipes.skinnet, &[0, 1, 2, 4, 5, 8, 10, 20]),
            bind_lbs: group(&self.lbs, &[0, 7, 10, 11, 12]),
            bind_dqs: group(&self.dqs, &[0, 7, 9, 10, 11, 12]),
            features,
            joint_mats,
            joint_dqs,
            skin_weights,
            output,
        };
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("bind mesh"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("position terms"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipes.position_terms);
            pass.set_bind_group(0, &bind_position_terms, &[]);
            self.dispatch(&mut pass, position_groups);
        }
        queue.submit([encoder.finish()]);
        Ok(mesh)
    }
}

pub(super) fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, GpuError> {
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("read-back"),
    });
    encoder.copy_buffer_to_buffer(src, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    let (tx, rx) = mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        // The receiver outlives the poll below; a failed send only means it was dropped.
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely())?;
    rx.recv().map_err(|_| GpuError::MapDropped)??;
    let bytes = staging.get_mapped_range(..)?.to_vec();
    staging.unmap();
    Ok(bytes)
}

/// Reads `count` skinned vertices back from `src` (an output vertex buffer).
pub(super) fn read_vertices(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    src: &wgpu::Buffer,
    count: u32,
) -> Result<Vec<SkinnedVertex>, GpuError> {
    let size = u64::from(count) * size_of::<SkinnedVertex>() as u64;
    Ok(bytemuck::pod_collect_to_vec(&read_buffer(
        device, queue, src, size,
    )?))
}

impl GpuMesh {
    /// Vertices of the mesh.
    #[must_use]
    pub fn vertex_count(&self) -> u32 {
        self.vertex_count
    }

    /// The skinned vertices ([`SkinnedVertex`], 32-byte stride; `STORAGE | VERTEX | COPY_SRC`),
    /// for the engine to draw from.
    #[must_use]
    pub fn output(&self) -> &wgpu::Buffer {
        &self.output
    }

    /// SkinNet's weights of the last frame, `[vertex][joint]` (`STORAGE | COPY_SRC`).
    #[must_use]
    pub fn weights_buffer(&self) -> &wgpu::Buffer {
        &self.skin_weights
    }

    /// Reads the skinned vertices back (submits a copy and waits for the device).
    pub fn read_vertices(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<SkinnedVertex>, GpuError> {
        read_vertices(device, queue, &self.output, self.vertex_count)
    }

    /// Reads SkinNet's weights of the last frame back, `[vertex][joint]`.
    pub fn read_weights(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<f32>, GpuError> {
        let size = u64::from(self.vertex_count) * self.joint_count as u64 * 4;
        Ok(bytemuck::pod_collect_to_vec(&read_buffer(
            device,
            queue,
            &self.skin_weights,
            size,
        )?))
    }
}
