//! The GPU skinner: the pipelines built once per device, dispatch sizes and buffer limits.

use wgpu::util::DeviceExt;

use super::GpuError;
use super::layout::{
    MAX_GPU_WIDTH, SKINNET_TILE, WORKGROUP_THREADS, WeightFormat, entry, shader_source,
};

pub(super) struct FormatPipelines {
    pub(super) position_terms: wgpu::ComputePipeline,
    pub(super) pose_terms: wgpu::ComputePipeline,
    pub(super) skinnet: wgpu::ComputePipeline,
}

/// The pipelines, built once per device.
pub struct GpuSkinner {
    pub(super) f16: FormatPipelines,
    pub(super) f32: FormatPipelines,
    pub(super) joint_dqs: wgpu::ComputePipeline,
    pub(super) lbs: wgpu::ComputePipeline,
    pub(super) dqs: wgpu::ComputePipeline,
    pub(super) fast: super::fast::FastPipelines,
    pub(super) limits: wgpu::Limits,
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

pub(super) fn require(name: &'static str, value: u64, required: u64) -> Result<(), GpuError> {
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
pub(super) fn split_dispatch(groups: u32, max: u32) -> (u32, u32) {
    if groups <= max {
        (groups, 1)
    } else {
        (max, groups.div_ceil(max))
    }
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

    pub(super) fn pipelines(&self, format: WeightFormat) -> &FormatPipelines {
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

    pub(super) fn check_size(&self, what: &'static str, bytes: u64) -> Result<(), GpuError> {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::mesh::position_inputs;
    use glam::Vec3;
    use skinfield_formats::skf::ModelConfig;

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
