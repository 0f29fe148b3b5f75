//! The per-frame SkinNet jobs (ozz style): a struct of caller-owned slices, [`SkinJob::validate`]
//! that names the first wrong field, and [`SkinJob::run`] over any vertex range, with no heap
//! allocation.

use alloc::vec;
use alloc::vec::Vec;

use glam::{Vec3, Vec4};

use crate::bind::BoundMesh;
use crate::error::RuntimeError;
use crate::frame::FrameState;
use crate::kernels::TILE;
use crate::model::SkinNet;
use crate::skinning::{Method, dqs, lbs};

/// Per-thread working memory for the tile MLP: two activation buffers, 64-byte aligned (not
/// `Clone`: a copy would lose the alignment; make another with [`Scratch::new`]).
#[derive(Debug)]
pub struct Scratch {
    buf: Vec<f32>,
    offset: usize,
    each: usize,
}

/// Floats per 64-byte line.
const LINE: usize = 16;

impl Scratch {
    /// Scratch for `model` (allocates once; reusable for any model of the same or smaller
    /// widths).
    #[must_use]
    pub fn new<W: AsRef<[f32]>>(model: &SkinNet<W>) -> Self {
        let each = model.layout().max_rows_p * TILE;
        let buf = vec![0.0f32; 2 * each + LINE];
        let misalign = (buf.as_ptr() as usize / 4) % LINE;
        let offset = (LINE - misalign) % LINE;
        Self { buf, offset, each }
    }

    fn buffers(&mut self, need: usize) -> Result<(&mut [f32], &mut [f32]), RuntimeError> {
        if need > self.each {
            return Err(RuntimeError::BufferLength {
                field: "scratch",
                len: self.each,
                expected: need,
            });
        }
        let (a, b) = self.buf[self.offset..self.offset + 2 * self.each].split_at_mut(self.each);
        Ok((a, b))
    }
}

/// Checks model, mesh and frame belong together and the range fits; returns the count.
fn check_parts<W: AsRef<[f32]>>(
    model: &SkinNet<W>,
    mesh: &BoundMesh,
    frame: &FrameState,
    first: usize,
    count: usize,
) -> Result<(), RuntimeError> {
    if mesh.model_id() != model.id() {
        return Err(RuntimeError::Mismatch { field: "mesh" });
    }
    if frame.model_id() != model.id() {
        return Err(RuntimeError::Mismatch { field: "frame" });
    }
    if !frame.is_ready() {
        return Err(RuntimeError::NoPose);
    }
    let n = mesh.vertex_count();
    if first.checked_add(count).is_none_or(|end| end > n) {
        return Err(RuntimeError::Range {
            first,
            count,
            vertex_count: n,
        });
    }
    Ok(())
}

/// Checks an optional output against its rest input: `out` needs `rest` (full mesh) and is
/// `count` long.
pub(crate) fn check_attr<A, B>(
    rest: Option<&[A]>,
    out: Option<&[B]>,
    names: (&'static str, &'static str),
    vertices: usize,
    count: usize,
) -> Result<(), RuntimeError> {
    if let Some(r) = rest
        && r.len() != vertices
    {
        return Err(RuntimeError::BufferLength {
            field: names.0,
            len: r.len(),
            expected: vertices,
        });
    }
    if let Some(o) = out {
        if rest.is_none() {
            return Err(RuntimeError::Missing {
                field: names.0,
                because: names.1,
            });
        }
        if o.len() != count {
            return Err(RuntimeError::BufferLength {
                field: names.1,
                len: o.len(),
                expected: count,
            });
        }
    }
    Ok(())
}

/// The optional per-vertex attributes every skinning job validates the same way: each output
/// needs its rest input, rest inputs cover the mesh (`vertices`), outputs the range (`count`),
/// and `out_weights` holds `joints` weights per vertex of the range.
pub(crate) struct VertexOutputs<'s> {
    pub(crate) rest_normals: Option<&'s [Vec3]>,
    pub(crate) out_normals: Option<&'s [Vec3]>,
    pub(crate) rest_tangents: Option<&'s [Vec4]>,
    pub(crate) out_tangents: Option<&'s [Vec4]>,
    pub(crate) out_weights: Option<&'s [f32]>,
}

