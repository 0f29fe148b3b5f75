//! Skinfield runtime: exact SkinNet evaluation and skinning on the CPU.
//!
//! The shape follows ozz-animation and meshoptimizer: everything that depends only on the file
//! or the mesh is done once, the per-frame path writes into caller slices and never allocates.
//!
//! 1. **Load**: [`SkinNet::from_skf`] (owning) or [`SkinNet::expand_into`] (caller memory,
//!    sized by [`expanded_len`]) turns a validated `.skf` into f32 weight panels in the layout
//!    the kernels want, and picks the fastest [`Kernel`] once.
//! 2. **Bind**: [`BoundMesh::bind`] normalises any mesh's canonical positions with the file's
//!    bounding box and precomputes the position parts of the first layer and of the skip layer.
//! 3. **Per frame**: [`FrameState::set_pose`] (or [`FrameState::set_engine_pose`], the
//!    engine's own joint order through a [`JointMap`] built once by name) runs forward
//!    kinematics, the pose features
//!    ([`skinfield_formats::pose_features`]) and the pose parts of those two layers, once.
//!    [`SkinJob`] then evaluates the MLP over tiles of [`TILE`] vertices, blends the joints
//!    (LBS or DQS) and writes positions, normals, tangents and optionally the weights, over any
//!    vertex range (so an engine's job system can split a frame; the `rayon` feature has a
//!    ready-made parallel run in [`parallel`]).
//! 4. **Static skinning**: [`StaticSkinJob`] does the same with a [`StaticSkin`].
//! 5. **Fast path**: [`FastMesh::bind`] picks a few hundred nodes of the mesh; per frame
//!    [`FastFrame::update`] evaluates SkinNet at those nodes only and [`FastSkinJob`] /
//!    [`TopKJob`] give every vertex interpolated weights (skinned, or as the top-k influences
//!    an engine's own skinning shader takes), so the MLP cost no longer grows with the mesh.
//! 6. **Engine buffers**: [`InterleavedJob`] writes any of the above straight into an
//!    interleaved vertex buffer (stride and offsets in a [`VertexLayout`]); the `gpu` module
//!    runs the same frames on the engine's wgpu device from the same [`FrameState`].
//! 7. **Level of detail** (`resample` feature): the `resample` module simplifies or subdivides
//!    a canonical mesh at load time; the result binds like any other mesh, same weight file.
//!
//! No function here panics on any input: bad slices, NaN poses and mismatched parts are typed
//! [`RuntimeError`]s naming the field (the GPU returns the same errors for the same inputs).
//! `docs/embedding.md` walks through an engine integration, from Rust and from C.
#![cfg_attr(not(feature = "std"), no_std)]

extern crate alloc;

mod activation;
mod bind;
pub mod candidates;
mod error;
pub mod fast;
mod frame;
#[cfg(feature = "gpu")]
pub mod gpu;
mod interleaved;
mod job;
mod joint_map;
pub mod kernels;
mod model;
#[cfg(feature = "rayon")]
pub mod parallel;
#[cfg(feature = "resample")]
pub mod resample;
mod skinning;
mod static_job;

pub use bind::{BoundMesh, MAX_BIND_VERTICES};
pub use error::RuntimeError;
pub use fast::{
    FastFrame, FastMesh, FastOptions, FastSkinJob, Influence, TopKIndices, TopKJob, TopKWeights,
};
pub use frame::{FrameState, Palette};
pub use interleaved::{CHUNK, InterleavedJob, VertexLayout, WeightSource};
pub use job::{Scratch, SkinJob, WeightsJob};
pub use joint_map::{BindSpace, JointMap};
pub use kernels::{Kernel, TILE};
pub use model::{SkinNet, SkinNetModel, expanded_len};
pub use skinning::{DualQuat, Method};
pub use static_job::StaticSkinJob;

pub use glam::{Mat4, Quat, Vec3, Vec4};
pub use skinfield_formats::skf::{ModelConfig, SkfError, SkfView};
#[cfg(feature = "std")]
pub use skinfield_formats::skf::{SkfFileError, read_skf_file};
pub use skinfield_formats::{Pose, Skeleton, StaticSkin, Transform, UpAxis};
