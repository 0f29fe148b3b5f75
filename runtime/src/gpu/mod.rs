//! SkinNet and skinning on the GPU (wgpu compute shaders, feature `gpu`).
//!
//! The same steps as the CPU path (see `docs/design.md`, *Runtime*), on a [`wgpu::Device`] and
//! [`wgpu::Queue`] that the caller (the engine) owns:
//!
//! - [`GpuSkinner::new`] builds the pipelines once from the WGSL in `shaders/`.
//! - [`GpuSkinner::bind_model`] copies a `.skf` SkinNet into GPU buffers (f16 weights stay f16,
//!   packed in pairs and read with `unpack2x16float`; f32 weights stay f32).
//! - [`GpuSkinner::bind_mesh`] uploads a mesh's canonical positions and normals and computes,
//!   once, the position part of the two input-fed layers (layer 0 and the skip layer).
//! - Per frame, the pose goes through the CPU's [`crate::FrameState`] (the same
//!   [`crate::Pose`] or engine-order transforms and [`crate::JointMap`] as the CPU path);
//!   [`GpuSkinner::upload_frame`] writes only its skinning matrices and pose features;
//!   [`GpuSkinner::encode`] records the pose terms, SkinNet (tiles of 16 vertices
//!   per workgroup, activations in workgroup memory), softmax and LBS or DQS into the caller's
//!   command encoder, writing [`GpuMesh::output`], a `STORAGE | VERTEX` buffer of
//!   [`SkinnedVertex`] the engine can draw from.
//! - [`GpuMesh::read_vertices`] and [`GpuMesh::read_weights`] read results back for tools and
//!   tests.
//! - Fast path: [`GpuSkinner::bind_fast_mesh`] uploads a CPU-bound [`crate::FastMesh`];
//!   [`GpuSkinner::encode_fast`] runs SkinNet at its nodes only, then LBS, DQS or the top-k
//!   output ([`GpuFastMesh`]).

mod fast;
mod frame;
mod layout;
mod mesh;
mod model;
mod skinner;

pub use fast::{FastOutputs, GpuFastMesh, GpuFastOptions, TopKIndexFormat, TopKWeightFormat};
pub use layout::{
    GpuFastParams, GpuLayer, GpuParams, MAX_GPU_LAYERS, MAX_GPU_WIDTH, SKINNET_TILE, SkinnedVertex,
    WORKGROUP_THREADS, WeightFormat, shader_source,
};
pub use mesh::GpuMesh;
pub use model::GpuModel;
pub use skinner::GpuSkinner;

/// Why a GPU operation failed.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// The model exceeds what the kernels support.
    #[error("skf: {what} = {value} exceeds the GPU kernels' maximum of {max}")]
    Unsupported {
        /// The configuration field.
        what: &'static str,
        /// Its value.
        value: usize,
        /// The largest supported value.
        max: usize,
    },
    /// A SkinNet layer is missing from the `.skf`.
    #[error("skf: SkinNet layer {0} is missing")]
    MissingLayer(usize),
    /// A SkinNet tensor has the wrong shape.
    #[error("skf: tensor `{name}` has shape {found:?}, expected {expected:?}")]
    TensorShape {
        /// Tensor name.
        name: String,
        /// Stored dimensions.
        found: [u32; 2],
        /// Dimensions the configuration implies.
        expected: [u32; 2],
    },
    /// A fast-path setting the kernels do not accept.
    #[error("{field} = {value}: accepted {accepted}")]
    Setting {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: usize,
        /// What is accepted.
        accepted: &'static str,
    },
    /// A buffer or dispatch would exceed the device's limits.
    #[error("{what}: {value} exceeds the device limit {limit}")]
    TooLarge {
        /// What is too large.
        what: &'static str,
        /// Requested size (bytes or workgroups).
        value: u64,
        /// The device limit.
        limit: u64,
    },
    /// The device's limits are below what the kernels need.
    #[error("device limit {name} = {value} is below the required {required}")]
    DeviceLimit {
        /// The limit's name in `wgpu::Limits`.
        name: &'static str,
        /// The device's value.
        value: u64,
        /// The kernels' requirement.
        required: u64,
    },
    /// An input refused by the same checks, with the same error, as on the CPU: a wrong
    /// length, a NaN, an empty mesh, a frame state without a pose.
    #[error(transparent)]
    Input(#[from] crate::RuntimeError),
    /// Mapping a read-back buffer failed.
    #[error("GPU read-back: {0}")]
    Map(#[from] wgpu::BufferAsyncError),
    /// Reading the mapped range failed.
    #[error("GPU read-back range: {0}")]
    MapRange(#[from] wgpu::MapRangeError),
    /// Waiting for the device failed.
    #[error("GPU poll: {0}")]
    Poll(#[from] wgpu::PollError),
    /// The read-back callback never ran.
    #[error("GPU read-back: the map callback was dropped")]
    MapDropped,
    /// No adapter ([`headless_device`]).
    #[error("no wgpu adapter: {0}")]
    NoAdapter(#[from] wgpu::RequestAdapterError),
    /// The adapter refused the device ([`headless_device`]).
    #[error("wgpu request_device: {0}")]
    RequestDevice(#[from] wgpu::RequestDeviceError),
}

/// A device and queue of the default adapter, without a window, for tools, tests and benches
/// (an engine passes its own device to [`GpuSkinner`] instead). The backends come from the
/// environment (`WGPU_BACKEND`); on a machine without a GPU, Mesa's lavapipe serves.
pub fn headless_device(
    limits: wgpu::Limits,
) -> Result<(wgpu::Adapter, wgpu::Device, wgpu::Queue), GpuError> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter =
        pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))?;
    let desc = wgpu::DeviceDescriptor {
        label: Some("skinfield headless"),
        required_limits: limits,
        ..Default::default()
    };
    let (device, queue) = pollster::block_on(adapter.request_device(&desc))?;
    Ok((adapter, device, queue))
}