impl VertexOutputs<'_> {
    /// Checks the attributes; the error names the first wrong field.
    pub(crate) fn check(
        &self,
        vertices: usize,
        count: usize,
        joints: usize,
    ) -> Result<(), RuntimeError> {
        check_attr(
            self.rest_normals,
            self.out_normals,
            ("rest_normals", "out_normals"),
            vertices,
            count,
        )?;
        check_attr(
            self.rest_tangents,
            self.out_tangents,
            ("rest_tangents", "out_tangents"),
            vertices,
            count,
        )?;
        if let Some(w) = self.out_weights {
            let expected = count * joints;
            if w.len() != expected {
                return Err(RuntimeError::BufferLength {
                    field: "out_weights",
                    len: w.len(),
                    expected,
                });
            }
        }
        Ok(())
    }
}

/// Skins `out_positions.len()` vertices starting at `first_vertex` with SkinNet weights.
pub struct SkinJob<'a, W> {
    /// The expanded model.
    pub model: &'a SkinNet<W>,
    /// The mesh bound to it.
    pub mesh: &'a BoundMesh,
    /// The posed frame.
    pub frame: &'a FrameState,
    /// LBS or DQS.
    pub method: Method,
    /// First vertex of the range.
    pub first_vertex: usize,
    /// Rest normals of the whole mesh (required for `out_normals`).
    pub rest_normals: Option<&'a [Vec3]>,
    /// Rest tangents of the whole mesh, `w` = handedness (required for `out_tangents`).
    pub rest_tangents: Option<&'a [Vec4]>,
    /// Skinned positions of the range (its length is the range's length).
    pub out_positions: &'a mut [Vec3],
    /// Skinned unit normals of the range.
    pub out_normals: Option<&'a mut [Vec3]>,
    /// Skinned unit tangents of the range (handedness copied).
    pub out_tangents: Option<&'a mut [Vec4]>,
    /// The SkinNet weights of the range, `J` per vertex.
    pub out_weights: Option<&'a mut [f32]>,
}

impl<W: AsRef<[f32]>> SkinJob<'_, W> {
    /// Checks every field; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        let count = self.out_positions.len();
        check_parts(self.model, self.mesh, self.frame, self.first_vertex, count)?;
        VertexOutputs {
            rest_normals: self.rest_normals,
            out_normals: self.out_normals.as_deref(),
            rest_tangents: self.rest_tangents,
            out_tangents: self.out_tangents.as_deref(),
            out_weights: self.out_weights.as_deref(),
        }
        .check(self.mesh.vertex_count(), count, self.model.joint_count())
    }

    /// Validates, then skins the range. Never allocates.
    pub fn run(&mut self, scratch: &mut Scratch) -> Result<(), RuntimeError> {
        self.validate()?;
        let count = self.out_positions.len();
        if count == 0 {
            return Ok(());
        }
        let model = self.model;
        let j_count = model.joint_count();
        let (a, b) = scratch.buffers(model.layout().max_rows_p * TILE)?;
        let palette = self.frame.palette();
        let (mats, dq) = (palette.matrices(), palette.dual_quats());
        let rest = self.mesh.rest_positions();
        let (first, end) = (self.first_vertex, self.first_vertex + count);
        for t in first / TILE..=(end - 1) / TILE {
            let w = model.forward_tile(
                self.mesh.tile(t),
                self.frame.frame_bias(),
                self.mesh.tile_candidates(t),
                a,
                b,
            );
            for v in first.max(t * TILE)..end.min((t + 1) * TILE) {
                let (lane, i) = (v - t * TILE, v - first);
                let infl = (0..j_count).map(|j| (j, w[j * TILE + lane]));
                let n = self.rest_normals.map_or(Vec3::Y, |r| r[v]);
                let tg = self.rest_tangents.map_or(Vec4::X, |r| r[v]);
                let s = match self.method {
                    Method::Lbs => lbs(mats, infl.clone(), rest[v], n, tg),
                    Method::Dqs => dqs(mats, dq, infl.clone(), rest[v], n, tg),
                };
                self.out_positions[i] = s.position;
                if let Some(o) = self.out_normals.as_deref_mut() {
                    o[i] = s.normal;
                }
                if let Some(o) = self.out_tangents.as_deref_mut() {
                    o[i] = s.tangent;
                }
                if let Some(o) = self.out_weights.as_deref_mut() {
                    for (dst, (_, wj)) in o[i * j_count..(i + 1) * j_count].iter_mut().zip(infl) {
                        *dst = wj;
                    }
                }
            }
        }
        Ok(())
    }
}

