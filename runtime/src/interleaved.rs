//! Interleaved output: skinned positions, normals and tangents written straight into an
//! engine's vertex buffer (one vertex every `stride` bytes, each attribute at its offset), so
//! an engine does not keep a second, packed copy of the mesh and a copy loop per frame.
//!
//! The job runs the packed jobs ([`SkinJob`], [`FastSkinJob`], [`StaticSkinJob`]) over chunks
//! of [`CHUNK`] vertices into stack arrays and scatters each chunk into the buffer: one code
//! path for the maths, and chunks aligned to the MLP's tiles so no tile is evaluated twice.
//! Bytes of a vertex outside the written attributes (UVs, colours, padding) are left as they
//! are. Floats are written in native byte order, as a GPU upload or a CPU-side mesh expects.

use glam::{Vec3, Vec4};
use skinfield_formats::StaticSkin;

use crate::bind::BoundMesh;
use crate::error::RuntimeError;
use crate::fast::{FastFrame, FastMesh, FastSkinJob};
use crate::frame::{FrameState, Palette};
use crate::job::{Scratch, SkinJob};
use crate::kernels::TILE;
use crate::model::SkinNet;
use crate::skinning::Method;
use crate::static_job::StaticSkinJob;

/// Vertices skinned per chunk (a multiple of the MLP tile, so chunks never split a tile).
pub const CHUNK: usize = 2 * TILE;

/// Bytes of a position or normal (3 × f32).
const VEC3_BYTES: usize = 12;
/// Bytes of a tangent (4 × f32, `w` = handedness).
const VEC4_BYTES: usize = 16;

/// Where each skinned attribute goes inside one vertex of an interleaved buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VertexLayout {
    /// Bytes from one vertex to the next.
    pub stride: usize,
    /// Byte offset of the position (3 × f32).
    pub position: usize,
    /// Byte offset of the unit normal (3 × f32), if the buffer has one.
    pub normal: Option<usize>,
    /// Byte offset of the unit tangent (4 × f32, `w` = handedness), if the buffer has one.
    pub tangent: Option<usize>,
}

impl VertexLayout {
    /// Positions only, packed (`stride` 12).
    pub const POSITIONS: Self = Self {
        stride: VEC3_BYTES,
        position: 0,
        normal: None,
        tangent: None,
    };

    /// Position, normal and tangent back to back (`stride` 40, offsets 0, 12, 24).
    pub const POSITION_NORMAL_TANGENT: Self = Self {
        stride: 2 * VEC3_BYTES + VEC4_BYTES,
        position: 0,
        normal: Some(VEC3_BYTES),
        tangent: Some(2 * VEC3_BYTES),
    };

    /// The attributes written, with their names and sizes.
    fn attributes(&self) -> [(&'static str, Option<usize>, usize); 3] {
        [
            ("position", Some(self.position), VEC3_BYTES),
            ("normal", self.normal, VEC3_BYTES),
            ("tangent", self.tangent, VEC4_BYTES),
        ]
    }

    /// Checks that every attribute lies inside the stride and that no two overlap.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        if self.stride < VEC3_BYTES {
            return Err(RuntimeError::Layout {
                field: "stride",
                offset: self.stride,
                size: VEC3_BYTES,
                problem: "is smaller than a position",
            });
        }
        let attrs = self.attributes();
        for (i, &(field, offset, size)) in attrs.iter().enumerate() {
            let Some(offset) = offset else { continue };
            if offset.checked_add(size).is_none_or(|end| end > self.stride) {
                return Err(RuntimeError::Layout {
                    field,
                    offset,
                    size,
                    problem: "runs past the stride",
                });
            }
            for &(_, other, other_size) in &attrs[..i] {
                if let Some(o) = other
                    && offset < o + other_size
                    && o < offset + size
                {
                    return Err(RuntimeError::Layout {
                        field,
                        offset,
                        size,
                        problem: "overlaps another attribute",
                    });
                }
            }
        }
        Ok(())
    }

    /// Bytes a buffer needs for `count` vertices: every vertex but the last takes `stride`, the
    /// last only up to the end of its last attribute. `None` on overflow.
    #[must_use]
    pub fn buffer_len(&self, count: usize) -> Option<usize> {
        if count == 0 {
            return Some(0);
        }
        let end = self
            .attributes()
            .iter()
            .filter_map(|&(_, offset, size)| offset.map(|o| o.saturating_add(size)))
            .max()
            .unwrap_or(0);
        (count - 1).checked_mul(self.stride)?.checked_add(end)
    }
}

