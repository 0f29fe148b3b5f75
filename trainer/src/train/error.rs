//! Why training cannot start or continue.

use std::path::PathBuf;

/// Why training cannot start or continue.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The data are inconsistent (names the field).
    #[error("training data: {0}")]
    Data(String),
    /// A tensor operation failed.
    #[error("candle: {0}")]
    Candle(#[from] candle_core::Error),
    /// A file could not be written or read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Exporting the model failed.
    #[error(transparent)]
    Export(#[from] crate::skinnet::export::ExportError),
    /// A checkpoint does not match this run.
    #[error("{path}: {reason}")]
    Checkpoint {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}
