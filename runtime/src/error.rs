//! The runtime's one error type: every failure names the field or part that is wrong.

use alloc::string::String;

use skinfield_formats::skf::{SkfError, TensorName};
use skinfield_formats::{PoseError, SkeletonError, SkinError};

use crate::kernels::Kernel;

/// Why a runtime call was refused. Nothing in the runtime panics on bad input; it returns one
/// of these instead.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RuntimeError {
    /// The `.skf` bytes are invalid.
    #[error("invalid .skf: {0}")]
    Skf(#[from] SkfError),
    /// The skeleton stored in the file (or given) is invalid, or a pose does not fit it
    /// (wrong joint count, NaN or infinite transforms).
    #[error("skeleton or pose: {0}")]
    Skeleton(#[from] SkeletonError),
    /// Pose features could not be computed.
    #[error("pose features: {0}")]
    Pose(#[from] PoseError),
    /// Static skinning weights are invalid.
    #[error("static skin: {0}")]
    Skin(#[from] SkinError),
    /// A tensor value in the file is NaN or infinite.
    #[error("tensor `{tensor}` holds a non-finite value at element {index}")]
    NonFiniteWeight {
        /// The tensor name.
        tensor: TensorName,
        /// Element index.
        index: usize,
    },
    /// A caller slice has the wrong length.
    #[error("`{field}` has {len} entries, expected {expected}")]
    BufferLength {
        /// The field.
        field: &'static str,
        /// Its length.
        len: usize,
        /// The length needed.
        expected: usize,
    },
    /// An input that must be present for the requested output is missing.
    #[error("`{field}` is required because `{because}` was given")]
    Missing {
        /// The missing field.
        field: &'static str,
        /// The output that needs it.
        because: &'static str,
    },
    /// A value is NaN or infinite.
    #[error("`{field}` holds a non-finite value at index {index}")]
    NonFinite {
        /// The field.
        field: &'static str,
        /// First bad index.
        index: usize,
    },
    /// The vertex range runs past the mesh.
    #[error("vertex range {first}..{first}+{count} exceeds the mesh's {vertex_count} vertices")]
    Range {
        /// First vertex.
        first: usize,
        /// Number of vertices.
        count: usize,
        /// Vertices in the mesh.
        vertex_count: usize,
    },
    /// Parts of a job come from different models or meshes.
    #[error("`{field}` was made for another model or mesh")]
    Mismatch {
        /// The field that does not fit.
        field: &'static str,
    },
    /// State derived from a frame (the fast path's nodes) was computed for another pose.
    #[error("`{field}` was computed for another pose: update it after set_pose")]
    Stale {
        /// The out-of-date field.
        field: &'static str,
    },
    /// An index refers past the end of what it indexes.
    #[error("`{field}`[{index}] refers to {value}, but there are only {limit}")]
    Index {
        /// The field holding the index.
        field: &'static str,
        /// Position of the bad entry.
        index: usize,
        /// The bad index.
        value: u32,
        /// How many there are.
        limit: usize,
    },
    /// A setting is outside its accepted range.
    #[error("`{field}` = {value} is outside {min}..={max}")]
    Setting {
        /// The setting.
        field: &'static str,
        /// Its value.
        value: usize,
        /// Smallest accepted value.
        min: usize,
        /// Largest accepted value.
        max: usize,
    },
    /// The frame state has no pose yet.
    #[error("the frame state has no pose: call set_pose or set_matrices first")]
    NoPose,
    /// The requested kernel is not supported by this CPU or build.
    #[error("kernel {0:?} is not available on this CPU or build")]
    KernelUnavailable(Kernel),
    /// A mesh has no vertices, or more than the cap.
    #[error("mesh has {0} vertices (1..=2^24 accepted)")]
    VertexCount(usize),
    /// Model joints that the engine skeleton does not name ([`crate::JointMap`]).
    #[error("the engine skeleton lacks {count} of the model's joints: {names}")]
    MissingJoints {
        /// How many are missing.
        count: usize,
        /// The first few missing names, quoted and comma-separated.
        names: String,
    },
    /// A joint name that appears twice in the engine skeleton ([`crate::JointMap`]).
    #[error("engine joint `{name}` appears twice, at indices {first} and {second}")]
    DuplicateJoint {
        /// The name.
        name: String,
        /// Its first index in the engine's order.
        first: usize,
        /// Its second index.
        second: usize,
    },
    /// A mapped joint whose engine parent is not the joint its model parent maps to, so local
    /// transforms would compose differently ([`crate::JointMap::check_parents`]).
    #[error("joint `{name}`: parent in the model is {model_parent}, in the engine {engine_parent}")]
    ParentMismatch {
        /// The joint's name.
        name: String,
        /// The model parent's name (or `none`).
        model_parent: String,
        /// The engine parent's name (or `none`).
        engine_parent: String,
    },
    /// The engine's bind pose differs from the model's at a joint by more than one shared
    /// transform ([`crate::JointMap::bind_space`]).
    #[error(
        "joint `{name}`: the engine's bind pose differs from the model's (relative difference {difference:.2e} after aligning the bind spaces)"
    )]
    BindMismatch {
        /// The joint's name.
        name: String,
        /// Largest entry of the difference of the per-joint bind-space transforms, relative
        /// to the root's.
        difference: f32,
    },
    /// A byte layout of an interleaved vertex buffer that cannot hold the attributes
    /// ([`crate::VertexLayout::validate`]).
    #[error("vertex layout: `{field}` at byte {offset} ({size} bytes) {problem}")]
    Layout {
        /// The attribute (`position`, `normal`, `tangent`) or `stride`.
        field: &'static str,
        /// Its byte offset (the stride itself for `stride`).
        offset: usize,
        /// Its size in bytes.
        size: usize,
        /// What is wrong.
        problem: &'static str,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString;

    #[test]
    fn messages_name_the_field() {
        let e = RuntimeError::BufferLength {
            field: "out_normals",
            len: 3,
            expected: 4,
        };
        assert_eq!(e.to_string(), "`out_normals` has 3 entries, expected 4");
        let e = RuntimeError::Missing {
            field: "rest_normals",
            because: "out_normals",
        };
        assert!(e.to_string().contains("rest_normals"));
    }
}
