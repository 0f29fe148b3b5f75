//! The `.skf` weight file: SkinNet (and the appearance nets) plus everything the runtime needs to
//! reproduce the trainer's forward pass.
//!
//! # Layout (version 1.0, all integers and floats little-endian)
//!
//! ```text
//! header   (64 B)  magic "SKINFLD\0" | major u16 | minor u16 | section_count u32 |
//!                  file_len u64 | checksum u64 | 32 reserved zero bytes
//! sections (32 B each) tag [u8;4] | 0 u32 | offset u64 | len u64 | 0 u64
//! CONF     (128 B) network hyper-parameters, pose encoding, canonical normalisation
//! SKEL             joint_count u32 | names_len u32 | 0 u32 ×2 | base [f32;16] |
//!                  joint_count × 128 B records | names (UTF-8)
//! TINF             tensor_count u32 | 0 u32 | tensor_count × 64 B entries
//! DATA             tensor bytes, each tensor 64-byte aligned
//! CAND             (version 1.1, optional) candidate joints of canonical anchors, see
//!                  [`candidates`]
//! PRNG             (version 1.2, optional) the training range of the pose features, see
//!                  [`pose_range`]
//! ```
//!
//! Every section starts on a 64-byte boundary; the bytes between sections are zero padding of
//! fewer than 64 bytes; the last section ends exactly at `file_len`, which equals the buffer
//! length; inside `DATA` the tensors, sorted by offset, cover it the same way. The checksum is
//! FNV-1a 64 over the whole file with the checksum field itself skipped. Tensors are f16
//! (or f32), row-major, `weight` tensors shaped `[out, in]`.
//!
//! Sections with unknown tags are skipped (room for later minor versions); a different major
//! version is refused.

pub mod candidates;
mod config;
mod error;
pub mod pose_range;
mod tensor;
mod view;
#[cfg(feature = "std")]
mod write;

pub use candidates::CandidatesView;
pub use config::{ModelConfig, Net, SkfConfigError};
pub use error::SkfError;
pub use pose_range::PoseRangeView;
pub use tensor::{Dtype, Tag, TensorName, TensorView};
pub use view::{SkeletonView, SkfView};
#[cfg(feature = "std")]
pub use write::{Candidates, PoseRange, SkfFileError, SkfModel, read_skf_file, write_atomic};

/// File magic.
pub const MAGIC: [u8; 8] = *b"SKINFLD\0";
/// Major version this crate reads and writes.
pub const VERSION_MAJOR: u16 = 1;
/// Highest minor version this crate writes: 1.2 for a file with a `PRNG` section, 1.1 for one
/// with `CAND` but no `PRNG`, 1.0 for neither (so each file declares the oldest format that
/// describes it; a reader of major version 1 skips the sections it does not know).
pub const VERSION_MINOR: u16 = 2;
/// Size of the fixed header.
pub const HEADER_LEN: usize = 64;
/// Size of one section-table entry.
pub const SECTION_ENTRY_LEN: usize = 32;
/// Size of the CONF section.
pub const CONF_LEN: usize = 128;
/// Size of the fixed part of the SKEL section.
pub const SKEL_HEADER_LEN: usize = 80;
/// Size of one joint record in SKEL.
pub const JOINT_RECORD_LEN: usize = 128;
/// Size of one tensor entry in TINF.
pub const TENSOR_ENTRY_LEN: usize = 64;
/// Alignment of sections and tensors.
pub const ALIGN: usize = 64;
/// Cap on the number of sections.
pub const MAX_SECTIONS: usize = 16;
/// Cap on the number of tensors.
pub const MAX_TENSORS: usize = 256;
/// Cap on the total file size (1 GiB).
pub const MAX_FILE_LEN: u64 = 1 << 30;
/// Cap on the positional-encoding frequency count.
pub const MAX_PE_FREQUENCIES: u32 = 16;
/// Cap on the number of hidden layers.
pub const MAX_HIDDEN_LAYERS: usize = 8;
/// Cap on one layer's width.
pub const MAX_LAYER_WIDTH: u32 = 4096;
/// Cap on the joint-name bytes.
pub const MAX_NAMES_LEN: usize = 1 << 20;

/// Section tags.
pub mod tag {
    /// Network configuration.
    pub const CONF: [u8; 4] = *b"CONF";
    /// Skeleton.
    pub const SKEL: [u8; 4] = *b"SKEL";
    /// Tensor table.
    pub const TINF: [u8; 4] = *b"TINF";
    /// Tensor data.
    pub const DATA: [u8; 4] = *b"DATA";
    /// Candidate joints of canonical anchors (version 1.1).
    pub const CAND: [u8; 4] = *b"CAND";
    /// Training range of the pose features (version 1.2).
    pub const PRNG: [u8; 4] = *b"PRNG";
}

/// FNV-1a 64 over `bytes`, continuing from `state` (start with [`FNV_OFFSET`]).
#[must_use]
pub fn fnv1a64(mut state: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        state ^= u64::from(b);
        state = state.wrapping_mul(0x0000_0100_0000_01b3);
    }
    state
}

/// FNV-1a 64 initial state.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// Checksum of a whole file: FNV-1a 64 of `bytes[..24] ++ bytes[32..]`.
#[must_use]
pub fn file_checksum(bytes: &[u8]) -> u64 {
    let h = fnv1a64(FNV_OFFSET, &bytes[..24.min(bytes.len())]);
    fnv1a64(h, bytes.get(32..).unwrap_or(&[]))
}

/// Rounds `n` up to a multiple of [`ALIGN`] (`None` on overflow).
#[must_use]
pub fn align_up(n: usize) -> Option<usize> {
    n.checked_add(ALIGN - 1).map(|v| v & !(ALIGN - 1))
}
