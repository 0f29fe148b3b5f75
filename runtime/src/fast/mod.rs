//! The fast path: pose-dependent skinning whose per-frame MLP cost does not grow with the mesh
//! (`docs/experiments/fast-path.md` has the design comparison and the measurements).
//!
//! SkinNet is a smooth field over canonical space. At bind time ([`FastMesh::bind`]):
//!
//! - **nodes**: `N` mesh vertices chosen by farthest-point sampling along the mesh;
//! - **base weights** `B_v`: SkinNet's exact weights of every vertex in the bind pose, kept to
//!   its [`FastOptions::base_influences`] strongest joints and renormalised;
//! - **interpolation**: every vertex's [`FastOptions::neighbours`] nearest nodes *along the
//!   mesh* (so a skirt never borrows from the leg it touches, an arm never from the torso) and
//!   convex weights `a_vi` from their distances.
//!
//! Per frame ([`FastFrame::update`]) SkinNet runs at the `N` nodes only, and each vertex gets
//!
//! ```text
//! w_v(θ) = B_v + Σ_i a_vi · (w_{n_i}(θ) − B_{n_i})
//! ```
//!
//! the exact spatial detail of the bind pose plus the interpolated pose-dependent change (both
//! terms sum to one, so `w_v` does). Because LBS is linear in the weights, [`FastSkinJob`] never
//! forms `w_v`: it blends the vertex's base joints' matrices with per-node residual matrices
//! `R_n = Σ_j (w_nj − B_nj) M_j` computed once per frame, so a vertex costs
//! `base_influences + neighbours` matrix blends whatever the joint count. DQS, which is not
//! linear, forms `w_v` and keeps its [`FastSkinJob::influences`] strongest joints.
//! [`TopKJob`] writes the `K` strongest joints per vertex in engine layouts (u8/u16 indices,
//! unorm8/unorm16/f32 weights summing exactly to one) for an engine's own skinning shader.

mod graph;
mod job;
mod mesh;
mod topk;

pub use job::{FastFrame, FastSkinJob};
pub use mesh::{BindStats, FastMesh};
pub use topk::{
    TopKIndices, TopKJob, TopKWeights, quantise_largest_remainder, strongest_influences,
};

/// Most joints per vertex [`FastSkinJob`] (DQS) and [`TopKJob`] keep, and most base
/// influences and neighbours per vertex.
pub const MAX_INFLUENCES: usize = 8;

/// A weighted reference: a joint (base weights, top-k) or a node (interpolation) and its weight.
/// The layout (8 bytes, `repr(C)`) is also the GPU's.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Influence {
    /// Joint or node index.
    pub index: u32,
    /// Its weight.
    pub weight: f32,
}

/// How distances between a vertex and the nodes are measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum NodeMetric {
    /// Shortest paths along the (welded) mesh edges: nodes never leak across surfaces that
    /// touch in the rest pose. Vertices in a component without a node fall back to
    /// [`NodeMetric::Euclidean`].
    #[default]
    AlongMesh,
    /// Straight-line distance in the rest pose (for comparison: leaks between touching parts).
    Euclidean,
}

/// How a vertex's distances to its nodes become interpolation weights.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Interpolation {
    /// `(1 − d_i / d_{k+1})²`, normalised (the embedded deformation graph's weights, Sumner et
    /// al. 2007, as in DeepCap): a node's weight falls to zero as it leaves a vertex's `k`
    /// nearest, so the interpolated field is continuous over the mesh.
    #[default]
    EmbeddedGraph,
    /// `1 / d_i²`, normalised (Shepard): exact at the nodes, but a step wherever the `k`
    /// nearest change.
    InverseDistance,
}

/// Bind-time settings of the fast path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FastOptions {
    /// Nodes at which SkinNet runs per frame (capped at the welded vertex count).
    pub nodes: usize,
    /// Nodes each vertex interpolates from (1..=[`MAX_INFLUENCES`]).
    pub neighbours: usize,
    /// Strongest bind-pose joints kept per vertex as the exact base (0..=[`MAX_INFLUENCES`];
    /// 0 interpolates the whole weights from the nodes; capped at the joint count).
    pub base_influences: usize,
    /// Distance used to pick and weight the neighbours.
    pub metric: NodeMetric,
    /// Distance-to-weight rule.
    pub interpolation: Interpolation,
}

impl FastOptions {
    /// The defaults (`docs/experiments/fast-path.md` has the measurements behind them).
    pub const DEFAULT: Self = Self {
        nodes: 256,
        neighbours: 4,
        base_influences: 8,
        metric: NodeMetric::AlongMesh,
        interpolation: Interpolation::EmbeddedGraph,
    };
}

impl Default for FastOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}
