//! GPU-side data layouts, mirrored from the WGSL structs in `shaders/common.wgsl`, and the
//! composition of the WGSL module.
//!
//! WGSL has no `#include`: the runtime concatenates the shared declarations, one weight-format
//! file and the kernels into one module per weight format. The unit tests parse and validate
//! both modules with naga and compare every Rust struct's size and field offsets with naga's
//! layouter, so a field added on one side only fails the build's tests, not a frame.

use bytemuck::{Pod, Zeroable};
use skinfield_formats::skf::MAX_HIDDEN_LAYERS;

/// Linear layers the kernels can hold: every hidden layer plus the output layer.
pub const MAX_GPU_LAYERS: usize = MAX_HIDDEN_LAYERS + 1;

/// Widest layer (hidden or output) the SkinNet kernel keeps in workgroup memory.
pub const MAX_GPU_WIDTH: usize = 256;

/// Vertices per SkinNet workgroup (`TILE` in `skinnet.wgsl`).
pub const SKINNET_TILE: u32 = 16;

/// Threads per workgroup of every kernel (`THREADS` in `common.wgsl`).
pub const WORKGROUP_THREADS: u32 = 64;

/// One linear layer as the kernels see it (`Layer` in WGSL).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuLayer {
    /// Input width (all columns, constant blocks included).
    pub in_w: u32,
    /// Output width.
    pub out_w: u32,
    /// First column pair of the transposed, pair-packed weight in the weight buffer.
    pub w_off: u32,
    /// First bias in the bias buffer.
    pub b_off: u32,
}

/// Per-mesh constants of every kernel (`Params` in WGSL, a uniform buffer).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuParams {
    /// Vertices of the bound mesh.
    pub vertex_count: u32,
    /// Hidden layers plus the output layer.
    pub layer_count: u32,
    /// Hidden layer fed `[h, x̂, γ(x̂), θ̃]`; 0 when there is no skip connection.
    pub skip_layer: u32,
    /// Width of `[x̂, γ(x̂)]`.
    pub pos_width: u32,
    /// Width of the pose features.
    pub pose_width: u32,
    /// Joints (SkinNet's output width).
    pub joint_count: u32,
    /// Width of layer 0.
    pub term0_width: u32,
    /// Width of the skip layer (0 without one).
    pub term_skip_width: u32,
    /// Softplus β.
    pub beta: f32,
    /// Candidate-list slots per vertex in the `candidates` buffer (0: no candidate mask).
    pub candidate_k: u32,
    /// Padding to the 16-byte alignment of `layers`.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
    /// Layer table (unused entries zero).
    pub layers: [GpuLayer; MAX_GPU_LAYERS],
}

/// Per-mesh constants of the fast-path kernels (`FastParams` in `shaders/fast.wgsl`, a uniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuFastParams {
    /// Vertices of the mesh.
    pub vertex_count: u32,
    /// Nodes SkinNet runs at.
    pub node_count: u32,
    /// Joints.
    pub joint_count: u32,
    /// Interpolation entries per vertex.
    pub neighbours: u32,
    /// Base entries per vertex (stored before the interpolation entries).
    pub base_count: u32,
    /// Joints per vertex for DQS.
    pub dqs_k: u32,
    /// Joints per vertex of the top-k output (4 or 8).
    pub top_k: u32,
    /// Bytes per top-k joint index (1 or 2).
    pub index_bytes: u32,
    /// Top-k weight format: 0 unorm8, 1 unorm16, 2 f32.
    pub weight_format: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// A skinned vertex as written by the skinning kernels: the layout of the output vertex buffer
/// (32-byte stride; `w` is 1 for the position and 0 for the normal).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SkinnedVertex {
    /// Position `(x, y, z, 1)`.
    pub position: [f32; 4],
    /// Unit normal `(x, y, z, 0)`.
    pub normal: [f32; 4],
}

impl SkinnedVertex {
    /// Vertex attributes for a render pipeline reading the output buffer: position at shader
    /// location 0, normal at 1.
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 2] =
        wgpu::vertex_attr_array![0 => Float32x4, 1 => Float32x4];

    /// Vertex-buffer layout of the output buffer for a render pipeline.
    #[must_use]
    pub fn buffer_layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: size_of::<Self>() as wgpu::BufferAddress,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &Self::ATTRIBUTES,
        }
    }
}

/// How the weights are stored on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightFormat {
    /// IEEE half pairs packed in a `u32`, read with `unpack2x16float` (the `.skf` bits as is).
    F16,
    /// f32 pairs.
    F32,
}

