//! BVH (Biovision Hierarchy) motion import: the joint hierarchy becomes a [`Skeleton`] and
//! every frame of the MOTION block a [`Pose`].
//!
//! Conventions, as BVH defines them and as the CMU conversions use them:
//! - joints are stored in the file's order (a depth-first pre-order, so parents come first);
//!   `End Site` blocks are not joints: they are kept in [`BvhMotion::end_sites`];
//! - a joint's `OFFSET` is its bind local translation; bind rotations are the identity;
//! - each joint lists its own channels, in its own order (orders differ within one file); the
//!   rotation channels, in degrees, compose as `R(a₀)·R(a₁)·R(a₂)` in the order they are listed
//!   and map to [`crate::JointDofs::Euler`] with the axes in that order;
//! - position channels (on the root, and on any other joint that has them) are added to the
//!   `OFFSET` in the parent's frame;
//! - [`BvhOptions::unit_scale`] multiplies every length (offsets and position channels), e.g.
//!   [`CMU_UNIT_TO_METRES`] or [`CENTIMETRES_TO_METRES`].
//!
//! Every count read from the text is checked before anything is allocated from it: joints and
//! end sites are capped ([`MAX_JOINTS`], [`MAX_END_SITES`]), channels per joint by
//! [`MAX_CHANNELS_PER_JOINT`], and the declared frames must both stay under [`MAX_FRAMES`] and
//! [`MAX_POSE_TRANSFORMS`] and fit (at two bytes per value at least) in the text that follows.

mod parse;

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::pose::Pose;
use crate::skeleton::{Axis, MAX_JOINTS, Skeleton, SkeletonError};

pub use parse::parse_bvh;

/// Cap on the declared frame count (2.4 hours at 120 fps).
pub const MAX_FRAMES: usize = 1 << 20;
/// Cap on the channels of one joint (three positions and three rotations).
pub const MAX_CHANNELS_PER_JOINT: usize = 6;
/// Cap on the number of `End Site` blocks.
pub const MAX_END_SITES: usize = MAX_JOINTS;
/// Cap on `frames × joints`, the number of local transforms the poses hold (≈ 0.8 GB).
pub const MAX_POSE_TRANSFORMS: usize = 1 << 24;
/// Largest file [`load_bvh`] reads (1 GiB).
pub const MAX_BVH_FILE_LEN: u64 = 1 << 30;
/// One CMU mocap unit in metres: the CMU FAQ gives 1 unit = 1/0.45 inch.
pub const CMU_UNIT_TO_METRES: f32 = 0.0254 / 0.45;
/// Centimetres to metres.
pub const CENTIMETRES_TO_METRES: f32 = 0.01;
/// Inches to metres.
pub const INCHES_TO_METRES: f32 = 0.0254;

/// One channel of a joint, as named on its `CHANNELS` line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BvhChannel {
    /// Translation along the parent's X (file units).
    Xposition,
    /// Translation along the parent's Y.
    Yposition,
    /// Translation along the parent's Z.
    Zposition,
    /// Rotation about local X (degrees).
    Xrotation,
    /// Rotation about local Y (degrees).
    Yrotation,
    /// Rotation about local Z (degrees).
    Zrotation,
}

impl BvhChannel {
    const ALL: [Self; 6] = [
        Self::Xposition,
        Self::Yposition,
        Self::Zposition,
        Self::Xrotation,
        Self::Yrotation,
        Self::Zrotation,
    ];

    /// The channel's name as BVH spells it.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Xposition => "Xposition",
            Self::Yposition => "Yposition",
            Self::Zposition => "Zposition",
            Self::Xrotation => "Xrotation",
            Self::Yrotation => "Yrotation",
            Self::Zrotation => "Zrotation",
        }
    }

    /// Parses a channel name (ASCII case-insensitive: writers differ in case).
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(name))
    }

    /// The axis the channel translates along or rotates about.
    #[must_use]
    pub fn axis(self) -> Axis {
        match self {
            Self::Xposition | Self::Xrotation => Axis::X,
            Self::Yposition | Self::Yrotation => Axis::Y,
            Self::Zposition | Self::Zrotation => Axis::Z,
        }
    }

    /// True for the rotation channels.
    #[must_use]
    pub fn is_rotation(self) -> bool {
        matches!(self, Self::Xrotation | Self::Yrotation | Self::Zrotation)
    }
}

impl std::fmt::Display for BvhChannel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An `End Site`: the tip of a chain, not a joint, kept for drawing and for counting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhEndSite {
    /// The joint the end site hangs from.
    pub parent: usize,
    /// Its offset from that joint, scaled by [`BvhOptions::unit_scale`].
    pub offset: Vec3,
}

