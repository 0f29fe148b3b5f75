//! The `PRNG` section (version 1.2): the range of pose features SkinNet was trained on.
//!
//! SkinNet's weights depend on the pose features `θ̃` ([`crate::pose_features`]), and a network
//! fitted to a few dozen training poses has no reason to extrapolate sensibly beyond them: on
//! the built-in capture the novel test motions (a high kick, a deep lunge) leave the training
//! range by up to 0.84 rad in some features, and those frames carried the largest errors.
//! The trainer therefore stores, per feature, the smallest and largest value over its training
//! frames, and the runtime clamps every feature into that box before the network sees it
//! (`skinfield_runtime::FrameState::set_pose`), so a pose beyond the training poses gets the
//! weights of the nearest pose inside their box, feature by feature. The skinning transforms are
//! not clamped: only what the network is asked about. A file without `PRNG` (versions 1.0 and
//! 1.1) is evaluated unclamped.
//!
//! ```text
//! PRNG  feature_count u32 | 0 u32 ×3 |
//!       feature_count × f32   lower bounds
//!       feature_count × f32   upper bounds
//! ```
//!
//! The section must be exactly that long; `feature_count` is the skeleton's
//! [`crate::pose_feature_count`]; every bound is finite and no lower bound exceeds its upper one.

use super::tag;
use super::view::{check_header_len, le_f32, le_u32};
use super::{SkfError, Tag};
use alloc::vec::Vec;

/// Size of the fixed part of the section.
pub const PRNG_HEADER_LEN: usize = 16;

/// A validated `PRNG` section, borrowed from the file's bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseRangeView<'a> {
    low: &'a [u8],
    high: &'a [u8],
}

impl<'a> PoseRangeView<'a> {
    /// Validates a `PRNG` section body for a model with `features` pose features.
    pub fn parse(body: &'a [u8], features: usize) -> Result<Self, SkfError> {
        let tag = Tag(tag::PRNG);
        check_header_len(body, tag, PRNG_HEADER_LEN)?;
        let count = le_u32(body, 0);
        if let Some(at) = (4..16).step_by(4).find(|&at| le_u32(body, at) != 0) {
            return Err(SkfError::ReservedNonZero(at as u64));
        }
        if count as usize != features {
            return Err(SkfError::PoseRangeCount {
                count,
                expected: features as u64,
            });
        }
        // `features` is 3 × a joint count the skeleton already bounded: no overflow.
        let expected = PRNG_HEADER_LEN + 8 * features;
        if body.len() != expected {
            return Err(SkfError::SectionLength {
                tag,
                len: body.len() as u64,
                expected: expected as u64,
            });
        }
        let view = Self {
            low: &body[PRNG_HEADER_LEN..PRNG_HEADER_LEN + 4 * features],
            high: &body[PRNG_HEADER_LEN + 4 * features..],
        };
        for i in 0..features {
            let (lo, hi) = (view.low(i), view.high(i));
            if !lo.is_finite() || !hi.is_finite() || lo > hi {
                return Err(SkfError::BadPoseRange(i as u32));
            }
        }
        Ok(view)
    }

    /// Number of features.
    #[must_use]
    pub fn len(&self) -> usize {
        self.low.len() / 4
    }

    /// Whether the range has no features (a skeleton without joints; never for a parsed file).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.low.is_empty()
    }

    /// Lower bound of feature `i` (`i < len()`).
    #[must_use]
    pub fn low(&self, i: usize) -> f32 {
        le_f32(self.low, 4 * i)
    }

    /// Upper bound of feature `i` (`i < len()`).
    #[must_use]
    pub fn high(&self, i: usize) -> f32 {
        le_f32(self.high, 4 * i)
    }
}

/// Serialises a `PRNG` body from per-feature bounds of equal length.
#[must_use]
pub fn prng_bytes(low: &[f32], high: &[f32]) -> Vec<u8> {
    let mut out = Vec::with_capacity(PRNG_HEADER_LEN + 4 * (low.len() + high.len()));
    out.extend_from_slice(&(low.len() as u32).to_le_bytes());
    out.extend_from_slice(&[0; 12]);
    for v in low.iter().chain(high) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body() -> Vec<u8> {
        prng_bytes(&[-1.0, 0.0, 0.5], &[1.0, 0.0, 2.0])
    }

    #[test]
    fn round_trip() {
        let b = body();
        let v = PoseRangeView::parse(&b, 3).unwrap();
        assert_eq!(v.len(), 3);
        assert_eq!((v.low(0), v.high(0)), (-1.0, 1.0));
        assert_eq!((v.low(1), v.high(1)), (0.0, 0.0));
        assert_eq!((v.low(2), v.high(2)), (0.5, 2.0));
    }

    #[test]
    fn every_bad_field_is_refused() {
        let b = body();
        let bad = |edit: &dyn Fn(&mut Vec<u8>), features: usize| {
            let mut x = b.clone();
            edit(&mut x);
            PoseRangeView::parse(&x, features).unwrap_err()
        };
        assert!(matches!(
            bad(&|x| x.truncate(10), 3),
            SkfError::SectionLength { .. }
        ));
        assert!(matches!(
            bad(&|x| x.truncate(x.len() - 1), 3),
            SkfError::SectionLength { .. }
        ));
        assert!(matches!(
            bad(&|x| x.extend_from_slice(&[0; 4]), 3),
            SkfError::SectionLength { .. }
        ));
        assert_eq!(bad(&|x| x[8] = 1, 3), SkfError::ReservedNonZero(8));
        assert_eq!(
            bad(&|_| {}, 6),
            SkfError::PoseRangeCount {
                count: 3,
                expected: 6
            }
        );
        assert_eq!(
            bad(&|x| x[0..4].copy_from_slice(&u32::MAX.to_le_bytes()), 3),
            SkfError::PoseRangeCount {
                count: u32::MAX,
                expected: 3
            }
        );
        // A NaN lower bound, an infinite upper bound, a lower bound above its upper one.
        assert_eq!(
            bad(&|x| x[20..24].copy_from_slice(&f32::NAN.to_le_bytes()), 3),
            SkfError::BadPoseRange(1)
        );
        assert_eq!(
            bad(
                &|x| x[36..40].copy_from_slice(&f32::INFINITY.to_le_bytes()),
                3
            ),
            SkfError::BadPoseRange(2)
        );
        assert_eq!(
            bad(&|x| x[16..20].copy_from_slice(&3.0f32.to_le_bytes()), 3),
            SkfError::BadPoseRange(0)
        );
    }
}