const COMMON: &str = include_str!("../../../shaders/common.wgsl");
const WEIGHTS_F16: &str = include_str!("../../../shaders/weights_f16.wgsl");
const WEIGHTS_F16_BITS: &str = include_str!("../../../shaders/weights_f16_bits.wgsl");
const WEIGHTS_F32: &str = include_str!("../../../shaders/weights_f32.wgsl");
const TERMS: &str = include_str!("../../../shaders/terms.wgsl");
const SKINNET: &str = include_str!("../../../shaders/skinnet.wgsl");
const SKIN: &str = include_str!("../../../shaders/skin.wgsl");
const FAST: &str = include_str!("../../../shaders/fast.wgsl");

/// The whole WGSL module for weights stored as `format`; f16 weights are decoded with
/// `unpack2x16float` when `unpack2x16float` is true (needs the adapter's
/// `DownlevelFlags::SHADER_F16_IN_F32`), else with integer operations.
#[must_use]
pub fn shader_source(format: WeightFormat, unpack2x16float: bool) -> String {
    let weights = match (format, unpack2x16float) {
        (WeightFormat::F16, true) => WEIGHTS_F16,
        (WeightFormat::F16, false) => WEIGHTS_F16_BITS,
        (WeightFormat::F32, _) => WEIGHTS_F32,
    };
    [COMMON, weights, TERMS, SKINNET, SKIN, FAST].join("\n")
}

/// Entry points of the module.
pub(crate) mod entry {
    pub const POSITION_TERMS: &str = "bind_position_terms";
    pub const POSE_TERMS: &str = "frame_pose_terms";
    pub const JOINT_DQS: &str = "frame_joint_dqs";
    pub const SKINNET: &str = "skinnet_weights";
    pub const SKIN_LBS: &str = "skin_lbs";
    pub const SKIN_DQS: &str = "skin_dqs";
    pub const FAST_RESIDUALS: &str = "fast_node_residuals";
    pub const FAST_LBS: &str = "fast_skin_lbs";
    pub const FAST_DQS: &str = "fast_skin_dqs";
    pub const FAST_TOP_K: &str = "fast_top_k";
    #[cfg(test)]
    pub const ALL: [&str; 10] = [
        POSITION_TERMS,
        POSE_TERMS,
        JOINT_DQS,
        SKINNET,
        SKIN_LBS,
        SKIN_DQS,
        FAST_RESIDUALS,
        FAST_LBS,
        FAST_DQS,
        FAST_TOP_K,
    ];
}

#[cfg(test)]
mod tests {
    use core::mem::offset_of;

    use wgpu::naga;

    use super::*;

    fn module_with(format: WeightFormat, unpack: bool) -> naga::Module {
        let src = shader_source(format, unpack);
        let module = naga::front::wgsl::parse_str(&src)
            .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
        // Only the unpack2x16float variant may need a capability beyond the baseline.
        let caps = if unpack {
            naga::valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32
        } else {
            naga::valid::Capabilities::empty()
        };
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
        module
    }

    fn module(format: WeightFormat) -> naga::Module {
        module_with(format, false)
    }

