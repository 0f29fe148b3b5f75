//! The fast path per frame: [`FastFrame`] (SkinNet at the nodes and their log-weight changes, or
//! blended node matrices without a base, once per frame) and [`FastSkinJob`] (skinning any
//! vertex range), with no heap allocation.

use alloc::vec;
use alloc::vec::Vec;

use glam::{Mat4, Vec3, Vec4};
use skinfield_formats::MAX_JOINTS;

use super::mesh::FastMesh;
use super::topk::{strongest_influences, strongest_sparse};
use super::{Influence, MAX_INFLUENCES};

use crate::error::RuntimeError;
use crate::frame::FrameState;
use crate::job::{Scratch, VertexOutputs, WeightsJob};
use crate::kernels::{TILE, blend, softmax_tile, tiles};
use crate::model::SkinNet;
use crate::skinning::{
    DualQuat, Method, dqs, lbs_normal_unnormalised, lbs_point, lbs_tangent_unnormalised,
    normalise_block,
};

/// Node weights are floored here before their logarithm: a joint the node gives (almost) no
/// weight in the bind pose and in the frame keeps a change of zero instead of the ratio of two
/// rounding errors, and a weight that vanishes in the frame switches the joint off
/// (`ln 1e-12 ≈ −27.6`) without an infinity.
pub const LOG_WEIGHT_FLOOR: f32 = 1e-12;

/// Convex-mode node weights smaller than this are exactly zero (2⁻¹⁰⁰ ≈ 7.9e-31).
const RESIDUAL_FLUSH: f32 = 7.888_609e-31;

/// The nodes' state for one frame: SkinNet's weights at the nodes and what the vertices
/// interpolate from them (log-weight changes, or blended node matrices when there is no base).
/// Buffers are allocated once by [`FastFrame::new`]; [`FastFrame::update`] never allocates.
#[derive(Clone, Debug)]
pub struct FastFrame {
    mesh_id: u64,
    joints: usize,
    /// `N × J`: SkinNet's weights at the nodes.
    node_weights: Vec<f32>,
    /// `N × J`: `ln w_n(θ) − ln w_n(bind)` (both floored at [`LOG_WEIGHT_FLOOR`]); zero
    /// without a base.
    log_changes: Vec<f32>,
    /// `N`: `Σ_j w_nj M_j` without a base; zero with one.
    node_matrices: Vec<Mat4>,
    /// The pose (`FrameState` generation) it was computed for; 0 = none.
    pose: u64,
}

impl FastFrame {
    /// Buffers for `mesh` (allocates once).
    #[must_use]
    pub fn new(mesh: &FastMesh) -> Self {
        let (n, j) = (mesh.node_count(), mesh.joint_count());
        Self {
            mesh_id: mesh.id(),
            joints: j,
            node_weights: vec![0.0; n * j],
            log_changes: vec![0.0; n * j],
            node_matrices: vec![Mat4::ZERO; n],
            pose: 0,
        }
    }

    /// SkinNet at the nodes for `frame`'s pose, then the nodes' log-weight changes (or, without
    /// a base, their blended matrices). The only per-frame MLP work of the fast path: `N`
    /// vertices, whatever the mesh size.
    pub fn update<W: AsRef<[f32]>>(
        &mut self,
        model: &SkinNet<W>,
        mesh: &FastMesh,
        frame: &FrameState,
        scratch: &mut Scratch,
    ) -> Result<(), RuntimeError> {
        self.pose = 0;
        if mesh.model_id() != model.id() {
            return Err(RuntimeError::Mismatch { field: "mesh" });
        }
        if mesh.id() != self.mesh_id {
            return Err(RuntimeError::Mismatch { field: "nodes" });
        }
        WeightsJob {
            model,
            mesh: mesh.node_mesh(),
            frame,
            first_vertex: 0,
            out_weights: &mut self.node_weights,
        }
        .run(scratch)?;
        if mesh.options().base_influences > 0 {
            let rows = self.node_weights.iter().zip(mesh.node_bind_weights());
            for (l, (&w, &b)) in self.log_changes.iter_mut().zip(rows) {
                *l = log_floored(w) - log_floored(b);
            }
        } else {
            let mats = frame.palette().matrices();
            let kernel = mesh.kernel();
            let rows = self.node_weights.chunks_exact(self.joints);
            for (m, w) in self.node_matrices.iter_mut().zip(rows) {
                // Weights below 2⁻¹⁰⁰ are zero: their products would be subnormal floats,
                // which cost a microcode assist per use on Intel cores (see
                // `activation::EXP_TAIL`).
                let nonzero = w
                    .iter()
                    .enumerate()
                    .filter(|(_, x)| x.abs() >= RESIDUAL_FLUSH);
                *m = Mat4::ZERO;
                blend(kernel, m, mats, nonzero.map(|(j, &x)| (j, x)));
            }
        }
        self.pose = frame.generation();
        Ok(())
    }

