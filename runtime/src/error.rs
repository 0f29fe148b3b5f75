//! The runtime's one error type: every failure names the field or part that is wrong.

use skinfield_formats::skf::SkfError;
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
        tensor: &'static str,
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
