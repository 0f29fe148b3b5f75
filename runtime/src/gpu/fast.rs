//! The fast path on the GPU (`shaders/fast.wgsl`): SkinNet at the nodes of a [`FastMesh`]
//! (the `skinnet_weights` kernel on an `N`-vertex node mesh), then per-vertex LBS, DQS or top-k
//! output from the bind-time data the CPU computed. Results equal the CPU's [`FastSkinJob`]
//! and [`TopKJob`] (`crate::fast`) to 1e-4 (quantised top-k weights within one unit).
//!
//! [`FastSkinJob`]: crate::FastSkinJob
//! [`TopKJob`]: crate::TopKJob

use glam::Vec3;

use super::GpuError;
use super::layout::{GpuFastParams, SkinnedVertex, WORKGROUP_THREADS, entry};
use super::mesh::{GpuMesh, read_buffer, read_vertices};
use super::model::GpuModel;
use super::skinner::{GpuSkinner, pipeline};
use crate::fast::{FastMesh, Influence, MAX_INFLUENCES};
use crate::{FrameState, Method, RuntimeError};

/// The fast-path pipelines (built once with the others by [`GpuSkinner::new`]).
pub(crate) struct FastPipelines {
    residuals: wgpu::ComputePipeline,
    lbs: wgpu::ComputePipeline,
    dqs: wgpu::ComputePipeline,
    top_k: wgpu::ComputePipeline,
}

impl FastPipelines {
    pub(super) fn new(device: &wgpu::Device, module: &wgpu::ShaderModule) -> Self {
        Self {
            residuals: pipeline(device, module, entry::FAST_RESIDUALS),
            lbs: pipeline(device, module, entry::FAST_LBS),
            dqs: pipeline(device, module, entry::FAST_DQS),
            top_k: pipeline(device, module, entry::FAST_TOP_K),
        }
    }
}

/// Joint-index type of the GPU top-k output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TopKIndexFormat {
    /// One byte per index (joint counts up to 256).
    U8,
    /// Two bytes per index.
    U16,
}

/// Weight type of the GPU top-k output (each vertex's weights sum exactly to one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TopKWeightFormat {
    /// unorm8 (255 is one).
    Unorm8,
    /// unorm16 (65535 is one).
    Unorm16,
    /// f32, multiples of 2⁻²⁴.
    F32,
}

/// What a [`GpuFastMesh`] computes besides SkinNet at its nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuFastOptions {
    /// Joints per vertex for DQS (1..=8).
    pub dqs_influences: usize,
    /// The top-k output's layout (`influences` 4 or 8), if wanted: buffers are sized for it.
    pub top_k: Option<(usize, TopKIndexFormat, TopKWeightFormat)>,
}

impl Default for GpuFastOptions {
    fn default() -> Self {
        Self {
            dqs_influences: 4,
            top_k: Some((4, TopKIndexFormat::U8, TopKWeightFormat::Unorm8)),
        }
    }
}

/// A [`FastMesh`] on the GPU: its node mesh (SkinNet inputs and outputs), the bind-time
/// interpolation and base weights, the residual buffers, the skinned-vertex output and the
/// top-k output.
pub struct GpuFastMesh {
    nodes: GpuMesh,
    vertex_count: u32,
    node_count: u32,
    params: GpuFastParams,
    output: wgpu::Buffer,
    top_indices: wgpu::Buffer,
    top_weights: wgpu::Buffer,
    top_bytes: (u64, u64),
    bind_residuals: wgpu::BindGroup,
    bind_lbs: wgpu::BindGroup,
    bind_dqs: wgpu::BindGroup,
    bind_top_k: wgpu::BindGroup,
}

/// What [`GpuSkinner::encode_fast`] records after SkinNet at the nodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FastOutputs {
    /// Skin the vertices into [`GpuFastMesh::output`].
    pub skinning: Option<Method>,
    /// Write the top-k indices and weights ([`GpuFastMesh::top_k_buffers`]).
    pub top_k: bool,
}

fn setting(field: &'static str, value: usize, accepted: &'static str) -> GpuError {
    GpuError::Setting {
        field,
        value,
        accepted,
    }
}