    /// SkinNet's weights at the nodes, `J` per node (node order of [`FastMesh::node_vertices`]).
    #[must_use]
    pub fn node_weights(&self) -> &[f32] {
        &self.node_weights
    }

    /// The nodes' log-weight changes from the bind pose, `J` per node (zero without a base).
    #[must_use]
    pub fn log_changes(&self) -> &[f32] {
        &self.log_changes
    }

    /// The nodes' blended skinning matrices `Σ_j w_nj M_j` (used, and non-zero, only without a
    /// base).
    #[must_use]
    pub fn node_matrices(&self) -> &[Mat4] {
        &self.node_matrices
    }

    /// Whether the last [`FastFrame::update`] succeeded.
    #[must_use]
    pub fn is_ready(&self) -> bool {
        self.pose != 0
    }

    /// Checks that this state belongs to `mesh` and is current for `frame`.
    pub(crate) fn check(&self, mesh: &FastMesh, frame: &FrameState) -> Result<(), RuntimeError> {
        if self.mesh_id != mesh.id() {
            return Err(RuntimeError::Mismatch { field: "nodes" });
        }
        if frame.model_id() != mesh.model_id() {
            return Err(RuntimeError::Mismatch { field: "frame" });
        }
        if !frame.is_ready() {
            return Err(RuntimeError::NoPose);
        }
        if self.pose != frame.generation() {
            return Err(RuntimeError::Stale { field: "nodes" });
        }
        Ok(())
    }

    /// The weights of vertices `first .. first + len` (`len` ≤ [`TILE`]; requires a base) on
    /// their base joints, the interpolated log-weight changes applied to the bind-pose base and
    /// renormalised, `w_vb ∝ B_vb · exp(Σ_i a_vi · L_{n_i, j_b})`, into `tile`. One softmax over
    /// the tile's columns (the runtime's `softmax_tile`, with its tail rule: below e^-72 of the
    /// strongest is exactly zero, so no subnormal float reaches the matrix blends). Vertex by
    /// vertex, each softmax waited on its own horizontal maximum and sum, a latency chain the
    /// core could not overlap with the next vertex's work; across a tile the exponentials are
    /// independent vectors. Each column is computed on its own, so a vertex's weights do not
    /// depend on the tile it falls in.
    pub(crate) fn base_tile(&self, mesh: &FastMesh, first: usize, len: usize, tile: &mut BaseTile) {
        let rows = mesh.options().base_influences.min(MAX_INFLUENCES);
        for k in 0..TILE {
            let mut t = [f32::NEG_INFINITY; MAX_INFLUENCES];
            if k < len {
                self.base_logits(mesh, first + k, &mut t);
            } else {
                // A column past the range: one finite logit keeps its softmax finite.
                t[0] = 0.0;
            }
            for (b, &x) in t.iter().enumerate().take(rows) {
                tile.weights[b * TILE + k] = x;
            }
        }
        softmax_tile(mesh.kernel(), &mut tile.weights, rows);
        tile.first = first;
    }

    /// The logits of vertex `v`'s base weights before their softmax, `ln B_vb + Σ_i a_vi ·
    /// L_{n_i, j_b}`, into `t` in base order; slots past its base are left as they are (callers
    /// pass −∞: weight 0).
    #[inline]
    fn base_logits(&self, mesh: &FastMesh, v: usize, t: &mut [f32; MAX_INFLUENCES]) {
        let j = self.joints;
        let (base, base_log) = (mesh.base_of(v), mesh.base_log_of(v));
        let interp = mesh.interp_of(v);
        for ((tb, b), &lb) in t.iter_mut().zip(base).zip(base_log) {
            let joint = b.index as usize;
            let change: f32 = interp
                .iter()
                .map(|a| a.weight * self.log_changes[a.index as usize * j + joint])
                .sum();
            *tb = lb + change;
        }
    }

    /// The fast path's weights of vertex `v` without a base (the convex combination of its
    /// nodes' weights) into `out` (`J` floats, dense).
    pub(crate) fn convex_weights(&self, mesh: &FastMesh, v: usize, out: &mut [f32]) {
        let j = self.joints;
        out.fill(0.0);
        for a in mesh.interp_of(v) {
            let n = a.index as usize;
            for (o, w) in out.iter_mut().zip(&self.node_weights[n * j..(n + 1) * j]) {
                *o += a.weight * w;
            }
        }
    }
}