/// Which weights skin the vertices.
pub enum WeightSource<'a, W> {
    /// SkinNet evaluated at every vertex ([`SkinJob`]).
    Exact {
        /// The expanded model.
        model: &'a SkinNet<W>,
        /// The mesh bound to it.
        mesh: &'a BoundMesh,
        /// The posed frame.
        frame: &'a FrameState,
        /// Working memory of the tile MLP.
        scratch: &'a mut Scratch,
    },
    /// SkinNet at the fast path's nodes, interpolated ([`FastSkinJob`]).
    Fast {
        /// The mesh bound for the fast path.
        mesh: &'a FastMesh,
        /// The posed frame.
        frame: &'a FrameState,
        /// The nodes, updated for `frame`'s pose.
        nodes: &'a FastFrame,
        /// Joints kept per vertex by DQS ([`FastSkinJob::influences`]).
        influences: usize,
    },
    /// Static weights ([`StaticSkinJob`]).
    Static {
        /// Sparse weights.
        skin: &'a StaticSkin,
        /// The posed joints.
        palette: &'a Palette,
        /// Rest positions of the whole mesh.
        rest_positions: &'a [Vec3],
    },
}

/// Skins `count` vertices from `first_vertex` into an interleaved buffer.
pub struct InterleavedJob<'a, W> {
    /// The weights.
    pub source: WeightSource<'a, W>,
    /// LBS or DQS.
    pub method: Method,
    /// First vertex of the range.
    pub first_vertex: usize,
    /// Number of vertices of the range.
    pub count: usize,
    /// Rest normals of the whole mesh (required when `layout.normal` is set).
    pub rest_normals: Option<&'a [Vec3]>,
    /// Rest tangents of the whole mesh (required when `layout.tangent` is set).
    pub rest_tangents: Option<&'a [Vec4]>,
    /// Where each attribute goes.
    pub layout: VertexLayout,
    /// The buffer, starting at vertex `first_vertex`: at least
    /// [`VertexLayout::buffer_len`]`(count)` bytes.
    pub out: &'a mut [u8],
}

impl<W: AsRef<[f32]>> InterleavedJob<'_, W> {
    /// Checks every field; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        self.layout.validate()?;
        let need = self
            .layout
            .buffer_len(self.count)
            .ok_or(RuntimeError::VertexCount(self.count))?;
        if self.out.len() < need {
            return Err(RuntimeError::BufferLength {
                field: "out",
                len: self.out.len(),
                expected: need,
            });
        }
        if self.layout.normal.is_some() && self.rest_normals.is_none() {
            return Err(RuntimeError::Missing {
                field: "rest_normals",
                because: "layout.normal",
            });
        }
        if self.layout.tangent.is_some() && self.rest_tangents.is_none() {
            return Err(RuntimeError::Missing {
                field: "rest_tangents",
                because: "layout.tangent",
            });
        }
        let vertex_count = match &self.source {
            WeightSource::Exact { mesh, .. } => mesh.vertex_count(),
            WeightSource::Fast { mesh, .. } => mesh.vertex_count(),
            WeightSource::Static { rest_positions, .. } => rest_positions.len(),
        };
        let end = self
            .first_vertex
            .checked_add(self.count)
            .filter(|&end| end <= vertex_count)
            .ok_or(RuntimeError::Range {
                first: self.first_vertex,
                count: self.count,
                vertex_count,
            })?;
        // The packed job over the empty range at the end of ours checks the parts and the rest
        // attributes' lengths without any output memory.
        let (mut p, mut n, mut t) = ([], [], []);
        let outs = Outputs {
            positions: &mut p,
            normals: self.rest_normals.map(|_| &mut n[..]),
            tangents: self.rest_tangents.map(|_| &mut t[..]),
        };
        match self.packed(end, outs) {
            Packed::Exact(job) => job.validate(),
            Packed::Fast(job) => job.validate(),
            Packed::Static(job) => job.validate(),
        }
    }

    /// Validates, then skins the range chunk by chunk. Never allocates.
    pub fn run(&mut self) -> Result<(), RuntimeError> {
        self.validate()?;
        let layout = self.layout;
        let (first, end) = (self.first_vertex, self.first_vertex + self.count);
        let mut positions = [Vec3::ZERO; CHUNK];
        let mut normals = [Vec3::ZERO; CHUNK];
        let mut tangents = [Vec4::ZERO; CHUNK];
        let mut start = first;
        while start < end {
            // Chunks end on multiples of CHUNK, so the MLP's tiles are never split.
            let stop = end.min((start / CHUNK + 1) * CHUNK);
            let len = stop - start;
            let outs = Outputs {
                positions: &mut positions[..len],
                normals: layout.normal.map(|_| &mut normals[..len]),
                tangents: layout.tangent.map(|_| &mut tangents[..len]),
            };
            self.skin_chunk(start, outs)?;
            let base = (start - first) * layout.stride;
            for i in 0..len {
                let at = base + i * layout.stride;
                put(self.out, at + layout.position, &positions[i].to_array());
                if let Some(o) = layout.normal {
                    put(self.out, at + o, &normals[i].to_array());
                }
                if let Some(o) = layout.tangent {
                    put(self.out, at + o, &tangents[i].to_array());
                }
            }
            start = stop;
        }
        Ok(())
    }

    fn skin_chunk(&mut self, first_vertex: usize, outs: Outputs<'_>) -> Result<(), RuntimeError> {
        match self.packed(first_vertex, outs) {
            Packed::Exact(mut job) => match &mut self.source {
                WeightSource::Exact { scratch, .. } => job.run(scratch),
                // `packed` makes an exact job only from an exact source.
                _ => Err(RuntimeError::Mismatch { field: "source" }),
            },
            Packed::Fast(mut job) => job.run(),
            Packed::Static(mut job) => job.run(),
        }
    }
}

