//! Zero-copy, allocation-free validation and reading of `.skf` bytes.

use glam::{Mat4, Quat, Vec3};

use super::config::{ModelConfig, Net};
use super::*;
use crate::math::Transform;

/// The skeleton stored in a `.skf`, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct SkeletonView<'a> {
    records: &'a [u8],
    names: &'a [u8],
    base: Mat4,
    count: usize,
}

impl<'a> SkeletonView<'a> {
    /// Number of joints.
    #[must_use]
    pub fn len(&self) -> usize {
        self.count
    }

    /// True when there are no joints (never, for a validated file).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    fn record(&self, j: usize) -> &'a [u8] {
        &self.records[j * JOINT_RECORD_LEN..(j + 1) * JOINT_RECORD_LEN]
    }

    /// Name of joint `j` (panics when `j >= len()`, like slice indexing).
    #[must_use]
    pub fn name(&self, j: usize) -> &'a str {
        let r = self.record(j);
        let (off, len) = (le_u32(r, 4) as usize, le_u32(r, 8) as usize);
        // Validated at parse time.
        core::str::from_utf8(&self.names[off..off + len]).unwrap_or("")
    }

    /// Parent of joint `j`.
    #[must_use]
    pub fn parent(&self, j: usize) -> Option<usize> {
        let p = le_u32(self.record(j), 0);
        (p != u32::MAX).then_some(p as usize)
    }

    /// Bind-pose local transform of joint `j`.
    #[must_use]
    pub fn bind_local(&self, j: usize) -> Transform {
        let r = self.record(j);
        let f = |k: usize| le_f32(r, 16 + 4 * k);
        Transform {
            translation: Vec3::new(f(0), f(1), f(2)),
            rotation: Quat::from_xyzw(f(3), f(4), f(5), f(6)),
            scale: Vec3::new(f(7), f(8), f(9)),
        }
    }

    /// Inverse bind matrix of joint `j`.
    #[must_use]
    pub fn inverse_bind(&self, j: usize) -> Mat4 {
        let r = self.record(j);
        Mat4::from_cols_array(&core::array::from_fn(|k| le_f32(r, 56 + 4 * k)))
    }

    /// Transform above every root.
    #[must_use]
    pub fn base(&self) -> Mat4 {
        self.base
    }

    /// Copies the skeleton into an owned [`crate::Skeleton`] (all joints [`crate::JointDofs::Free`]).
    pub fn to_skeleton(&self) -> Result<crate::Skeleton, crate::SkeletonError> {
        use alloc::string::ToString;
        crate::Skeleton::new(
            (0..self.count).map(|j| self.name(j).to_string()).collect(),
            (0..self.count).map(|j| self.parent(j)).collect(),
            (0..self.count).map(|j| self.bind_local(j)).collect(),
            Some((0..self.count).map(|j| self.inverse_bind(j)).collect()),
            None,
            self.base,
        )
    }
}

/// A validated `.skf` file borrowed from its bytes.
#[derive(Clone, Copy, Debug)]
pub struct SkfView<'a> {
    config: ModelConfig,
    skeleton: SkeletonView<'a>,
    table: &'a [u8],
    data: &'a [u8],
    minor: u16,
    candidates: Option<super::candidates::CandidatesView<'a>>,
    pose_range: Option<super::pose_range::PoseRangeView<'a>>,
}

pub(super) fn le_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

pub(super) fn le_u32(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    let mut a = [0; 8];
    a.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(a)
}

pub(super) fn le_f32(b: &[u8], at: usize) -> f32 {
    f32::from_bits(le_u32(b, at))
}

/// Checks that an optional section's body holds at least its fixed header.
pub(super) fn check_header_len(body: &[u8], tag: Tag, header_len: usize) -> Result<(), SkfError> {
    if body.len() < header_len {
        return Err(SkfError::SectionLength {
            tag,
            len: body.len() as u64,
            expected: header_len as u64,
        });
    }
    Ok(())
}

