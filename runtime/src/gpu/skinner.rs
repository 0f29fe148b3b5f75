//! The GPU skinner: pipelines, model and mesh binding, per-frame upload, dispatch, read-back.

use std::sync::mpsc;

use glam::{Mat4, Vec3};
use half::f16;
use skinfield_formats::skf::candidates::NO_JOINT;
use skinfield_formats::skf::{Dtype, ModelConfig, Net, SkfView, TensorView};
use wgpu::util::DeviceExt;

use super::GpuError;
use super::layout::{
    GpuLayer, GpuParams, MAX_GPU_LAYERS, MAX_GPU_WIDTH, SKINNET_TILE, SkinnedVertex,
    WORKGROUP_THREADS, WeightFormat, entry, shader_source,
};
use crate::candidates::AnchorSet;
use crate::{FrameState, Method, RuntimeError};

struct FormatPipelines {
    position_terms: wgpu::ComputePipeline,
    pose_terms: wgpu::ComputePipeline,
    skinnet: wgpu::ComputePipeline,
}

/// The pipelines, built once per device.
pub struct GpuSkinner {
    f16: FormatPipelines,
    f32: FormatPipelines,
    pub(super) joint_dqs: wgpu::ComputePipeline,
    lbs: wgpu::ComputePipeline,
    dqs: wgpu::ComputePipeline,
    pub(super) fast: super::fast::FastPipelines,
    pub(super) limits: wgpu::Limits,
}

/// A SkinNet bound to a device: weights and biases in storage buffers.
pub struct GpuModel {
    config: ModelConfig,
    format: WeightFormat,
    params: GpuParams,
    weights: wgpu::Buffer,
    biases: wgpu::Buffer,
    /// The model's candidate joints (`CAND`), turned into per-vertex lists at bind time.
    anchors: Option<AnchorSet>,
}

/// A mesh bound to a model: rest vertices, precomputed position terms, the per-frame inputs and
/// the output vertex buffer, with the bind groups of every kernel.
pub struct GpuMesh {
    format: WeightFormat,
    vertex_count: u32,
    pub(super) joint_count: usize,
    pose_width: usize,
    term_count: u32,
    features: wgpu::Buffer,
    pub(super) joint_mats: wgpu::Buffer,
    pub(super) joint_dqs: wgpu::Buffer,
    pub(super) skin_weights: wgpu::Buffer,
    output: wgpu::Buffer,
    bind_pose_terms: wgpu::BindGroup,
    pub(super) bind_joint_dqs: wgpu::BindGroup,
    bind_skinnet: wgpu::BindGroup,
    bind_lbs: wgpu::BindGroup,
    bind_dqs: wgpu::BindGroup,
}

pub(super) fn pipeline(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry_point),
        layout: None,
        module,
        entry_point: Some(entry_point),
        compilation_options: wgpu::PipelineCompilationOptions::default(),
        cache: None,
    })
}

fn require(name: &'static str, value: u64, required: u64) -> Result<(), GpuError> {
    if value < required {
        Err(GpuError::DeviceLimit {
            name,
            value,
            required,
        })
    } else {
        Ok(())
    }
}