impl<'a, W> InterleavedJob<'a, W> {
    /// The packed job of the source over `outs.positions.len()` vertices from `first_vertex`:
    /// the one place this job's fields become a packed job's, for validation and for each
    /// chunk. It borrows the source's references, not `self`, so the exact path's scratch can
    /// still be borrowed mutably to run it.
    fn packed<'j>(&self, first_vertex: usize, outs: Outputs<'j>) -> Packed<'j, W>
    where
        'a: 'j,
    {
        let (method, rest_normals, rest_tangents) =
            (self.method, self.rest_normals, self.rest_tangents);
        match &self.source {
            WeightSource::Exact {
                model, mesh, frame, ..
            } => Packed::Exact(SkinJob {
                model: *model,
                mesh,
                frame,
                method,
                first_vertex,
                rest_normals,
                rest_tangents,
                out_positions: outs.positions,
                out_normals: outs.normals,
                out_tangents: outs.tangents,
                out_weights: None,
            }),
            WeightSource::Fast {
                mesh,
                frame,
                nodes,
                influences,
            } => Packed::Fast(FastSkinJob {
                mesh,
                frame,
                nodes,
                method,
                influences: *influences,
                first_vertex,
                rest_normals,
                rest_tangents,
                out_positions: outs.positions,
                out_normals: outs.normals,
                out_tangents: outs.tangents,
                out_weights: None,
            }),
            WeightSource::Static {
                skin,
                palette,
                rest_positions,
            } => Packed::Static(StaticSkinJob {
                skin,
                palette,
                method,
                first_vertex,
                rest_positions,
                rest_normals,
                rest_tangents,
                out_positions: outs.positions,
                out_normals: outs.normals,
                out_tangents: outs.tangents,
            }),
        }
    }
}

/// A packed job over one chunk (or, for validation, an empty range).
enum Packed<'j, W> {
    Exact(SkinJob<'j, W>),
    Fast(FastSkinJob<'j>),
    Static(StaticSkinJob<'j>),
}

/// The packed outputs of one chunk.
struct Outputs<'c> {
    positions: &'c mut [Vec3],
    normals: Option<&'c mut [Vec3]>,
    tangents: Option<&'c mut [Vec4]>,
}

/// Writes `values` as native-endian f32 at byte `at` (in bounds: checked by `validate`).
fn put(out: &mut [u8], at: usize, values: &[f32]) {
    for (k, v) in values.iter().enumerate() {
        out[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_ne_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_that_do_not_fit_are_named() {
        VertexLayout::POSITIONS.validate().unwrap();
        VertexLayout::POSITION_NORMAL_TANGENT.validate().unwrap();
        let base = VertexLayout {
            stride: 48,
            position: 0,
            normal: Some(12),
            tangent: Some(32),
        };
        base.validate().unwrap();
        let cases = [
            (
                VertexLayout { stride: 8, ..base },
                "stride",
                "is smaller than a position",
            ),
            (
                VertexLayout {
                    position: 40,
                    ..base
                },
                "position",
                "runs past the stride",
            ),
            (
                VertexLayout {
                    normal: Some(8),
                    ..base
                },
                "normal",
                "overlaps another attribute",
            ),
            (
                VertexLayout {
                    tangent: Some(20),
                    ..base
                },
                "tangent",
                "overlaps another attribute",
            ),
            (
                VertexLayout {
                    tangent: Some(usize::MAX - 4),
                    ..base
                },
                "tangent",
                "runs past the stride",
            ),
        ];
        for (layout, name, why) in cases {
            match layout.validate() {
                Err(RuntimeError::Layout { field, problem, .. }) => {
                    assert_eq!((field, problem), (name, why), "{layout:?}");
                }
                other => panic!("{layout:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn buffer_len_ends_at_the_last_attribute() {
        let l = VertexLayout {
            stride: 64,
            position: 8,
            normal: Some(24),
            tangent: None,
        };
        assert_eq!(l.buffer_len(0), Some(0));
        assert_eq!(l.buffer_len(1), Some(36));
        assert_eq!(l.buffer_len(3), Some(2 * 64 + 36));
        assert_eq!(l.buffer_len(usize::MAX), None);
    }
}