/// A tile of vertices' softmaxed base weights ([`FastFrame::base_tile`]).
pub(crate) struct BaseTile {
    /// `[base slot][TILE]`: slot `b` of the tile's vertex `k` at `b · TILE + k`.
    weights: [f32; MAX_INFLUENCES * TILE],
    /// The tile's first vertex.
    first: usize,
}

impl BaseTile {
    /// An empty tile (fill it with [`FastFrame::base_tile`]).
    pub(crate) fn new() -> Self {
        Self {
            weights: [0.0; MAX_INFLUENCES * TILE],
            first: 0,
        }
    }

    /// Vertex `v`'s `(joint, weight)` entries, in base order (`v` in the tile).
    #[inline]
    pub(crate) fn entries<'a>(
        &'a self,
        mesh: &'a FastMesh,
        v: usize,
    ) -> impl Iterator<Item = (usize, f32)> + Clone + 'a {
        let k = v - self.first;
        let base = mesh.base_of(v).iter().enumerate();
        base.map(move |(b, e)| (e.index as usize, self.weights[b * TILE + k]))
    }
}

/// Adds sparse `(joint, weight)` entries into dense weights `out`.
fn scatter(entries: impl Iterator<Item = (usize, f32)>, out: &mut [f32]) {
    for (joint, weight) in entries {
        out[joint] += weight;
    }
}

/// `ln max(w, LOG_WEIGHT_FLOOR)`.
fn log_floored(w: f32) -> f32 {
    libm::logf(w.max(LOG_WEIGHT_FLOOR))
}

/// Checks the range of a fast-path job against the mesh.
pub(crate) fn check_range(mesh: &FastMesh, first: usize, count: usize) -> Result<(), RuntimeError> {
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

/// Skins `out_positions.len()` vertices from `first_vertex` with the fast path's weights.
pub struct FastSkinJob<'a> {
    /// The mesh bound for the fast path.
    pub mesh: &'a FastMesh,
    /// The posed frame (joint palette).
    pub frame: &'a FrameState,
    /// The nodes, updated for `frame`'s pose.
    pub nodes: &'a FastFrame,
    /// LBS (exact blend of the interpolated weights: `base_influences` matrices per vertex, or
    /// `neighbours` node matrices without a base) or DQS (over the `influences` strongest
    /// joints).
    pub method: Method,
    /// Joints kept per vertex by DQS, 1..=[`MAX_INFLUENCES`] (renormalised); LBS ignores it.
    pub influences: usize,
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
    /// The interpolated (dense, `J` per vertex) weights of the range.
    pub out_weights: Option<&'a mut [f32]>,
}