    #[test]
    fn portable_modules_need_no_capability_and_unpack_needs_exactly_one() {
        for format in [WeightFormat::F16, WeightFormat::F32] {
            module_with(format, false);
        }
        module_with(WeightFormat::F16, true);
        let src = shader_source(WeightFormat::F16, true);
        let m = naga::front::wgsl::parse_str(&src).unwrap();
        let err = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&m)
        .err();
        assert!(
            err.is_some(),
            "unpack2x16float validated without SHADER_FLOAT16_IN_FLOAT32"
        );
    }

    /// (size, [(member name, offset)]) of the WGSL struct `name` per naga's layouter.
    fn wgsl_layout(module: &naga::Module, name: &str) -> (u32, Vec<(String, u32)>) {
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).unwrap();
        let (handle, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap();
        let naga::TypeInner::Struct { members, .. } = &ty.inner else {
            panic!("{name} is not a struct")
        };
        let fields = members
            .iter()
            .map(|m| (m.name.clone().unwrap(), m.offset))
            .collect();
        (layouter[handle].size, fields)
    }

    fn check(module: &naga::Module, name: &str, size: usize, rust: &[(&str, usize)]) {
        let (wgsl_size, wgsl) = wgsl_layout(module, name);
        assert_eq!(wgsl_size as usize, size, "size of {name}");
        let rust: Vec<(String, u32)> = rust
            .iter()
            .map(|&(n, o)| (n.to_string(), o as u32))
            .collect();
        assert_eq!(wgsl, rust, "fields of {name}");
    }

    #[test]
    fn both_modules_validate_with_every_entry_point() {
        for format in [WeightFormat::F16, WeightFormat::F32] {
            let m = module(format);
            let names: Vec<&str> = m.entry_points.iter().map(|e| e.name.as_str()).collect();
            assert_eq!(names.len(), entry::ALL.len());
            for e in entry::ALL {
                assert!(names.contains(&e), "{e} missing in {format:?}");
            }
            for ep in &m.entry_points {
                assert_eq!(ep.workgroup_size, [WORKGROUP_THREADS, 1, 1], "{}", ep.name);
            }
        }
    }

    #[test]
    fn rust_structs_match_wgsl_layouts() {
        let m = module(WeightFormat::F16);
        check(
            &m,
            "Layer",
            size_of::<GpuLayer>(),
            &[
                ("in_w", offset_of!(GpuLayer, in_w)),
                ("out_w", offset_of!(GpuLayer, out_w)),
                ("w_off", offset_of!(GpuLayer, w_off)),
                ("b_off", offset_of!(GpuLayer, b_off)),
            ],
        );
        check(
            &m,
            "Params",
            size_of::<GpuParams>(),
            &[
                ("vertex_count", offset_of!(GpuParams, vertex_count)),
                ("layer_count", offset_of!(GpuParams, layer_count)),
                ("skip_layer", offset_of!(GpuParams, skip_layer)),
                ("pos_width", offset_of!(GpuParams, pos_width)),
                ("pose_width", offset_of!(GpuParams, pose_width)),
                ("joint_count", offset_of!(GpuParams, joint_count)),
                ("term0_width", offset_of!(GpuParams, term0_width)),
                ("term_skip_width", offset_of!(GpuParams, term_skip_width)),
                ("beta", offset_of!(GpuParams, beta)),
                ("candidate_k", offset_of!(GpuParams, candidate_k)),
                ("_pad1", offset_of!(GpuParams, _pad1)),
                ("_pad2", offset_of!(GpuParams, _pad2)),
                ("layers", offset_of!(GpuParams, layers)),
            ],
        );
        check(
            &m,
            "FastParams",
            size_of::<GpuFastParams>(),
            &[
                ("vertex_count", offset_of!(GpuFastParams, vertex_count)),
                ("node_count", offset_of!(GpuFastParams, node_count)),
                ("joint_count", offset_of!(GpuFastParams, joint_count)),
                ("neighbours", offset_of!(GpuFastParams, neighbours)),
                ("base_count", offset_of!(GpuFastParams, base_count)),
                ("dqs_k", offset_of!(GpuFastParams, dqs_k)),
                ("top_k", offset_of!(GpuFastParams, top_k)),
                ("index_bytes", offset_of!(GpuFastParams, index_bytes)),
                ("weight_format", offset_of!(GpuFastParams, weight_format)),
                ("_pad0", offset_of!(GpuFastParams, _pad0)),
                ("_pad1", offset_of!(GpuFastParams, _pad1)),
                ("_pad2", offset_of!(GpuFastParams, _pad2)),
            ],
        );
        check(
            &m,
            "Influence",
            size_of::<crate::fast::Influence>(),
            &[
                ("index", offset_of!(crate::fast::Influence, index)),
                ("weight", offset_of!(crate::fast::Influence, weight)),
            ],
        );
        check(
            &m,
            "Vertex",
            size_of::<SkinnedVertex>(),
            &[
                ("position", offset_of!(SkinnedVertex, position)),
                ("normal", offset_of!(SkinnedVertex, normal)),
            ],
        );
        // The layer table's array stride must equal the Rust element size.
        let (handle, _) = m
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some("Params"))
            .unwrap();
        let naga::TypeInner::Struct { members, .. } = &m.types[handle].inner else {
            unreachable!()
        };
        let layers_ty = &m.types[members.last().unwrap().ty].inner;
        let naga::TypeInner::Array {
            stride,
            size: naga::ArraySize::Constant(n),
            ..
        } = layers_ty
        else {
            panic!("layers is not a fixed array")
        };
        assert_eq!(
            (*stride as usize, n.get() as usize),
            (size_of::<GpuLayer>(), MAX_GPU_LAYERS)
        );
    }

    #[test]
    fn kernel_constants_match_rust() {
        let src = shader_source(WeightFormat::F16, false);
        assert!(src.contains(&format!("const THREADS: u32 = {WORKGROUP_THREADS}u;")));
        assert!(src.contains(&format!("const TILE: u32 = {SKINNET_TILE}u;")));
        assert!(src.contains(&format!("const MAX_WIDTH: u32 = {MAX_GPU_WIDTH}u;")));
        assert!(src.contains(&format!(
            "const MAX_K: u32 = {}u;",
            crate::fast::MAX_INFLUENCES
        )));
        // Workgroup memory: MAX_WIDTH rows × TILE vertices of f32 within WebGPU's default 16 KiB.
        assert!(src.contains(&format!(
            "array<vec4<f32>, {}>",
            MAX_GPU_WIDTH * SKINNET_TILE as usize / 4
        )));
        assert!(MAX_GPU_WIDTH * SKINNET_TILE as usize * 4 <= 16384);
    }
}