/// Checks that `[start, end)` is fewer than [`ALIGN`] zero bytes.
fn check_padding(bytes: &[u8], start: usize, end: usize) -> Result<(), SkfError> {
    if end < start || end - start >= ALIGN || bytes[start..end].iter().any(|&b| b != 0) {
        return Err(SkfError::Uncovered {
            offset: start as u64,
            len: end.saturating_sub(start) as u64,
        });
    }
    Ok(())
}

impl<'a> SkfView<'a> {
    /// Validates `bytes` completely (header, checksum, sections, coverage, config, skeleton,
    /// tensor table, network shapes) and returns a view; never allocates or panics.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, SkfError> {
        let len = bytes.len() as u64;
        if bytes.len() < HEADER_LEN {
            return Err(SkfError::Truncated {
                needed: HEADER_LEN as u64,
                len,
            });
        }
        if bytes[..8] != MAGIC {
            return Err(SkfError::BadMagic);
        }
        let (major, minor) = (le_u16(bytes, 8), le_u16(bytes, 10));
        if major != VERSION_MAJOR {
            return Err(SkfError::UnsupportedVersion { major, minor });
        }
        let section_count = le_u32(bytes, 12);
        let declared = le_u64(bytes, 16);
        if declared > MAX_FILE_LEN {
            return Err(SkfError::TooLarge(declared));
        }
        if declared != len {
            return Err(if declared > len {
                SkfError::Truncated {
                    needed: declared,
                    len,
                }
            } else {
                SkfError::LengthMismatch {
                    declared,
                    actual: len,
                }
            });
        }
        let stored = le_u64(bytes, 24);
        let computed = file_checksum(bytes);
        if stored != computed {
            return Err(SkfError::Checksum { stored, computed });
        }
        if let Some(k) = bytes[32..HEADER_LEN].iter().position(|&b| b != 0) {
            return Err(SkfError::ReservedNonZero((32 + k) as u64));
        }
        if section_count == 0 || section_count as usize > MAX_SECTIONS {
            return Err(SkfError::SectionCount(section_count));
        }
        // Bounded by MAX_SECTIONS: cannot overflow.
        let table_end = HEADER_LEN + SECTION_ENTRY_LEN * section_count as usize;
        if bytes.len() < table_end {
            return Err(SkfError::Truncated {
                needed: table_end as u64,
                len,
            });
        }
        let mut found: [Option<&[u8]>; 6] = [None; 6];
        let mut cursor = table_end;
        for s in 0..section_count as usize {
            let e = &bytes
                [HEADER_LEN + s * SECTION_ENTRY_LEN..HEADER_LEN + (s + 1) * SECTION_ENTRY_LEN];
            let tag = Tag([e[0], e[1], e[2], e[3]]);
            let (offset, slen) = (le_u64(e, 8), le_u64(e, 16));
            if le_u32(e, 4) != 0 || le_u64(e, 24) != 0 {
                return Err(SkfError::ReservedNonZero(
                    (HEADER_LEN + s * SECTION_ENTRY_LEN) as u64,
                ));
            }
            let end = offset
                .checked_add(slen)
                .filter(|&end| end <= len)
                .ok_or(SkfError::SectionOutOfBounds { tag })?;
            // Both fit in usize: they are <= len.
            let (offset, end) = (offset as usize, end as usize);
            if offset % ALIGN != 0 || offset < cursor {
                return Err(SkfError::SectionPlacement {
                    tag,
                    offset: offset as u64,
                });
            }
            check_padding(bytes, cursor, offset)?;
            cursor = end;
            let slot = match tag.0 {
                tag::CONF => 0,
                tag::SKEL => 1,
                tag::TINF => 2,
                tag::DATA => 3,
                tag::CAND => 4,
                tag::PRNG => 5,
                _ => continue,
            };
            if found[slot].is_some() {
                return Err(SkfError::DuplicateSection(tag));
            }
            found[slot] = Some(&bytes[offset..end]);
        }
        if cursor != bytes.len() {
            return Err(SkfError::Uncovered {
                offset: cursor as u64,
                len: len - cursor as u64,
            });
        }
        let tags = [tag::CONF, tag::SKEL, tag::TINF, tag::DATA];
        let get = |k: usize| found[k].ok_or(SkfError::MissingSection(Tag(tags[k])));
        let (conf, skel, tinf, data) = (get(0)?, get(1)?, get(2)?, get(3)?);

