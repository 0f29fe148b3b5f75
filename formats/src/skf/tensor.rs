//! The pieces of a `.skf` a reader names: tensor names, section tags, element types, and a
//! tensor borrowed from the file's bytes.

use core::fmt;

use half::f16;

use super::SkfError;

/// A tensor name as stored (up to 24 bytes of UTF-8, zero padded).
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct TensorName(pub [u8; 24]);

impl TensorName {
    /// The name as text (empty when it is not UTF-8).
    #[must_use]
    pub fn as_str(&self) -> &str {
        let end = self.0.iter().position(|&b| b == 0).unwrap_or(24);
        core::str::from_utf8(&self.0[..end]).unwrap_or("")
    }

    /// Builds a stored name from text (`None` when longer than 24 bytes or empty).
    #[must_use]
    pub fn new(name: &str) -> Option<Self> {
        let b = name.as_bytes();
        if b.is_empty() || b.len() > 24 || b.contains(&0) {
            return None;
        }
        let mut n = [0; 24];
        n[..b.len()].copy_from_slice(b);
        Some(Self(n))
    }
}

impl fmt::Debug for TensorName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl fmt::Display for TensorName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A four-byte section tag.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Tag(pub [u8; 4]);

impl fmt::Debug for Tag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(self, f)
    }
}

impl fmt::Display for Tag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for &b in &self.0 {
            let c = if b.is_ascii_graphic() { b as char } else { '?' };
            write!(f, "{c}")?;
        }
        Ok(())
    }
}

/// Element type of a tensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// IEEE half precision.
    F16,
    /// IEEE single precision.
    F32,
}

impl Dtype {
    /// Stored code.
    #[must_use]
    pub fn code(self) -> u32 {
        match self {
            Dtype::F16 => 1,
            Dtype::F32 => 2,
        }
    }

    /// Bytes per element.
    #[must_use]
    pub fn size(self) -> usize {
        match self {
            Dtype::F16 => 2,
            Dtype::F32 => 4,
        }
    }

    pub(super) fn from_code(c: u32) -> Option<Self> {
        match c {
            1 => Some(Dtype::F16),
            2 => Some(Dtype::F32),
            _ => None,
        }
    }
}

/// A tensor borrowed from the file bytes.
#[derive(Clone, Copy, Debug)]
pub struct TensorView<'a> {
    /// Name.
    pub name: TensorName,
    /// Element type.
    pub dtype: Dtype,
    /// Rank (1 or 2).
    pub rank: u32,
    /// Dimensions (`[n, 0]` for rank 1, `[out, in]` for weights).
    pub dims: [u32; 2],
    /// Raw little-endian bytes.
    pub bytes: &'a [u8],
}

impl<'a> TensorView<'a> {
    /// Number of elements.
    #[must_use]
    pub fn len(&self) -> usize {
        self.bytes.len() / self.dtype.size()
    }

    /// True for a tensor without elements (never, for a validated file).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The elements in place, when the dtype is f16 and the buffer is 2-byte aligned on a
    /// little-endian machine.
    #[must_use]
    pub fn as_f16(&self) -> Option<&'a [f16]> {
        if self.dtype != Dtype::F16 || cfg!(target_endian = "big") {
            return None;
        }
        bytemuck::try_cast_slice(self.bytes).ok()
    }

    /// Element `i` as f32 (`None` out of range).
    #[must_use]
    pub fn get(&self, i: usize) -> Option<f32> {
        let s = self.dtype.size();
        let b = self
            .bytes
            .get(i.checked_mul(s)?..i.checked_mul(s)?.checked_add(s)?)?;
        Some(match self.dtype {
            Dtype::F16 => f16::from_le_bytes([b[0], b[1]]).to_f32(),
            Dtype::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        })
    }

    /// Expands every element to f32 into `out` (length = [`TensorView::len`]).
    pub fn to_f32(&self, out: &mut [f32]) -> Result<(), SkfError> {
        if out.len() != self.len() {
            return Err(SkfError::OutputLength {
                len: out.len(),
                expected: self.len(),
            });
        }
        match self.dtype {
            Dtype::F16 => {
                for (o, b) in out.iter_mut().zip(self.bytes.chunks_exact(2)) {
                    *o = f16::from_le_bytes([b[0], b[1]]).to_f32();
                }
            }
            Dtype::F32 => {
                for (o, b) in out.iter_mut().zip(self.bytes.chunks_exact(4)) {
                    *o = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
                }
            }
        }
        Ok(())
    }
}
