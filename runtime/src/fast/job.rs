//! The fast path per frame: [`FastFrame`] (SkinNet at the nodes, residual weights and matrices,
//! once per frame) and [`FastSkinJob`] (skinning any vertex range), with no heap allocation.

use alloc::vec;
use alloc::vec::Vec;

use glam::{Mat4, Vec3, Vec4};
use skinfield_formats::MAX_JOINTS;

use super::mesh::FastMesh;
use super::topk::strongest_influences;
use super::{Influence, MAX_INFLUENCES};
use crate::error::RuntimeError;
use crate::frame::FrameState;
use crate::job::{Scratch, VertexOutputs, WeightsJob};
use crate::kernels::blend;
use crate::model::SkinNet;
use crate::skinning::{Method, dqs, lbs_normal, lbs_tangent};

/// Residual weights smaller than this are exactly zero (2⁻¹⁰⁰ ≈ 7.9e-31).
const RESIDUAL_FLUSH: f32 = 7.888_609e-31;

/// The nodes' state for one frame: SkinNet's weights at the nodes, their change from the
/// bind-pose base, and the residual skinning matrix of every node. Buffers are allocated once
/// by [`FastFrame::new`]; [`FastFrame::update`] never allocates.
#[derive(Clone, Debug)]
pub struct FastFrame {
    mesh_id: u64,
    joints: usize,
    /// `N × J`: SkinNet's weights at the nodes.
    node_weights: Vec<f32>,
    /// `N × J`: `w_n − B_n`.
    residuals: Vec<f32>,
    /// `N`: `R_n = Σ_j (w_nj − B_nj) M_j`.
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
            residuals: vec![0.0; n * j],
            node_matrices: vec![Mat4::ZERO; n],
            pose: 0,
        }
    }

    /// SkinNet at the nodes for `frame`'s pose, then the residual weights and matrices. The
    /// only per-frame MLP work of the fast path: `N` vertices, whatever the mesh size.
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
        let j = self.joints;
        let mats = frame.palette().matrices();
        let kernel = mesh.kernel();
        for (n, (&v, (w, r))) in mesh
            .node_vertices()
            .iter()
            .zip(
                self.node_weights
                    .chunks_exact(j)
                    .zip(self.residuals.chunks_exact_mut(j)),
            )
            .enumerate()
        {
            r.copy_from_slice(w);
            for b in mesh.base_of(v as usize) {
                r[b.index as usize] -= b.weight;
            }
            // Residuals below 2⁻¹⁰⁰ are zero: their products would be subnormal floats, which
            // cost a microcode assist per use on Intel cores (see `activation::EXP_TAIL`).
            for x in r.iter_mut() {
                if x.abs() < RESIDUAL_FLUSH {
                    *x = 0.0;
                }
            }
            let mut m = Mat4::ZERO;
            let nonzero = r.iter().enumerate().filter(|(_, x)| **x != 0.0);
            blend(kernel, &mut m, mats, nonzero.map(|(j, &x)| (j, x)));
            self.node_matrices[n] = m;
        }
        self.pose = frame.generation();
        Ok(())
    }

    /// SkinNet's weights at the nodes, `J` per node (node order of [`FastMesh::node_vertices`]).
    #[must_use]
    pub fn node_weights(&self) -> &[f32] {
        &self.node_weights
    }

    /// The nodes' residual weights `w_n − B_n`, `J` per node.
    #[must_use]
    pub fn residuals(&self) -> &[f32] {
        &self.residuals
    }

    /// The nodes' residual skinning matrices `R_n = Σ_j (w_nj − B_nj) M_j`.
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

    /// The interpolated weights `B_v + Σ_i a_vi (w_{n_i} − B_{n_i})` of vertex `v` into `out`
    /// (`J` floats).
    pub(crate) fn dense_weights(&self, mesh: &FastMesh, v: usize, out: &mut [f32]) {
        let j = self.joints;
        out.fill(0.0);
        for b in mesh.base_of(v) {
            out[b.index as usize] += b.weight;
        }
        for a in mesh.interp_of(v) {
            let n = a.index as usize;
            for (o, r) in out.iter_mut().zip(&self.residuals[n * j..(n + 1) * j]) {
                *o += a.weight * r;
            }
        }
    }
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
    /// LBS (exact blend of the interpolated weights, `base_influences + neighbours` matrices
    /// per vertex) or DQS (over the `influences` strongest joints).
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
        let (mesh, nodes) = (self.mesh, self.nodes);
        let j = mesh.joint_count();
        let palette = self.frame.palette();
        let (mats, dq) = (palette.matrices(), palette.dual_quats());
        let rest = mesh.rest_positions();
        let mut dense = [0.0f32; MAX_JOINTS];
        let dense = &mut dense[..j];
        let mut strongest = [Influence::default(); MAX_INFLUENCES];
        let strongest = &mut strongest[..self.influences];
        let kernel = mesh.kernel();
        let node_mats = nodes.node_matrices();
        for i in 0..self.out_positions.len() {
            let v = self.first_vertex + i;
            match self.method {
                Method::Lbs => {
                    // LBS is linear in the weights: the base joints' matrices plus the nodes'
                    // residual matrices give Σ_j w_vj M_j without forming w_v.
                    let mut m = Mat4::ZERO;
                    let base = mesh.base_of(v).iter();
                    blend(
                        kernel,
                        &mut m,
                        mats,
                        base.map(|b| (b.index as usize, b.weight)),
                    );
                    let interp = mesh.interp_of(v).iter();
                    blend(
                        kernel,
                        &mut m,
                        node_mats,
                        interp.map(|a| (a.index as usize, a.weight)),
                    );
                    self.out_positions[i] = m.transform_point3(rest[v]);
                    if let (Some(o), Some(r)) = (self.out_normals.as_deref_mut(), self.rest_normals)
                    {
                        o[i] = lbs_normal(&m, r[v]);
                    }
                    if let (Some(o), Some(r)) =
                        (self.out_tangents.as_deref_mut(), self.rest_tangents)
                    {
                        o[i] = lbs_tangent(&m, r[v]);
                    }
                }
                Method::Dqs => {
                    let n = self.rest_normals.map_or(Vec3::Y, |r| r[v]);
                    let t = self.rest_tangents.map_or(Vec4::X, |r| r[v]);
                    nodes.dense_weights(mesh, v, dense);
                    strongest_influences(dense, strongest);
                    let infl = strongest.iter().map(|e| (e.index as usize, e.weight));
                    let s = dqs(mats, dq, infl, rest[v], n, t);
                    self.out_positions[i] = s.position;
                    if let Some(o) = self.out_normals.as_deref_mut() {
                        o[i] = s.normal;
                    }
                    if let Some(o) = self.out_tangents.as_deref_mut() {
                        o[i] = s.tangent;
                    }
                }
            }
            if let Some(o) = self.out_weights.as_deref_mut() {
                nodes.dense_weights(mesh, v, &mut o[i * j..(i + 1) * j]);
            }
        }
        Ok(())
    }
}