impl GpuSkinner {
    /// Uploads a [`FastMesh`] (bound on the CPU to the same `.skf`) with the rest `normals` of
    /// its vertices: a node mesh for SkinNet (its position terms computed now, submitted on
    /// `queue`), the interpolation and base weights, and output buffers.
    pub fn bind_fast_mesh(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        model: &GpuModel,
        mesh: &FastMesh,
        normals: &[Vec3],
        options: &GpuFastOptions,
    ) -> Result<GpuFastMesh, GpuError> {
        let v_count = mesh.vertex_count();
        let j = mesh.joint_count();
        if model.config().joint_count as usize != j {
            return Err(GpuError::Input(RuntimeError::BufferLength {
                field: "fast mesh joints",
                len: j,
                expected: model.config().joint_count as usize,
            }));
        }
        if normals.len() != v_count {
            return Err(GpuError::Input(RuntimeError::BufferLength {
                field: "normals",
                len: normals.len(),
                expected: v_count,
            }));
        }
        if let Some(index) = normals.iter().position(|n| !n.is_finite()) {
            return Err(GpuError::Input(RuntimeError::NonFinite {
                field: "normals",
                index,
            }));
        }
        if !(1..=MAX_INFLUENCES).contains(&options.dqs_influences) {
            return Err(setting("dqs_influences", options.dqs_influences, "1..=8"));
        }
        let (top_k, index_bytes, weight_format) = match options.top_k {
            None => (4, 1, 0),
            Some((k, idx, w)) => {
                if k != 4 && k != 8 {
                    return Err(setting("top_k influences", k, "4 or 8"));
                }
                if idx == TopKIndexFormat::U8 && j > 256 {
                    return Err(setting("top_k u8 indices: joint count", j, "1..=256"));
                }
                let ib = match idx {
                    TopKIndexFormat::U8 => 1,
                    TopKIndexFormat::U16 => 2,
                };
                let wf = match w {
                    TopKWeightFormat::Unorm8 => 0,
                    TopKWeightFormat::Unorm16 => 1,
                    TopKWeightFormat::F32 => 2,
                };
                (k, ib, wf)
            }
        };
        let rest = mesh.rest_positions();
        let node_positions: Vec<Vec3> = mesh
            .node_vertices()
            .iter()
            .map(|&v| rest[v as usize])
            .collect();
        let nodes = self.bind_mesh(
            device,
            queue,
            model,
            &node_positions,
            &vec![Vec3::Y; node_positions.len()],
        )?;
        let vertex_count = u32::try_from(v_count).map_err(|_| GpuError::TooLarge {
            what: "vertices",
            value: v_count as u64,
            limit: u32::MAX.into(),
        })?;
        let o = mesh.options();
        let (kb, k) = (o.base_influences, o.neighbours);
        let params = GpuFastParams {
            vertex_count,
            node_count: mesh.node_count() as u32,
            joint_count: j as u32,
            neighbours: k as u32,
            base_count: kb as u32,
            dqs_k: options.dqs_influences as u32,
            top_k: top_k as u32,
            index_bytes,
            weight_format,
            ..GpuFastParams::default()
        };
        self.check_groups(
            "fast-path vertex workgroups",
            u64::from(vertex_count).div_ceil(WORKGROUP_THREADS.into()),
        )?;

        // Bind-time data, laid out for the kernels.
        // The log-weight changes' reference (unused, so zero, without a base).
        let node_base = if kb > 0 {
            mesh.node_bind_weights().to_vec()
        } else {
            vec![0.0f32; mesh.node_count() * j]
        };
        let mut influences: Vec<Influence> = Vec::with_capacity(v_count * (kb + k));
        for v in 0..v_count {
            influences.extend_from_slice(&mesh.base()[v * kb..(v + 1) * kb]);
            influences.extend_from_slice(&mesh.interpolation()[v * k..(v + 1) * k]);
        }
        let rest_vertices: Vec<SkinnedVertex> = rest
            .iter()
            .zip(normals)
            .map(|(p, n)| SkinnedVertex {
                position: p.extend(1.0).to_array(),
                normal: n.extend(0.0).to_array(),
            })
            .collect();
        let v = u64::from(vertex_count);
        let none = wgpu::BufferUsages::empty();
        let copy_src = wgpu::BufferUsages::COPY_SRC;
        let params_buf = wgpu::util::DeviceExt::create_buffer_init(
            device,
            &wgpu::util::BufferInitDescriptor {
                label: Some("fast params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            },
        );
        let node_base_buf =
            self.storage_init(device, "fast node base", bytemuck::cast_slice(&node_base))?;
        let residuals = self.storage(
            device,
            "fast node residuals",
            (node_base.len() * 4) as u64,
            none,
        )?;
        let node_mats = self.storage(
            device,
            "fast node matrices",
            mesh.node_count() as u64 * 64,
            none,
        )?;
        let influences_buf = self.storage_init(
            device,
            "fast vertex influences",
            bytemuck::cast_slice(&influences),
        )?;
        let rest_buf = self.storage_init(
            device,
            "fast rest vertices",
            bytemuck::cast_slice(&rest_vertices),
        )?;
        let output = self.storage(
            device,
            "fast skinned vertices",
            v * size_of::<SkinnedVertex>() as u64,
            wgpu::BufferUsages::VERTEX | copy_src,
        )?;
        let weight_bytes = [1u64, 2, 4][weight_format as usize];
        let top_bytes = if options.top_k.is_some() {
            (
                v * top_k as u64 * u64::from(index_bytes),
                v * top_k as u64 * weight_bytes,
            )
        } else {
            (0, 0)
        };
        let top_indices = self.storage(
            device,
            "fast top-k indices",
            top_bytes.0,
            wgpu::BufferUsages::VERTEX | copy_src,
        )?;
        let top_weights = self.storage(
            device,
            "fast top-k weights",
            top_bytes.1,
            wgpu::BufferUsages::VERTEX | copy_src,
        )?;
        let buffers: [(u32, &wgpu::Buffer); 12] = [
            (7, &nodes.joint_mats),
            (9, &nodes.joint_dqs),
            (10, &nodes.skin_weights),
            (11, &rest_buf),
            (12, &output),
            (13, &params_buf),
            (14, &node_base_buf),
            (15, &residuals),
            (16, &node_mats),
            (17, &influences_buf),
            (18, &top_indices),
            (19, &top_weights),
        ];
        let group = |pipeline: &wgpu::ComputePipeline, bindings: &[u32]| {
            let entries: Vec<wgpu::BindGroupEntry<'_>> = bindings
                .iter()
                .filter_map(|&b| buffers.iter().find(|(n, _)| *n == b))
                .map(|&(binding, buf)| wgpu::BindGroupEntry {
                    binding,
                    resource: buf.as_entire_binding(),
                })
                .collect();
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            })
        };
        let p = &self.fast;
        Ok(GpuFastMesh {
            bind_residuals: group(&p.residuals, &[7, 10, 13, 14, 15, 16]),
            bind_lbs: group(&p.lbs, &[7, 11, 12, 13, 15, 16, 17]),
            bind_dqs: group(&p.dqs, &[7, 9, 11, 12, 13, 15, 17]),
            bind_top_k: group(&p.top_k, &[13, 15, 17, 18, 19]),
            nodes,
            vertex_count,
            node_count: params.node_count,
            params,
            output,
            top_indices,
            top_weights,
            top_bytes,
        })
    }