impl FastSkinJob<'_> {
    /// Checks every field; the error names the first one that is wrong.
    pub fn validate(&self) -> Result<(), RuntimeError> {
        let count = self.out_positions.len();
        self.nodes.check(self.mesh, self.frame)?;
        check_range(self.mesh, self.first_vertex, count)?;
        if !(1..=MAX_INFLUENCES).contains(&self.influences) {
            return Err(RuntimeError::Setting {
                field: "influences",
                value: self.influences,
                min: 1,
                max: MAX_INFLUENCES,
            });
        }
        VertexOutputs {
            rest_normals: self.rest_normals,
            out_normals: self.out_normals.as_deref(),
            rest_tangents: self.rest_tangents,
            out_tangents: self.out_tangents.as_deref(),
            out_weights: self.out_weights.as_deref(),
        }
        .check(self.mesh.vertex_count(), count, self.mesh.joint_count())
    }

    /// Validates, then skins the range. Never allocates.
    pub fn run(&mut self) -> Result<(), RuntimeError> {
        self.validate()?;
        if self.mesh.options().base_influences > 0 {
            self.run_with_base();
        } else {
            self.run_convex();
        }
        Ok(())
    }

    /// Without a base: each vertex takes the convex combination of its nodes' weights.
    fn run_convex(&mut self) {
        let (mesh, nodes) = (self.mesh, self.nodes);
        let j = mesh.joint_count();
        let palette = self.frame.palette();
        let (mats, dq) = (palette.matrices(), palette.dual_quats());
        let mut dense = [0.0f32; MAX_JOINTS];
        let dense = &mut dense[..j];
        let mut strongest = [Influence::default(); MAX_INFLUENCES];
        let strongest = &mut strongest[..self.influences];
        let kernel = mesh.kernel();
        let node_mats = nodes.node_matrices();
        for (start, len) in tiles(self.out_positions.len()) {
            for i in start..start + len {
                let v = self.first_vertex + i;
                match self.method {
                    Method::Lbs => {
                        // LBS is linear in the convex node weights: the nodes' blended
                        // matrices give Σ_j w_vj M_j in `neighbours` blends.
                        let mut m = Mat4::ZERO;
                        let interp = mesh.interp_of(v).iter();
                        blend(
                            kernel,
                            &mut m,
                            node_mats,
                            interp.map(|a| (a.index as usize, a.weight)),
                        );
                        self.write_lbs(i, v, &m);
                    }
                    Method::Dqs => {
                        nodes.convex_weights(mesh, v, dense);
                        strongest_influences(dense, strongest);
                        let infl = strongest.iter().map(|e| (e.index as usize, e.weight));
                        self.write_dqs(i, v, mats, dq, infl);
                    }
                }
                if let Some(o) = self.out_weights.as_deref_mut() {
                    // What the branch above formed is written, not formed a second time.
                    let o = &mut o[i * j..(i + 1) * j];
                    match self.method {
                        Method::Dqs => o.copy_from_slice(dense),
                        Method::Lbs => nodes.convex_weights(mesh, v, o),
                    }
                }
            }
            if self.method == Method::Lbs {
                self.normalise_lbs(start..start + len);
            }
        }
    }

    /// With a base, [`TILE`] vertices at a time ([`FastFrame::base_tile`]): LBS blends the base
    /// joints' matrices; DQS keeps the `influences` strongest base joints, so a vertex costs its
    /// base, not the joint count.
    fn run_with_base(&mut self) {
        let (mesh, nodes) = (self.mesh, self.nodes);
        let j = mesh.joint_count();
        let palette = self.frame.palette();
        let (mats, dq) = (palette.matrices(), palette.dual_quats());
        let kernel = mesh.kernel();
        let mut strongest = [Influence::default(); MAX_INFLUENCES];
        let strongest = &mut strongest[..self.influences];
        let mut tile = BaseTile::new();
        for (start, len) in tiles(self.out_positions.len()) {
            nodes.base_tile(mesh, self.first_vertex + start, len, &mut tile);
            for i in start..start + len {
                let v = self.first_vertex + i;
                let weights = tile.entries(mesh, v);
                match self.method {
                    Method::Lbs => {
                        let mut m = Mat4::ZERO;
                        blend(kernel, &mut m, mats, weights.clone());
                        self.write_lbs(i, v, &m);
                    }
                    Method::Dqs => {
                        strongest_sparse(weights.clone(), j, strongest);
                        let infl = strongest.iter().map(|e| (e.index as usize, e.weight));
                        self.write_dqs(i, v, mats, dq, infl);
                    }
                }
                if let Some(o) = self.out_weights.as_deref_mut() {
                    let o = &mut o[i * j..(i + 1) * j];
                    o.fill(0.0);
                    scatter(weights, o);
                }
            }
            if self.method == Method::Lbs {
                self.normalise_lbs(start..start + len);
            }
        }
    }

    /// Output `i` of vertex `v` skinned by DQS over `infl`.
    fn write_dqs(
        &mut self,
        i: usize,
        v: usize,
        mats: &[Mat4],
        dq: &[DualQuat],
        infl: impl Iterator<Item = (usize, f32)> + Clone,
    ) {
        let n = self.rest_normals.map_or(Vec3::Y, |r| r[v]);
        let t = self.rest_tangents.map_or(Vec4::X, |r| r[v]);
        let s = dqs(mats, dq, infl, self.mesh.rest_positions()[v], n, t);
        self.out_positions[i] = s.position;
        if let Some(o) = self.out_normals.as_deref_mut() {
            o[i] = s.normal;
        }
        if let Some(o) = self.out_tangents.as_deref_mut() {
            o[i] = s.tangent;
        }
    }

    /// Output `i` of vertex `v` skinned with the blended matrix `m`: its position, and its
    /// normal and tangent where the job asks for them, left unnormalised for
    /// [`FastSkinJob::normalise_lbs`].
    #[inline]
    fn write_lbs(&mut self, i: usize, v: usize, m: &Mat4) {
        self.out_positions[i] = lbs_point(m, self.mesh.rest_positions()[v]);
        if let (Some(o), Some(r)) = (self.out_normals.as_deref_mut(), self.rest_normals) {
            o[i] = lbs_normal_unnormalised(m, r[v]);
        }
        if let (Some(o), Some(r)) = (self.out_tangents.as_deref_mut(), self.rest_tangents) {
            o[i] = lbs_tangent_unnormalised(m, r[v]);
        }
    }

    /// Normalises the normals and tangents [`FastSkinJob::write_lbs`] wrote to outputs
    /// `range`, a block at a time (`skinning::lbs_normal_unnormalised` says why).
    fn normalise_lbs(&mut self, range: core::ops::Range<usize>) {
        normalise_block(
            self.out_normals.as_deref_mut(),
            self.out_tangents.as_deref_mut(),
            range,
        );
    }
}
