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
//! Per frame ([`FastFrame::update`]) SkinNet runs at the `N` nodes only; each node's change
//! of log-weight from the bind pose, `L_nj = ln w_nj(θ) − ln w_nj(bind)` (both floored at
//! [`LOG_WEIGHT_FLOOR`]), is interpolated to the vertices and applied to their exact base:
//!
//! ```text
//! w_vj(θ) ∝ B_vj · exp(Σ_i a_vi · L_{n_i, j})      over the vertex's base joints, summing to one
//! ```
//!
//! The exact spatial detail of the bind pose times the interpolated pose-dependent change. As a
//! softmax's log-normaliser is common to all joints of a point and cancels on renormalising, this
//! interpolates SkinNet's *logit* changes, which are smooth over the surface; the weights are
//! positive by construction. (The additive form `B_v + Σ a_vi (w_n − B_n)` this replaced carried
//! a node's shift of weight between two joints to vertices with little weight on the joint losing
//! it, and gave a third of the vertex-frames of a trained model a negative weight, up to −0.12,
//! which LBS turned into a 9.5 cm error; `docs/experiments/fast-path.md`.) A vertex costs
//! `neighbours × base_influences` multiply-adds, `base_influences` exponentials and as many matrix
//! blends, whatever the joint count. With `base_influences = 0` the vertex takes the convex
//! combination `Σ_i a_vi w_{n_i}(θ)` of its nodes' weights instead (blended as per-node matrices
//! for LBS). DQS keeps the [`FastSkinJob::influences`] strongest joints of `w_v`; [`TopKJob`]
//! writes the `K` strongest joints per vertex in engine layouts (u8/u16 indices,
//! unorm8/unorm16/f32 weights summing exactly to one) for an engine's own skinning shader. With
//! a base both select among the base joints only, so they too cost the base, not `J`.
//!
//! The defaults (128 nodes, 4 base influences) meet 10k vertices in ≤ 2 ms and 50k in ≤ 4 ms
//! per frame on one AVX2 core with no measurable loss on the built-in character; characters
//! whose weights change quickly over the surface (the zoo's Witch, CesiumMan) need more nodes
//! for the same accuracy: measure with `trainer eval --fast N`.

mod graph;
mod job;
mod mesh;
mod topk;

pub use job::{FastFrame, FastSkinJob, LOG_WEIGHT_FLOOR};
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
    /// Strongest bind-pose joints kept per vertex as the exact base, the joints its weights
    /// range over in every pose (0..=[`MAX_INFLUENCES`]; 0 interpolates the whole weights
    /// from the nodes, convexly; capped at the joint count).
    pub base_influences: usize,
    /// Distance used to pick and weight the neighbours.
    pub metric: NodeMetric,
    /// Distance-to-weight rule.
    pub interpolation: Interpolation,
}

impl FastOptions {
    /// The defaults (`docs/experiments/fast-path.md` has the measurements behind them).
    pub const DEFAULT: Self = Self {
        nodes: 128,
        neighbours: 4,
        base_influences: 4,
        metric: NodeMetric::AlongMesh,
        interpolation: Interpolation::EmbeddedGraph,
    };
}

impl Default for FastOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}