    /// Writes one frame's inputs from a posed [`FrameState`] (as
    /// [`GpuSkinner::upload_frame`]).
    pub fn upload_fast_frame(
        &self,
        queue: &wgpu::Queue,
        mesh: &GpuFastMesh,
        frame: &FrameState,
    ) -> Result<(), GpuError> {
        self.upload_frame(queue, &mesh.nodes, frame)
    }

    /// Records one fast frame into the caller's encoder: pose terms and SkinNet at the nodes,
    /// the residuals, then the requested outputs. Asking for top-k output from a mesh bound
    /// without a top-k layout is an error.
    pub fn encode_fast(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        mesh: &GpuFastMesh,
        outputs: FastOutputs,
    ) -> Result<(), GpuError> {
        if outputs.top_k && mesh.top_bytes.0 == 0 {
            return Err(setting(
                "top_k output",
                0,
                "a mesh bound with a top_k layout",
            ));
        }
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("skinfield fast frame"),
            timestamp_writes: None,
        });
        self.encode_weights(&mut pass, &mesh.nodes);
        let p = &self.fast;
        pass.set_pipeline(&p.residuals);
        pass.set_bind_group(0, &mesh.bind_residuals, &[]);
        self.dispatch(&mut pass, mesh.node_count.div_ceil(WORKGROUP_THREADS));
        let vertex_groups = mesh.vertex_count.div_ceil(WORKGROUP_THREADS);
        match outputs.skinning {
            Some(Method::Lbs) => {
                pass.set_pipeline(&p.lbs);
                pass.set_bind_group(0, &mesh.bind_lbs, &[]);
                self.dispatch(&mut pass, vertex_groups);
            }
            Some(Method::Dqs) => {
                pass.set_pipeline(&self.joint_dqs);
                pass.set_bind_group(0, &mesh.nodes.bind_joint_dqs, &[]);
                self.dispatch(
                    &mut pass,
                    (mesh.nodes.joint_count as u32).div_ceil(WORKGROUP_THREADS),
                );
                pass.set_pipeline(&p.dqs);
                pass.set_bind_group(0, &mesh.bind_dqs, &[]);
                self.dispatch(&mut pass, vertex_groups);
            }
            None => {}
        }
        if outputs.top_k {
            pass.set_pipeline(&p.top_k);
            pass.set_bind_group(0, &mesh.bind_top_k, &[]);
            self.dispatch(&mut pass, vertex_groups);
        }
        Ok(())
    }

    /// Uploads a frame, records it in a new encoder and submits it on `queue`.
    pub fn skin_fast(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        mesh: &GpuFastMesh,
        frame: &FrameState,
        outputs: FastOutputs,
    ) -> Result<wgpu::SubmissionIndex, GpuError> {
        self.upload_fast_frame(queue, mesh, frame)?;
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("skinfield fast frame"),
        });
        self.encode_fast(&mut encoder, mesh, outputs)?;
        Ok(queue.submit([encoder.finish()]))
    }
}