/// `(x, y)` workgroups covering `groups` with each dimension ≤ `max` (the kernels rebuild the
/// linear index as `y · x_count + x` and skip the excess).
fn split_dispatch(groups: u32, max: u32) -> (u32, u32) {
    if groups <= max {
        (groups, 1)
    } else {
        (max, groups.div_ceil(max))
    }
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

fn check_shape(t: &TensorView<'_>, expected: [u32; 2]) -> Result<(), GpuError> {
    let found = if t.rank == 1 { [t.dims[0], 0] } else { t.dims };
    if found != expected || t.len() != expected[0] as usize * expected[1].max(1) as usize {
        return Err(GpuError::TensorShape {
            name: t.name.as_str().to_string(),
            found,
            expected,
        });
    }
    Ok(())
}

fn f16_bits(t: &TensorView<'_>, i: usize) -> u16 {
    match t.dtype {
        Dtype::F16 => u16::from_le_bytes([t.bytes[2 * i], t.bytes[2 * i + 1]]),
        Dtype::F32 => f16::from_f32(f32_at(t, i)).to_bits(),
    }
}

fn f32_at(t: &TensorView<'_>, i: usize) -> f32 {
    match t.dtype {
        Dtype::F16 => f16::from_bits(f16_bits(t, i)).to_f32(),
        Dtype::F32 => f32::from_le_bytes([
            t.bytes[4 * i],
            t.bytes[4 * i + 1],
            t.bytes[4 * i + 2],
            t.bytes[4 * i + 3],
        ]),
    }
}

/// Packed weights: `u32` pairs of f16 bits or f32 pairs, transposed to `[in / 2][out]`.
enum Packed {
    Half(Vec<u32>),
    Single(Vec<[f32; 2]>),
}

impl GpuSkinner {
    /// Builds every pipeline on `device` (the caller's), checking its limits first. f16 weights
    /// are decoded with integer operations, which every adapter runs.
    pub fn new(device: &wgpu::Device) -> Result<Self, GpuError> {
        Self::with_unpack2x16float(device, false)
    }

    /// As [`GpuSkinner::new`], decoding f16 weights with WGSL's `unpack2x16float` when
    /// `unpack2x16float` is true: only for devices whose adapter reports
    /// `wgpu::DownlevelFlags::SHADER_F16_IN_F32` (shader creation fails otherwise).
    pub fn with_unpack2x16float(
        device: &wgpu::Device,
        unpack2x16float: bool,
    ) -> Result<Self, GpuError> {
        let limits = device.limits();
        let tile_bytes = (MAX_GPU_WIDTH as u64) * u64::from(SKINNET_TILE) * 4;
        require(
            "max_compute_workgroup_storage_size",
            limits.max_compute_workgroup_storage_size.into(),
            tile_bytes,
        )?;
        require(
            "max_compute_invocations_per_workgroup",
            limits.max_compute_invocations_per_workgroup.into(),
            WORKGROUP_THREADS.into(),
        )?;
        require(
            "max_compute_workgroup_size_x",
            limits.max_compute_workgroup_size_x.into(),
            WORKGROUP_THREADS.into(),
        )?;
        require(
            "max_storage_buffers_per_shader_stage",
            limits.max_storage_buffers_per_shader_stage.into(),
            6,
        )?;
        let build = |format| {
            device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("skinfield"),
                source: wgpu::ShaderSource::Wgsl(shader_source(format, unpack2x16float).into()),
            })
        };
        let (m16, m32) = (build(WeightFormat::F16), build(WeightFormat::F32));
        let per_format = |m: &wgpu::ShaderModule| FormatPipelines {
            position_terms: pipeline(device, m, entry::POSITION_TERMS),
            pose_terms: pipeline(device, m, entry::POSE_TERMS),
            skinnet: pipeline(device, m, entry::SKINNET),
        };
        Ok(Self {
            f16: per_format(&m16),
            f32: per_format(&m32),
            joint_dqs: pipeline(device, &m16, entry::JOINT_DQS),
            lbs: pipeline(device, &m16, entry::SKIN_LBS),
            dqs: pipeline(device, &m16, entry::SKIN_DQS),
            fast: super::fast::FastPipelines::new(device, &m16),
            limits,
        })
    }

    fn pipelines(&self, format: WeightFormat) -> &FormatPipelines {
        match format {
            WeightFormat::F16 => &self.f16,
            WeightFormat::F32 => &self.f32,
        }
    }

    pub(super) fn dispatch(&self, pass: &mut wgpu::ComputePass<'_>, groups: u32) {
        let (x, y) = split_dispatch(groups, self.limits.max_compute_workgroups_per_dimension);
        pass.dispatch_workgroups(x, y, 1);
    }

    pub(super) fn check_groups(&self, what: &'static str, groups: u64) -> Result<u32, GpuError> {
        let max = u64::from(self.limits.max_compute_workgroups_per_dimension);
        let limit = max * max;
        match u32::try_from(groups) {
            Ok(g) if groups <= limit => Ok(g),
            _ => Err(GpuError::TooLarge {
                what,
                value: groups,
                limit,
            }),
        }
    }

    pub(super) fn storage(
        &self,
        device: &wgpu::Device,
        label: &'static str,
        bytes: u64,
        usage: wgpu::BufferUsages,
    ) -> Result<wgpu::Buffer, GpuError> {
        self.check_size(label, bytes)?;
        Ok(device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | usage,
            mapped_at_creation: false,
        }))
    }

    pub(super) fn storage_init(
        &self,
        device: &wgpu::Device,
        label: &'static str,
        contents: &[u8],
    ) -> Result<wgpu::Buffer, GpuError> {
        self.check_size(label, contents.len() as u64)?;
        let pad = [0u8; 16];
        let contents = if contents.is_empty() {
            &pad[..]
        } else {
            contents
        };
        Ok(
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            }),
        )
    }

    fn check_size(&self, what: &'static str, bytes: u64) -> Result<(), GpuError> {
        let limit = self
            .limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size);
        if bytes > limit {
            Err(GpuError::TooLarge {
                what,
                value: bytes,
                limit,
            })
        } else {
            Ok(())
        }
    }

    /// Copies SkinNet out of `view` into GPU buffers, keeping the file's precision: f16 when
    /// every SkinNet weight is stored as f16, else f32.
    pub fn bind_model(
        &self,
        device: &wgpu::Device,
        view: &SkfView<'_>,
    ) -> Result<GpuModel, GpuError> {
        self.bind_model_as(device, view, None)
    }

    /// As [`GpuSkinner::bind_model`] with the GPU storage format chosen by the caller
    /// (`Some(F16)` rounds f32 tensors to half; `Some(F32)` expands f16 exactly).
    pub fn bind_model_as(
        &self,
        device: &wgpu::Device,
        view: &SkfView<'_>,
        format: Option<WeightFormat>,
    ) -> Result<GpuModel, GpuError> {
        let config = *view.config();
        let anchors = view.candidates().map(|c| AnchorSet::from_view(&c));
        let hidden = config.hidden_widths();
        let n = hidden.len();
        for &w in hidden {
            if w as usize > MAX_GPU_WIDTH {
                return Err(GpuError::Unsupported {
                    what: "hidden width",
                    value: w as usize,
                    max: MAX_GPU_WIDTH,
                });
            }
        }
        let joints = config.joint_count as usize;
        if joints > MAX_GPU_WIDTH {
            return Err(GpuError::Unsupported {
                what: "joint_count",
                value: joints,
                max: MAX_GPU_WIDTH,
            });
        }
        let mut tensors = Vec::with_capacity(n + 1);
        for (l, (out, inp)) in config.layer_shapes(Net::Skin).enumerate() {
            let (w, b) = view.layer(Net::Skin, l).ok_or(GpuError::MissingLayer(l))?;
            check_shape(&w, [out as u32, inp as u32])?;
            check_shape(&b, [out as u32, 0])?;
            tensors.push((w, b, out, inp));
        }
        let format = format.unwrap_or(
            if tensors.iter().all(|(w, _, _, _)| w.dtype == Dtype::F16) {
                WeightFormat::F16
            } else {
                WeightFormat::F32
            },
        );
        let mut packed = match format {
            WeightFormat::F16 => Packed::Half(Vec::new()),
            WeightFormat::F32 => Packed::Single(Vec::new()),
        };
        let mut biases = Vec::new();
        let mut layers = [GpuLayer::default(); MAX_GPU_LAYERS];
        for (l, (w, b, out, inp)) in tensors.iter().enumerate() {
            let w_off = match &packed {
                Packed::Half(v) => v.len(),
                Packed::Single(v) => v.len(),
            };
            let too_large = |value: usize| GpuError::TooLarge {
                what: "SkinNet weights",
                value: value as u64,
                limit: u32::MAX.into(),
            };
            layers[l] = GpuLayer {
                in_w: *inp as u32,
                out_w: *out as u32,
                w_off: u32::try_from(w_off).map_err(|_| too_large(w_off))?,
                b_off: u32::try_from(biases.len()).map_err(|_| too_large(biases.len()))?,
            };
            for p in 0..inp.div_ceil(2) {
                for o in 0..*out {
                    let (i0, i1) = (o * inp + 2 * p, o * inp + 2 * p + 1);
                    let has_hi = 2 * p + 1 < *inp;
                    match &mut packed {
                        Packed::Half(v) => {
                            let hi = if has_hi { f16_bits(w, i1) } else { 0 };
                            v.push(u32::from(f16_bits(w, i0)) | (u32::from(hi) << 16));
                        }
                        Packed::Single(v) => {
                            v.push([f32_at(w, i0), if has_hi { f32_at(w, i1) } else { 0.0 }])
                        }
                    }
                }
            }
            biases.extend((0..*out).map(|o| f32_at(b, o)));
        }
        let skip = config.skip_layer as usize;
        let skip = if skip > 0 && skip < n { skip } else { 0 };
        let params = GpuParams {
            vertex_count: 0,
            layer_count: (n + 1) as u32,
            skip_layer: skip as u32,
            pos_width: config.position_width() as u32,
            pose_width: config.pose_width() as u32,
            joint_count: config.joint_count,
            term0_width: hidden[0],
            term_skip_width: if skip > 0 { hidden[skip] } else { 0 },
            beta: config.softplus_beta,
            candidate_k: anchors.as_ref().map_or(0, |a| a.k() as u32),
            layers,
            ..GpuParams::default()
        };
        let weight_bytes: &[u8] = match &packed {
            Packed::Half(v) => bytemuck::cast_slice(v),
            Packed::Single(v) => bytemuck::cast_slice(v),
        };
        Ok(GpuModel {
            config,
            format,
            params,
            weights: self.storage_init(device, "skinnet weights", weight_bytes)?,
            biases: self.storage_init(device, "skinnet biases", bytemuck::cast_slice(&biases))?,
            anchors,
        })
    }

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

