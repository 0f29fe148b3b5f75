//! Skinfield asset schema shared by the trainer and the runtime.
//!
//! The core (skeleton, pose, pose features, template mesh, static skin, camera rig and the
//! zero-copy [`skf`] weight-file view) is `no_std` + `alloc`; readers and writers that touch
//! files (glTF, BVH, capture manifest, images, the `.skf` writer) need the `std` feature.
//!
//! Conventions (see `docs/design.md`, *Conventions*): right-handed, +Y up, metres; quaternions
//! are glam's `(x, y, z, w)`; matrices are column-major; joints are stored in topological order
//! (a parent's index is smaller than its children's).
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

extern crate alloc;

#[cfg(feature = "std")]
pub mod bvh;
pub mod camera;
#[cfg(feature = "std")]
pub mod capture;
#[cfg(feature = "std")]
pub mod gltf_io;
#[cfg(feature = "std")]
pub mod makehuman;
pub mod math;
pub mod mesh;
pub mod pose;
#[cfg(feature = "std")]
pub mod shared_data;
pub mod skeleton;
pub mod skf;
pub mod skin;

pub use camera::{Camera, CameraError, CameraRig, Distortion};
pub use math::{Aabb, Transform};
pub use mesh::{MeshError, PartLabel, Template};
pub use pose::{POSE_FEATURE_ENCODING, Pose, PoseError, UpAxis, pose_feature_count, pose_features};
pub use skeleton::{Axis, JointDofs, MAX_JOINTS, Skeleton, SkeletonError};
pub use skin::{SkinError, StaticSkin};