/// How to read a BVH file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhOptions {
    /// Multiplies every length (offsets, position channels), e.g. [`CMU_UNIT_TO_METRES`];
    /// must be finite and positive.
    pub unit_scale: f32,
}

impl Default for BvhOptions {
    fn default() -> Self {
        Self { unit_scale: 1.0 }
    }
}

/// A BVH clip: skeleton, frame timing, one pose per frame, and the channel layout.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhMotion {
    /// Joints in file order (End Sites excluded), `OFFSET`s as bind translations, identity bind
    /// rotations, Euler degrees of freedom in each joint's channel order.
    pub skeleton: Skeleton,
    /// Seconds per frame.
    pub frame_time: f32,
    /// One pose per frame.
    pub poses: Vec<Pose>,
    /// Each joint's channels in file order (empty for joints without channels).
    pub channels: Vec<Vec<BvhChannel>>,
    /// The raw channel values as written (degrees, file units), `frames × channel_count`,
    /// row-major in file order.
    pub values: Vec<f32>,
    /// The End Sites, in file order.
    pub end_sites: Vec<BvhEndSite>,
}

impl BvhMotion {
    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.poses.len()
    }

    /// Channels per frame, summed over joints.
    #[must_use]
    pub fn channel_count(&self) -> usize {
        self.channels.iter().map(Vec::len).sum()
    }

    /// Clip length: every frame is held for [`BvhMotion::frame_time`].
    #[must_use]
    pub fn duration_s(&self) -> f32 {
        self.frame_count() as f32 * self.frame_time
    }

    /// The raw values of frame `frame` (`None` past the end).
    #[must_use]
    pub fn frame_values(&self, frame: usize) -> Option<&[f32]> {
        let c = self.channel_count();
        let start = frame.checked_mul(c)?;
        self.values.get(start..start.checked_add(c)?)
    }
}

