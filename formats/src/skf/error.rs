//! The reasons `.skf` bytes are refused, one variant per failure.

use super::{SkfConfigError, Tag, TensorName};

/// Why `.skf` bytes were refused. Each failure has its own variant.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SkfError {
    /// Fewer bytes than the header or the section table need.
    #[error("file is truncated: {needed} bytes needed, {len} present")]
    Truncated {
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        len: u64,
    },
    /// The magic bytes are wrong.
    #[error("not a .skf file (bad magic)")]
    BadMagic,
    /// A major version this reader does not know.
    #[error("unsupported .skf version {major}.{minor}")]
    UnsupportedVersion {
        /// Major version.
        major: u16,
        /// Minor version.
        minor: u16,
    },
    /// The header's `file_len` differs from the number of bytes.
    #[error("header declares {declared} bytes but the file has {actual}")]
    LengthMismatch {
        /// Declared length.
        declared: u64,
        /// Actual length.
        actual: u64,
    },
    /// The file is larger than [`MAX_FILE_LEN`](super::MAX_FILE_LEN).
    #[error("file of {0} bytes exceeds the cap")]
    TooLarge(u64),
    /// Checksum mismatch (corruption).
    #[error("checksum mismatch: stored {stored:#018x}, computed {computed:#018x}")]
    Checksum {
        /// Stored value.
        stored: u64,
        /// Computed value.
        computed: u64,
    },
    /// Reserved header or table bytes are not zero.
    #[error("reserved bytes at offset {0} are not zero")]
    ReservedNonZero(u64),
    /// Zero sections or more than [`MAX_SECTIONS`](super::MAX_SECTIONS).
    #[error("section count {0} is out of range")]
    SectionCount(u32),
    /// A section does not start on a 64-byte boundary or precedes the end of the previous one.
    #[error("section `{tag}` at offset {offset} is misplaced")]
    SectionPlacement {
        /// Section tag.
        tag: Tag,
        /// Its offset.
        offset: u64,
    },
    /// A section runs past the end of the file.
    #[error("section `{tag}` runs past the end of the file")]
    SectionOutOfBounds {
        /// Section tag.
        tag: Tag,
    },
    /// Bytes between or after sections that no section covers (and are not short zero padding).
    #[error("{len} bytes at offset {offset} are not covered by any section")]
    Uncovered {
        /// Offset of the gap.
        offset: u64,
        /// Its length.
        len: u64,
    },
    /// A required section is missing.
    #[error("section `{0}` is missing")]
    MissingSection(Tag),
    /// A section appears twice.
    #[error("section `{0}` appears twice")]
    DuplicateSection(Tag),
    /// The `CAND` section's anchor count is zero or above the cap.
    #[error("CAND: {0} anchors is out of range")]
    AnchorCount(u64),
    /// The `CAND` section's list length is zero or above the cap.
    #[error("CAND: {0} candidates per anchor is out of range")]
    CandidateCount(u64),
    /// An anchor's position is not finite, or its candidate list is empty, unsorted, repeats a
    /// joint, names a joint the skeleton lacks or continues after its padding.
    #[error("CAND: anchor {0} is invalid")]
    BadAnchor(u32),
    /// The `PRNG` section's feature count is not the skeleton's pose-feature count.
    #[error("PRNG: {count} pose features, the skeleton has {expected}")]
    PoseRangeCount {
        /// Count in the section.
        count: u32,
        /// `3 × joint count`.
        expected: u64,
    },
    /// A `PRNG` bound is not finite, or a lower bound exceeds its upper one.
    #[error("PRNG: the range of pose feature {0} is invalid")]
    BadPoseRange(u32),
    /// A section has the wrong length for its contents.
    #[error("section `{tag}` is {len} bytes, expected {expected}")]
    SectionLength {
        /// Section tag.
        tag: Tag,
        /// Its length.
        len: u64,
        /// Length implied by its contents.
        expected: u64,
    },
    /// The CONF section is invalid.
    #[error(transparent)]
    Config(#[from] SkfConfigError),
    /// The skeleton's joint count differs from CONF's or exceeds the cap.
    #[error("SKEL has {skel} joints, CONF says {conf}")]
    JointCount {
        /// SKEL's count.
        skel: u32,
        /// CONF's count.
        conf: u32,
    },
    /// A joint's parent is not an earlier joint.
    #[error("SKEL joint {0} has an invalid parent")]
    BadParent(u32),
    /// A joint's name is out of the names block or not UTF-8.
    #[error("SKEL joint {0} has an invalid name")]
    BadJointName(u32),
    /// A skeleton transform is NaN or infinite.
    #[error("SKEL joint {0} has a non-finite transform")]
    NonFiniteJoint(u32),
    /// More tensors than [`MAX_TENSORS`](super::MAX_TENSORS).
    #[error("tensor count {0} exceeds the cap")]
    TensorCount(u32),
    /// A tensor name is empty, not UTF-8, or repeated.
    #[error("tensor entry {0} has an invalid or repeated name")]
    BadTensorName(u32),
    /// Unknown dtype code.
    #[error("tensor `{name}` has unknown dtype {code}")]
    BadDtype {
        /// Tensor name.
        name: TensorName,
        /// The code.
        code: u32,
    },
    /// Rank not 1 or 2, or a zero dimension, or unused dims not zero.
    #[error("tensor `{0}` has an invalid shape")]
    BadShape(TensorName),
    /// `nbytes` does not equal the element count times the dtype size.
    #[error("tensor `{0}` declares a byte size that does not match its shape")]
    ByteSize(TensorName),
    /// Tensor bytes out of DATA, misaligned, overlapping, or not in offset order.
    #[error("tensor `{0}` is misplaced in DATA")]
    TensorPlacement(TensorName),
    /// A tensor the configured networks need is missing.
    #[error("tensor `{0}` is missing")]
    MissingTensor(TensorName),
    /// A network tensor has a shape other than the one CONF implies.
    #[error("tensor `{name}` has shape {got:?}, expected {expected:?}")]
    TensorShape {
        /// Tensor name.
        name: TensorName,
        /// Stored dims.
        got: [u32; 2],
        /// Expected dims.
        expected: [u32; 2],
    },
    /// A caller's output buffer has the wrong length.
    #[error("output buffer has {len} entries, expected {expected}")]
    OutputLength {
        /// Its length.
        len: usize,
        /// Expected.
        expected: usize,
    },
}