impl<'a, W> SkinJob<'a, W> {
    /// Splits the job after `at` vertices of its range (outputs split alike), so the halves can
    /// run on different threads; `None` when `at` exceeds the range.
    #[must_use]
    pub fn split_at(self, at: usize) -> Option<(Self, Self)> {
        if at > self.out_positions.len() {
            return None;
        }
        let j = if let Some(w) = &self.out_weights {
            w.len().checked_div(self.out_positions.len()).unwrap_or(0)
        } else {
            0
        };
        if self.out_normals.as_ref().is_some_and(|o| o.len() < at)
            || self.out_tangents.as_ref().is_some_and(|o| o.len() < at)
            || self.out_weights.as_ref().is_some_and(|o| o.len() < at * j)
        {
            return None;
        }
        let (p0, p1) = self.out_positions.split_at_mut(at);
        let (n0, n1) = split_opt(self.out_normals, at);
        let (t0, t1) = split_opt(self.out_tangents, at);
        let (w0, w1) = split_opt(self.out_weights, at * j);
        let (model, mesh, frame, method) = (self.model, self.mesh, self.frame, self.method);
        let (rest_normals, rest_tangents, first_vertex) =
            (self.rest_normals, self.rest_tangents, self.first_vertex);
        let head = SkinJob {
            model,
            mesh,
            frame,
            method,
            first_vertex,
            rest_normals,
            rest_tangents,
            out_positions: p0,
            out_normals: n0,
            out_tangents: t0,
            out_weights: w0,
        };
        let tail = SkinJob {
            model,
            mesh,
            frame,
            method,
            first_vertex: first_vertex + at,
            rest_normals,
            rest_tangents,
            out_positions: p1,
            out_normals: n1,
            out_tangents: t1,
            out_weights: w1,
        };
        Some((head, tail))
    }
}

fn split_opt<T>(s: Option<&mut [T]>, at: usize) -> (Option<&mut [T]>, Option<&mut [T]>) {
    match s {
        Some(s) => {
            let (a, b) = s.split_at_mut(at);
            (Some(a), Some(b))
        }
        None => (None, None),
    }
}

/// Only the SkinNet weights of a vertex range (`out_weights.len() / J` vertices from
/// `first_vertex`): what an exporter or a GPU upload needs. Never allocates.
pub struct WeightsJob<'a, W> {
    /// The expanded model.
    pub model: &'a SkinNet<W>,
    /// The mesh bound to it.
    pub mesh: &'a BoundMesh,
    /// The posed frame.
    pub frame: &'a FrameState,
    /// First vertex of the range.
    pub first_vertex: usize,
    /// `J` weights per vertex, row-major.
    pub out_weights: &'a mut [f32],
}

impl<W: AsRef<[f32]>> WeightsJob<'_, W> {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        let j = self.model.joint_count();
        if !self.out_weights.len().is_multiple_of(j) {
            let expected = self.out_weights.len() / j * j;
            return Err(RuntimeError::BufferLength {
                field: "out_weights",
                len: self.out_weights.len(),
                expected,
            });
        }
        check_parts(
            self.model,
            self.mesh,
            self.frame,
            self.first_vertex,
            self.out_weights.len() / j,
        )
    }

    /// Validates, then evaluates the MLP over the range.
    pub fn run(&mut self, scratch: &mut Scratch) -> Result<(), RuntimeError> {
        self.validate()?;
        let j_count = self.model.joint_count();
        let count = self.out_weights.len() / j_count;
        if count == 0 {
            return Ok(());
        }
        let (a, b) = scratch.buffers(self.model.layout().max_rows_p * TILE)?;
        let (first, end) = (self.first_vertex, self.first_vertex + count);
        for t in first / TILE..=(end - 1) / TILE {
            let w = self.model.forward_tile(
                self.mesh.tile(t),
                self.frame.frame_bias(),
                self.mesh.tile_candidates(t),
                a,
                b,
            );
            for v in first.max(t * TILE)..end.min((t + 1) * TILE) {
                let (lane, i) = (v - t * TILE, v - first);
                for (j, dst) in self.out_weights[i * j_count..(i + 1) * j_count]
                    .iter_mut()
                    .enumerate()
                {
                    *dst = w[j * TILE + lane];
                }
            }
        }
        Ok(())
    }
}