impl GpuFastMesh {
    /// Vertices of the mesh.
    #[must_use]
    pub fn vertex_count(&self) -> u32 {
        self.vertex_count
    }

    /// Nodes SkinNet runs at.
    #[must_use]
    pub fn node_count(&self) -> u32 {
        self.node_count
    }

    /// The kernels' constants.
    #[must_use]
    pub fn params(&self) -> &GpuFastParams {
        &self.params
    }

    /// The skinned vertices ([`SkinnedVertex`]; `STORAGE | VERTEX | COPY_SRC`).
    #[must_use]
    pub fn output(&self) -> &wgpu::Buffer {
        &self.output
    }

    /// The top-k joint indices and weights (`STORAGE | VERTEX | COPY_SRC`), `K` per vertex in
    /// the bound layout, byte for byte what [`crate::TopKJob`] writes into its slices.
    #[must_use]
    pub fn top_k_buffers(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.top_indices, &self.top_weights)
    }

    /// Reads the skinned vertices back (submits a copy and waits for the device).
    pub fn read_vertices(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<SkinnedVertex>, GpuError> {
        read_vertices(device, queue, &self.output, self.vertex_count)
    }

    /// Reads SkinNet's weights at the nodes of the last frame back, `[node][joint]`.
    pub fn read_node_weights(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<Vec<f32>, GpuError> {
        self.nodes.read_weights(device, queue)
    }

    /// Reads the top-k output back as bytes: (indices, weights), in the bound layout.
    pub fn read_top_k(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
    ) -> Result<(Vec<u8>, Vec<u8>), GpuError> {
        if self.top_bytes.0 == 0 {
            return Ok((Vec::new(), Vec::new()));
        }
        Ok((
            read_buffer(device, queue, &self.top_indices, self.top_bytes.0)?,
            read_buffer(device, queue, &self.top_weights, self.top_bytes.1)?,
        ))
    }
}