        if conf.len() != CONF_LEN {
            return Err(SkfError::SectionLength {
                tag: Tag(tag::CONF),
                len: conf.len() as u64,
                expected: CONF_LEN as u64,
            });
        }
        let config = ModelConfig::from_bytes(conf)?;
        let skeleton = Self::parse_skeleton(skel, &config)?;
        let table = Self::parse_table(tinf, data)?;
        let candidates = match found[4] {
            Some(body) => Some(super::candidates::CandidatesView::parse(
                body,
                config.joint_count as usize,
            )?),
            None => None,
        };
        let pose_range = match found[5] {
            Some(body) => Some(super::pose_range::PoseRangeView::parse(
                body,
                crate::pose_feature_count(config.joint_count as usize),
            )?),
            None => None,
        };
        let view = Self {
            config,
            skeleton,
            table,
            data,
            minor,
            candidates,
            pose_range,
        };
        for net in [Net::Skin, Net::Albedo, Net::Shadow] {
            if config.nets & net.bit() != 0 {
                view.check_net(net)?;
            }
        }
        Ok(view)
    }

    fn parse_skeleton(skel: &'a [u8], config: &ModelConfig) -> Result<SkeletonView<'a>, SkfError> {
        let tag = Tag(tag::SKEL);
        if skel.len() < SKEL_HEADER_LEN {
            return Err(SkfError::SectionLength {
                tag,
                len: skel.len() as u64,
                expected: SKEL_HEADER_LEN as u64,
            });
        }
        let count = le_u32(skel, 0);
        let names_len = le_u32(skel, 4) as usize;
        if le_u32(skel, 8) != 0 || le_u32(skel, 12) != 0 {
            return Err(SkfError::ReservedNonZero(8));
        }
        if count != config.joint_count {
            return Err(SkfError::JointCount {
                skel: count,
                conf: config.joint_count,
            });
        }
        // joint_count <= MAX_JOINTS and names_len <= MAX_NAMES_LEN keep this far from overflow.
        if names_len > MAX_NAMES_LEN {
            return Err(SkfError::SectionLength {
                tag,
                len: skel.len() as u64,
                expected: MAX_NAMES_LEN as u64,
            });
        }
        let records_len = JOINT_RECORD_LEN * count as usize;
        let expected = SKEL_HEADER_LEN + records_len + names_len;
        if skel.len() != expected {
            return Err(SkfError::SectionLength {
                tag,
                len: skel.len() as u64,
                expected: expected as u64,
            });
        }
        let base = Mat4::from_cols_array(&core::array::from_fn(|k| le_f32(skel, 16 + 4 * k)));
        if !base.is_finite() {
            return Err(SkfError::NonFiniteJoint(0));
        }
        let view = SkeletonView {
            records: &skel[SKEL_HEADER_LEN..SKEL_HEADER_LEN + records_len],
            names: &skel[SKEL_HEADER_LEN + records_len..],
            base,
            count: count as usize,
        };
        for j in 0..count as usize {
            let r = view.record(j);
            let parent = le_u32(r, 0);
            if parent != u32::MAX && parent as usize >= j {
                return Err(SkfError::BadParent(j as u32));
            }
            let (off, nlen) = (le_u32(r, 4) as usize, le_u32(r, 8) as usize);
            let name = off
                .checked_add(nlen)
                .and_then(|end| view.names.get(off..end));
            match name.map(core::str::from_utf8) {
                Some(Ok(s)) if !s.is_empty() => {}
                _ => return Err(SkfError::BadJointName(j as u32)),
            }
            if le_u32(r, 12) != 0 || r[120..].iter().any(|&b| b != 0) {
                return Err(SkfError::ReservedNonZero(j as u64));
            }
            if (4..30).any(|k| !le_f32(r, 4 * k).is_finite()) {
                return Err(SkfError::NonFiniteJoint(j as u32));
            }
        }
        Ok(view)
    }

    fn parse_table(tinf: &'a [u8], data: &'a [u8]) -> Result<&'a [u8], SkfError> {
        let tag = Tag(tag::TINF);
        if tinf.len() < 8 {
            return Err(SkfError::SectionLength {
                tag,
                len: tinf.len() as u64,
                expected: 8,
            });
        }
        let count = le_u32(tinf, 0);
        if le_u32(tinf, 4) != 0 {
            return Err(SkfError::ReservedNonZero(4));
        }
        if count as usize > MAX_TENSORS {
            return Err(SkfError::TensorCount(count));
        }
        let expected = 8 + TENSOR_ENTRY_LEN * count as usize;
        if tinf.len() != expected {
            return Err(SkfError::SectionLength {
                tag,
                len: tinf.len() as u64,
                expected: expected as u64,
            });
        }
        let table = &tinf[8..];
        let mut cursor = 0usize;
        for i in 0..count as usize {
            let t = entry(table, i);
            let name = t.name;
            if name.as_str().is_empty() || (0..i).any(|k| entry(table, k).name == name) {
                return Err(SkfError::BadTensorName(i as u32));
            }
            let dtype = Dtype::from_code(t.dtype).ok_or(SkfError::BadDtype {
                name,
                code: t.dtype,
            })?;
            let [d0, d1] = t.dims;
            let shape_ok = match t.rank {
                1 => d0 > 0 && d1 == 0,
                2 => d0 > 0 && d1 > 0,
                _ => false,
            } && t.extra_dims == [0, 0]
                && t.reserved == 0;
            if !shape_ok {
                return Err(SkfError::BadShape(name));
            }
            let elems = u64::from(d0) * u64::from(d1.max(1));
            if elems.checked_mul(dtype.size() as u64) != Some(t.nbytes) {
                return Err(SkfError::ByteSize(name));
            }
            let end = t
                .offset
                .checked_add(t.nbytes)
                .filter(|&e| e <= data.len() as u64);
            let Some(end) = end else {
                return Err(SkfError::TensorPlacement(name));
            };
            let (offset, end) = (t.offset as usize, end as usize);
            if offset % ALIGN != 0
                || offset < cursor
                || check_padding(data, cursor, offset).is_err()
            {
                return Err(SkfError::TensorPlacement(name));
            }
            cursor = end;
        }
        if cursor != data.len() {
            return Err(SkfError::Uncovered {
                offset: cursor as u64,
                len: (data.len() - cursor) as u64,
            });
        }
        Ok(table)
    }

    fn check_net(&self, net: Net) -> Result<(), SkfError> {
        let n = self.config.hidden_widths().len();
        for (i, (out, inp)) in self.config.layer_shapes(net).enumerate() {
            let layer = if i < n {
                LayerName::Hidden(i)
            } else {
                LayerName::Out
            };
            for (kind, expected) in [
                ("weight", [out as u32, inp as u32]),
                ("bias", [out as u32, 0]),
            ] {
                let name = tensor_name(net, layer, kind);
                let t = self.tensor_by(&name).ok_or(SkfError::MissingTensor(name))?;
                if t.dims != expected {
                    return Err(SkfError::TensorShape {
                        name,
                        got: t.dims,
                        expected,
                    });
                }
            }
        }
        Ok(())
    }

    fn tensor_by(&self, name: &TensorName) -> Option<TensorView<'a>> {
        (0..self.table.len() / TENSOR_ENTRY_LEN)
            .map(|i| self.tensor_at(i))
            .find(|t| t.name == *name)
    }

    fn tensor_at(&self, i: usize) -> TensorView<'a> {
        let e = entry(self.table, i);
        // Validated at parse time.
        let dtype = Dtype::from_code(e.dtype).unwrap_or(Dtype::F16);
        let (start, end) = (e.offset as usize, (e.offset + e.nbytes) as usize);
        TensorView {
            name: e.name,
            dtype,
            rank: e.rank,
            dims: e.dims,
            bytes: &self.data[start..end],
        }
    }

    /// Network configuration.
    #[must_use]
    pub fn config(&self) -> &ModelConfig {
        &self.config
    }

    /// Minor version of the file.
    #[must_use]
    pub fn minor_version(&self) -> u16 {
        self.minor
    }

    /// The candidate joints of the canonical anchors (`CAND`), if the file has them; without
    /// them every joint is a candidate everywhere.
    #[must_use]
    pub fn candidates(&self) -> Option<super::candidates::CandidatesView<'a>> {
        self.candidates
    }

    /// The training range of the pose features (`PRNG`), if the file has it; without it the
    /// features are not clamped.
    #[must_use]
    pub fn pose_range(&self) -> Option<super::pose_range::PoseRangeView<'a>> {
        self.pose_range
    }

    /// The stored skeleton (joint order = SkinNet output order = pose-feature order).
    #[must_use]
    pub fn skeleton(&self) -> SkeletonView<'a> {
        self.skeleton
    }

    /// Number of tensors.
    #[must_use]
    pub fn tensor_count(&self) -> usize {
        self.table.len() / TENSOR_ENTRY_LEN
    }

    /// Tensor by name.
    #[must_use]
    pub fn tensor(&self, name: &str) -> Option<TensorView<'a>> {
        self.tensor_by(&TensorName::new(name)?)
    }

    /// All tensors in table order.
    pub fn tensors(&self) -> impl Iterator<Item = TensorView<'a>> + '_ {
        (0..self.tensor_count()).map(|i| self.tensor_at(i))
    }

    /// Weight (`[out, in]`) and bias of layer `layer` of `net` (hidden layers `0..n`, then the
    /// output layer at index `n`); `None` when the net is not stored or the index is too large.
    #[must_use]
    pub fn layer(&self, net: Net, layer: usize) -> Option<(TensorView<'a>, TensorView<'a>)> {
        if self.config.nets & net.bit() == 0 {
            return None;
        }
        let n = self.config.hidden_widths().len();
        let l = match layer.cmp(&n) {
            core::cmp::Ordering::Less => LayerName::Hidden(layer),
            core::cmp::Ordering::Equal => LayerName::Out,
            core::cmp::Ordering::Greater => return None,
        };
        Some((
            self.tensor_by(&tensor_name(net, l, "weight"))?,
            self.tensor_by(&tensor_name(net, l, "bias"))?,
        ))
    }
}