impl GpuModel {
    /// The model's configuration.
    #[must_use]
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// How the weights are stored on the GPU.
    #[must_use]
    pub fn weight_format(&self) -> WeightFormat {
        self.format
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dispatch_split_covers_every_group_within_the_limit() {
        for (groups, max) in [
            (0, 65535),
            (1, 65535),
            (65535, 65535),
            (65536, 65535),
            (1_000_000, 65535),
            (9, 3),
            (7, 3),
        ] {
            let (x, y) = split_dispatch(groups, max);
            assert!(x <= max && y <= max.max(1));
            assert!(u64::from(x) * u64::from(y) >= u64::from(groups));
            // No whole spare row: the excess is less than one row.
            assert!(u64::from(x) * u64::from(y) - u64::from(groups) < u64::from(x.max(1)));
        }
    }

    #[test]
    fn position_inputs_match_the_documented_layout() {
        let mut c = ModelConfig::paper_architecture(2, [-1.0, 0.0, 2.0], [1.0, 2.0, 6.0]);
        c.pe_frequencies = 2;
        let mut out = Vec::new();
        position_inputs(&c, &[Vec3::new(0.5, 0.5, 3.0)], &mut out);
        assert_eq!(out.len(), c.position_width());
        let xh = [0.5f64, -0.5, -0.5];
        let pi = core::f64::consts::PI;
        let mut expected = xh.to_vec();
        for k in 0..2 {
            let s = f64::from(1 << k) * pi;
            expected.extend(xh.iter().map(|x| (s * x).sin()));
            expected.extend(xh.iter().map(|x| (s * x).cos()));
        }
        for (a, b) in out.iter().zip(&expected) {
            assert!((f64::from(*a) - b).abs() < 1e-7, "{out:?} vs {expected:?}");
        }
    }
}
