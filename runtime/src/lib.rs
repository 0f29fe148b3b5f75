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
//! 3. **Per frame**: [`FrameState::set_pose`] runs forward kinematics, the pose features
//!    ([`skinfield_formats::pose_features`]) and the pose parts of those two layers, once.
//!    [`SkinJob`] then evaluates the MLP over tiles of [`TILE`] vertices, blends the joints
//!    (LBS or DQS) and writes positions, normals, tangents and optionally the weights, over any
//!    vertex range (so an engine's job system can split a frame; the `rayon` feature has a
//!    ready-made parallel run in [`parallel`]).
//! 4. **Static skinning**: [`StaticSkinJob`] does the same with a [`StaticSkin`].
//! 5. **Level of detail** (`resample` feature): the `resample` module simplifies or subdivides
//!    a canonical mesh at load time; the result binds like any other mesh, same weight file.
//!
//! No function here panics on any input: bad slices, NaN poses and mismatched parts are typed
//! [`RuntimeError`]s naming the field.
#![cfg_attr(not(feature = "std"), no_std)]

extern crate alloc;

pub mod activation;
pub mod bind;
pub mod candidates;
pub mod error;
pub mod frame;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod job;
pub mod kernels;
pub mod model;
#[cfg(feature = "rayon")]
pub mod parallel;
#[cfg(feature = "resample")]
pub mod resample;
pub mod skinning;
pub mod static_job;

pub use bind::{BoundMesh, positional_encoding};
pub use error::RuntimeError;
pub use frame::{FrameState, Palette};
pub use job::{Scratch, SkinJob, WeightsJob};
pub use kernels::{Kernel, TILE};
pub use model::{SkinNet, SkinNetModel, expanded_len};
pub use skinning::{DualQuat, Method};
pub use static_job::StaticSkinJob;

pub use glam::{Mat4, Quat, Vec3, Vec4};
pub use skinfield_formats::{Pose, Skeleton, StaticSkin};
