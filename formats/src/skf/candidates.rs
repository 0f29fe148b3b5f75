//! The `CAND` section (version 1.1): which joints a point of the canonical space may be skinned
//! to.
//!
//! SkinNet's weights are a softmax over its *candidate* joints only; every other joint's weight
//! is zero (a masked softmax in the trainer and the runtime). The candidates of any canonical
//! point are those of its nearest *anchor*: the trainer stores its training template's vertices
//! as anchors with their candidate lists, so the runtime can rebuild the lists for a mesh of any
//! resolution at bind time. A file without `CAND` (version 1.0) has no mask: every joint is a
//! candidate everywhere.
//!
//! ```text
//! CAND  anchor_count u32 | k u32 | 0 u32 ×2 |
//!       anchor_count × 3 f32   canonical positions
//!       anchor_count × k u16   joint indices, ascending, padded with 0xFFFF
//! ```
//!
//! The section must be exactly that long. Every anchor has at least one candidate; indices are
//! below the joint count and strictly ascending before the padding; positions are finite.

use super::tag;
use super::view::{check_header_len, le_f32, le_u16, le_u32};
use super::{SkfError, Tag};
use alloc::vec::Vec;

/// Cap on the number of anchors.
pub const MAX_ANCHORS: usize = 1 << 22;
/// Cap on the candidates per anchor.
pub const MAX_CANDIDATES: usize = 64;
/// Padding of a candidate list.
pub const NO_JOINT: u16 = u16::MAX;
/// Size of the fixed part of the section.
pub const CAND_HEADER_LEN: usize = 16;

/// A validated `CAND` section, borrowed from the file's bytes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CandidatesView<'a> {
    positions: &'a [u8],
    joints: &'a [u8],
    count: usize,
    k: usize,
}

impl<'a> CandidatesView<'a> {
    /// Validates a `CAND` section body for a skeleton of `joints` joints.
    pub fn parse(body: &'a [u8], joints: usize) -> Result<Self, SkfError> {
        let tag = Tag(tag::CAND);
        check_header_len(body, tag, CAND_HEADER_LEN)?;
        let count = le_u32(body, 0) as usize;
        let k = le_u32(body, 4) as usize;
        if le_u32(body, 8) != 0 || le_u32(body, 12) != 0 {
            return Err(SkfError::ReservedNonZero(8));
        }
        if count == 0 || count > MAX_ANCHORS {
            return Err(SkfError::AnchorCount(count as u64));
        }
        if k == 0 || k > MAX_CANDIDATES {
            return Err(SkfError::CandidateCount(k as u64));
        }
        // Bounded by the caps above: no overflow on any platform with 32-bit usize or more.
        let positions_len = count * 12;
        let expected = CAND_HEADER_LEN + positions_len + count * k * 2;
        if body.len() != expected {
            return Err(SkfError::SectionLength {
                tag,
                len: body.len() as u64,
                expected: expected as u64,
            });
        }
        let view = Self {
            positions: &body[CAND_HEADER_LEN..CAND_HEADER_LEN + positions_len],
            joints: &body[CAND_HEADER_LEN + positions_len..],
            count,
            k,
        };
        for a in 0..count {
            if (0..3).any(|c| !le_f32(view.positions, 12 * a + 4 * c).is_finite()) {
                return Err(SkfError::BadAnchor(a as u32));
            }
            let mut previous: Option<u16> = None;
            let mut padding = false;
            for c in 0..k {
                let j = le_u16(view.joints, 2 * (a * k + c));
                if j == NO_JOINT {
                    padding = true;
                    continue;
                }
                let ascending = previous.is_none_or(|p| j > p);
                if padding || !ascending || j as usize >= joints {
                    return Err(SkfError::BadAnchor(a as u32));
                }
                previous = Some(j);
            }
            if previous.is_none() {
                return Err(SkfError::BadAnchor(a as u32));
            }
        }
        Ok(view)
    }

    /// Number of anchors.
    #[must_use]
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether there are no anchors (never true for a parsed section).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Slots per candidate list.
    #[must_use]
    pub fn k(&self) -> usize {
        self.k
    }