/// Why a BVH file was refused; parse errors name the line (1-based) and the field.
#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A parse error in a named file.
    #[error("{path}: {source}")]
    File {
        /// The file.
        path: PathBuf,
        /// The parse error.
        source: Box<BvhError>,
    },
    /// The file is larger than [`MAX_BVH_FILE_LEN`].
    #[error("{path}: {len} bytes exceed the cap of {MAX_BVH_FILE_LEN}")]
    FileTooLarge {
        /// The file.
        path: PathBuf,
        /// Its length.
        len: u64,
    },
    /// [`BvhOptions::unit_scale`] is not finite and positive.
    #[error("unit_scale {0} must be finite and positive")]
    BadUnitScale(f32),
    /// The text ends where something else was required.
    #[error("line {line}: expected {expected}, found the end of the file")]
    UnexpectedEof {
        /// Last line of the text.
        line: usize,
        /// What was expected.
        expected: &'static str,
    },
    /// A keyword or brace other than the one the grammar allows.
    #[error("line {line}: expected {expected}, found `{found}`")]
    Unexpected {
        /// Line.
        line: usize,
        /// What was expected.
        expected: &'static str,
        /// What was found (at most 40 characters).
        found: String,
    },
    /// A hierarchy or header number does not parse.
    #[error("line {line}: {field} `{text}` is not a valid number")]
    BadNumber {
        /// Line.
        line: usize,
        /// The field (`OFFSET`, `CHANNELS`, `Frames`, `Frame Time`).
        field: &'static str,
        /// The text (at most 40 characters).
        text: String,
    },
    /// A hierarchy number is NaN or infinite.
    #[error("line {line}: {field} is not finite")]
    NonFinite {
        /// Line.
        line: usize,
        /// The field.
        field: &'static str,
    },
    /// A `CHANNELS` line declares more than [`MAX_CHANNELS_PER_JOINT`] channels.
    #[error(
        "line {line}: joint `{joint}` declares {count} channels, at most {MAX_CHANNELS_PER_JOINT} are supported"
    )]
    ChannelCount {
        /// Line.
        line: usize,
        /// The joint.
        joint: String,
        /// The declared count.
        count: u64,
    },
    /// A channel name that is not one of the six BVH channels.
    #[error("line {line}: joint `{joint}` has unknown channel `{found}`")]
    UnknownChannel {
        /// Line.
        line: usize,
        /// The joint.
        joint: String,
        /// The name found (at most 40 characters).
        found: String,
    },
    /// A joint lists the same channel twice.
    #[error("line {line}: joint `{joint}` lists channel {channel} twice")]
    DuplicateChannel {
        /// Line.
        line: usize,
        /// The joint.
        joint: String,
        /// The repeated channel.
        channel: BvhChannel,
    },
    /// A joint or End Site has two `OFFSET` or two `CHANNELS` lines.
    #[error("line {line}: joint `{joint}` has a second {field}")]
    DuplicateField {
        /// Line.
        line: usize,
        /// The joint (or `End Site`).
        joint: String,
        /// `OFFSET` or `CHANNELS`.
        field: &'static str,
    },
    /// A joint or End Site closes without an `OFFSET`.
    #[error("line {line}: joint `{joint}` has no OFFSET")]
    MissingOffset {
        /// Line of the closing brace.
        line: usize,
        /// The joint (or `End Site`).
        joint: String,
    },
    /// More joints than [`MAX_JOINTS`] or End Sites than [`MAX_END_SITES`].
    #[error("line {line}: more than {max} {what}")]
    TooMany {
        /// Line.
        line: usize,
        /// `joints` or `End Sites`.
        what: &'static str,
        /// The cap.
        max: usize,
    },
    /// The declared frame count exceeds [`MAX_FRAMES`] or [`MAX_POSE_TRANSFORMS`].
    #[error("line {line}: {frames} frames of {joints} joints exceed the caps")]
    TooManyFrames {
        /// Line.
        line: usize,
        /// Declared frames.
        frames: u64,
        /// Joint count.
        joints: usize,
    },
    /// The declared frames cannot fit in the bytes that follow (two bytes per value at least).
    #[error(
        "line {line}: {frames} frames of {channels} channels cannot fit in the {bytes} bytes that follow"
    )]
    FramesExceedData {
        /// Line.
        line: usize,
        /// Declared frames.
        frames: u64,
        /// Channels per frame.
        channels: usize,
        /// Bytes after the header.
        bytes: usize,
    },
    /// `Frame Time` is not finite and positive.
    #[error("line {line}: Frame Time {value} must be finite and positive")]
    BadFrameTime {
        /// Line.
        line: usize,
        /// The value.
        value: f32,
    },
    /// A frame line holds another number of values than the channels.
    #[error("line {line}: frame {frame} has {found} values, expected {expected} (one per channel)")]
    FrameChannelCount {
        /// Line.
        line: usize,
        /// Frame index (0-based).
        frame: usize,
        /// Channels per frame.
        expected: usize,
        /// Values found.
        found: usize,
    },
    /// A frame value does not parse or is not finite.
    #[error(
        "line {line}: frame {frame}, joint `{joint}` channel {channel}: `{text}` is not a finite number"
    )]
    BadChannelValue {
        /// Line.
        line: usize,
        /// Frame index (0-based).
        frame: usize,
        /// The joint.
        joint: String,
        /// The channel.
        channel: BvhChannel,
        /// The text (at most 40 characters).
        text: String,
    },
    /// A joint's translation overflows to infinity once offset, channel and unit scale combine.
    #[error("line {line}: frame {frame}, joint `{joint}` has a non-finite translation")]
    NonFiniteTranslation {
        /// Line.
        line: usize,
        /// Frame index.
        frame: usize,
        /// The joint.
        joint: String,
    },
    /// The text ends before the declared number of frames.
    #[error("line {line}: the file ends after {found} of {expected} frames")]
    MissingFrames {
        /// Last line.
        line: usize,
        /// Declared frames.
        expected: usize,
        /// Frames present.
        found: usize,
    },
    /// Non-blank text after the last declared frame.
    #[error("line {line}: data after the last of {frames} declared frames")]
    TrailingData {
        /// Line.
        line: usize,
        /// Declared frames.
        frames: usize,
    },
    /// The hierarchy does not make a valid skeleton (two joints with one name, a bone whose
    /// scaled offset overflows).
    #[error("invalid joint hierarchy: {0}")]
    Skeleton(#[from] SkeletonError),
}

/// Reads and parses a BVH file in its own units ([`BvhOptions::default`]); errors name the
/// file (and the line for parse errors).
pub fn load_bvh(path: impl AsRef<Path>) -> Result<BvhMotion, BvhError> {
    load_bvh_with(path, &BvhOptions::default())
}

/// Reads and parses a BVH file with `options` (e.g. a unit scale to metres).
///
/// Bytes that are not UTF-8 (Latin-1 joint names) are replaced, not refused.
pub fn load_bvh_with(path: impl AsRef<Path>, options: &BvhOptions) -> Result<BvhMotion, BvhError> {
    let path = path.as_ref();
    let io = |source| BvhError::Io {
        path: path.to_owned(),
        source,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_BVH_FILE_LEN {
        return Err(BvhError::FileTooLarge {
            path: path.to_owned(),
            len,
        });
    }
    let bytes = std::fs::read(path).map_err(io)?;
    let text = String::from_utf8_lossy(&bytes);
    parse_bvh(&text, options).map_err(|e| BvhError::File {
        path: path.to_owned(),
        source: Box::new(e),
    })
}
