//! Skinfield asset schema shared by the trainer and the runtime.
//!
//! The core (skeleton, pose, pose features, template mesh, static skin, camera rig and the
//! zero-copy [`skf`] weight-file view) is `no_std` + `alloc`; the `std` feature adds the `.skf`
//! file writer and reader, and the `import` feature the offline readers and writers (glTF, BVH,
//! capture manifest, images, MakeHuman), so an engine's build never compiles a parser.
//!
//! Conventions (see `docs/design.md`, *Conventions*): right-handed, +Y up, metres; quaternions
//! are glam's `(x, y, z, w)`; matrices are column-major; joints are stored in topological order
//! (a parent's index is smaller than its children's).
#![cfg_attr(not(feature = "std"), no_std)]
#![forbid(unsafe_code)]

extern crate alloc;

#[cfg(feature = "import")]
pub mod bvh;
pub mod camera;
#[cfg(feature = "import")]
pub mod capture;
#[cfg(feature = "import")]
pub mod gltf_io;
#[cfg(feature = "import")]
pub mod makehuman;
pub mod math;
pub mod mesh;
pub mod pose;
pub mod retarget;
#[cfg(feature = "import")]
pub mod shared_data;
pub mod skeleton;
pub mod skf;
pub mod skin;

pub use camera::{Camera, CameraError, CameraRig, Distortion};
pub use math::{Aabb, Transform};
pub use mesh::{MeshError, PartLabel, Template};
pub use pose::{POSE_FEATURE_ENCODING, Pose, PoseError, UpAxis, pose_feature_count, pose_features};
pub use retarget::{Retarget, RetargetError};
pub use skeleton::{Axis, JointDofs, MAX_JOINTS, Skeleton, SkeletonError};
pub use skin::{SkinError, StaticSkin};