    /// The canonical position of anchor `a` (`a < len()`).
    #[must_use]
    pub fn position(&self, a: usize) -> [f32; 3] {
        core::array::from_fn(|c| le_f32(self.positions, 12 * a + 4 * c))
    }

    /// The candidate joints of anchor `a` (`a < len()`), ascending, without padding.
    pub fn joints(&self, a: usize) -> impl Iterator<Item = u16> + '_ {
        (0..self.k)
            .map(move |c| le_u16(self.joints, 2 * (a * self.k + c)))
            .take_while(|&j| j != NO_JOINT)
    }
}

/// Serialises a `CAND` body from anchors and their lists (each ascending, at most `k` joints).
#[must_use]
pub fn cand_bytes(positions: &[[f32; 3]], lists: &[Vec<u16>], k: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(CAND_HEADER_LEN + positions.len() * (12 + 2 * k));
    out.extend_from_slice(&(positions.len() as u32).to_le_bytes());
    out.extend_from_slice(&(k as u32).to_le_bytes());
    out.extend_from_slice(&[0; 8]);
    for p in positions {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for list in lists {
        for c in 0..k {
            let j = list.get(c).copied().unwrap_or(NO_JOINT);
            out.extend_from_slice(&j.to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body() -> Vec<u8> {
        cand_bytes(
            &[[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]],
            &[vec![0, 2], vec![1]],
            3,
        )
    }

    #[test]
    fn round_trip() {
        let b = body();
        let v = CandidatesView::parse(&b, 3).unwrap();
        assert_eq!((v.len(), v.k()), (2, 3));
        assert_eq!(v.position(1), [3.0, 4.0, 5.0]);
        assert_eq!(v.joints(0).collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(v.joints(1).collect::<Vec<_>>(), vec![1]);
    }

    #[test]
    fn every_bad_field_is_refused() {
        let b = body();
        let bad = |edit: &dyn Fn(&mut Vec<u8>), joints: usize| {
            let mut x = b.clone();
            edit(&mut x);
            CandidatesView::parse(&x, joints).unwrap_err()
        };
        assert!(matches!(
            bad(&|x| x.truncate(10), 3),
            SkfError::SectionLength { .. }
        ));
        assert!(matches!(
            bad(&|x| x.truncate(x.len() - 1), 3),
            SkfError::SectionLength { .. }
        ));
        assert_eq!(bad(&|x| x[8] = 1, 3), SkfError::ReservedNonZero(8));
        assert_eq!(
            bad(&|x| x[0..4].copy_from_slice(&0u32.to_le_bytes()), 3),
            SkfError::AnchorCount(0)
        );
        assert_eq!(
            bad(&|x| x[0..4].copy_from_slice(&u32::MAX.to_le_bytes()), 3),
            SkfError::AnchorCount(u64::from(u32::MAX))
        );
        assert_eq!(
            bad(&|x| x[4..8].copy_from_slice(&0u32.to_le_bytes()), 3),
            SkfError::CandidateCount(0)
        );
        assert_eq!(
            bad(&|x| x[4..8].copy_from_slice(&1000u32.to_le_bytes()), 3),
            SkfError::CandidateCount(1000)
        );
        // A NaN position.
        assert_eq!(
            bad(&|x| x[16..20].copy_from_slice(&f32::NAN.to_le_bytes()), 3),
            SkfError::BadAnchor(0)
        );
        let lists = 16 + 24;
        // Joint index out of range for a 2-joint skeleton.
        assert_eq!(bad(&|_| {}, 2), SkfError::BadAnchor(0));
        // Not ascending.
        assert_eq!(
            bad(
                &|x| x[lists..lists + 2].copy_from_slice(&2u16.to_le_bytes()),
                3
            ),
            SkfError::BadAnchor(0)
        );
        // A joint after the padding.
        assert_eq!(
            bad(
                &|x| x[lists + 10..lists + 12].copy_from_slice(&2u16.to_le_bytes()),
                3
            ),
            SkfError::BadAnchor(1)
        );
        // An empty list.
        assert_eq!(
            bad(
                &|x| x[lists + 6..lists + 8].copy_from_slice(&NO_JOINT.to_le_bytes()),
                3
            ),
            SkfError::BadAnchor(1)
        );
    }
}
