//! Why a MakeHuman asset could not be read: one variant per failure, each naming the file.

use std::path::PathBuf;

use crate::mesh::MeshError;
use crate::skeleton::SkeletonError;
use crate::skin::SkinError;

use super::MAX_FILE_BYTES;

/// Why a MakeHuman asset could not be read.
#[derive(Debug, thiserror::Error)]
pub enum MakeHumanError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is larger than [`MAX_FILE_BYTES`].
    #[error("{path}: file has {bytes} bytes, more than the cap of {MAX_FILE_BYTES}")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
    /// An OBJ line is malformed or out of range.
    #[error("{path}:{line}: {what}")]
    Obj {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// The JSON does not parse.
    #[error("{path}: invalid JSON: {source}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: serde_json::Error,
    },
    /// A JSON field is missing, of the wrong type or refers to something that does not exist.
    #[error("{path}: field `{field}`: {what}")]
    Field {
        /// The file.
        path: PathBuf,
        /// The field (a JSON path).
        field: String,
        /// What is wrong.
        what: String,
    },
    /// The skeleton is invalid.
    #[error("{path}: {source}")]
    Skeleton {
        /// The `.mhskel` file.
        path: PathBuf,
        /// Why.
        source: SkeletonError,
    },
    /// The selected groups give an invalid mesh.
    #[error("{path}: {source}")]
    Mesh {
        /// The OBJ file.
        path: PathBuf,
        /// Why.
        source: MeshError,
    },
    /// The weights are invalid (e.g. a template vertex has none).
    #[error("{path}: {source}")]
    Skin {
        /// The `.mhw` file.
        path: PathBuf,
        /// Why.
        source: SkinError,
    },
}