struct Entry {
    name: TensorName,
    dtype: u32,
    rank: u32,
    dims: [u32; 2],
    extra_dims: [u32; 2],
    offset: u64,
    nbytes: u64,
    reserved: u64,
}

// Entry layout: name [u8;24] | dtype u32 | rank u32 | dims [u32;4] | offset u64 | nbytes u64.
// The fourth dims slot doubles as reserved space: rank ≤ 2 is all version 1 writes.
fn entry(table: &[u8], i: usize) -> Entry {
    let e = &table[i * TENSOR_ENTRY_LEN..(i + 1) * TENSOR_ENTRY_LEN];
    let mut name = [0; 24];
    name.copy_from_slice(&e[..24]);
    Entry {
        name: TensorName(name),
        dtype: le_u32(e, 24),
        rank: le_u32(e, 28),
        dims: [le_u32(e, 32), le_u32(e, 36)],
        extra_dims: [le_u32(e, 40), le_u32(e, 44)],
        offset: le_u64(e, 48),
        nbytes: le_u64(e, 56),
        reserved: 0,
    }
}

/// Which linear layer of a network.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LayerName {
    /// Hidden layer `i`.
    Hidden(usize),
    /// The output layer.
    Out,
}

/// `"{net}.l{i}.{kind}"` or `"{net}.out.{kind}"`, e.g. `skin.l2.weight`.
pub(crate) fn tensor_name(net: Net, layer: LayerName, kind: &str) -> TensorName {
    let mut buf = [0u8; 24];
    let mut n = 0;
    let mut push = |s: &[u8]| {
        for &b in s {
            if n < 24 {
                buf[n] = b;
                n += 1;
            }
        }
    };
    push(net.prefix().as_bytes());
    match layer {
        LayerName::Hidden(i) => {
            push(b".l");
            push(&[b'0' + (i % 10) as u8]);
        }
        LayerName::Out => push(b".out"),
    }
    push(b".");
    push(kind.as_bytes());
    TensorName(buf)
}
