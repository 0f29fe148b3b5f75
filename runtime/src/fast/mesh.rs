//! Binding a mesh for the fast path: nodes, per-vertex interpolation weights and bind-pose
//! base weights, all computed once.

use alloc::vec;
use alloc::vec::Vec;
use core::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3;

use super::graph::{
    MeshGraph, farthest_point_nodes, nearest_nodes_along_mesh, nearest_nodes_in_space,
};
use super::topk::strongest_influences;
use super::{FastOptions, Influence, Interpolation, MAX_INFLUENCES, NodeMetric};
use crate::bind::{BoundMesh, MAX_BIND_VERTICES};
use crate::error::RuntimeError;
use crate::frame::FrameState;
use crate::job::{Scratch, WeightsJob};
use crate::kernels::Kernel;
use crate::model::SkinNet;

static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// Vertices per SkinNet batch when the bind-pose weights are computed (bounds the memory of
/// that step to `BASE_CHUNK × J` floats).
const BASE_CHUNK: usize = 4096;

/// Interpolation weights below this fraction of the nearest node's are dropped.
const INTERPOLATION_FLUSH: f32 = 1e-6;

/// What binding found, for reports and checks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BindStats {
    /// Vertices after welding bitwise-equal positions.
    pub welded_vertices: usize,
    /// Vertices in a component without a node, interpolated by straight-line distance instead.
    pub euclidean_fallback_vertices: usize,
}

/// A mesh bound for the fast path (see the [module docs](super)).
#[derive(Clone, Debug)]
pub struct FastMesh {
    model_id: u64,
    id: u64,
    joints: usize,
    kernel: Kernel,
    rest: Vec<Vec3>,
    options: FastOptions,
    node_vertices: Vec<u32>,
    node_mesh: BoundMesh,
    /// `vertices × neighbours`: node index and interpolation weight (unused slots weigh 0).
    interp: Vec<Influence>,
    /// `vertices × base_influences`: joint and bind-pose weight.
    base: Vec<Influence>,
    /// `vertices × base_influences`: `ln` of each base weight (−∞ for an empty slot), so a frame
    /// costs one `exp` per base joint and no `ln`.
    base_log: Vec<f32>,
    /// `nodes × J`: SkinNet's exact (dense) bind-pose weights at the nodes, the reference of
    /// the nodes' log-weight changes.
    node_bind: Vec<f32>,
    stats: BindStats,
}

fn setting(field: &'static str, value: usize, min: usize, max: usize) -> Result<(), RuntimeError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(RuntimeError::Setting {
            field,
            value,
            min,
            max,
        })
    }
}

/// Interpolation weights of one vertex from its nearest nodes `found` (sorted, `k + 1` entries
/// when available, missing ones infinite; the first is finite) into `out` (`k` slots).
fn interpolation_weights(found: &[(f32, u32)], rule: Interpolation, out: &mut [Influence]) {
    let k = out.len();
    let m = found.iter().take(k).filter(|e| e.0.is_finite()).count();
    let d = |i: usize| found[i].0;
    let mut w = [0.0f32; MAX_INFLUENCES];
    match rule {
        Interpolation::EmbeddedGraph => {
            let r = match found.get(k) {
                Some(e) if e.0.is_finite() => e.0,
                _ => 2.0 * d(m - 1),
            };
            for (i, wi) in w.iter_mut().enumerate().take(m) {
                *wi = if r > 0.0 {
                    let x = (1.0 - d(i) / r).max(0.0);
                    x * x
                } else {
                    1.0
                };
            }
        }
        Interpolation::InverseDistance => {
            if d(0) <= 0.0 {
                w[0] = 1.0;
            } else {
                for (i, wi) in w.iter_mut().enumerate().take(m) {
                    *wi = 1.0 / (d(i) * d(i));
                }
            }
        }
    }
    // Negligible weights are zero: their products with small residuals would be subnormal
    // (slow on Intel cores; see `activation::EXP_TAIL`).
    // The nearest node has the largest weight under both rules.
    let floor = INTERPOLATION_FLUSH * w[0];
    for wi in w.iter_mut().take(m) {
        if *wi < floor {
            *wi = 0.0;
        }
    }
    let mut sum: f32 = w[..m].iter().sum();
    if !(sum > 0.0 && sum.is_finite()) {
        // Every candidate at the cut-off distance: share among the nearest ones.
        for (i, wi) in w.iter_mut().enumerate().take(m) {
            *wi = if d(i) == d(0) { 1.0 } else { 0.0 };
        }
        sum = w[..m].iter().sum();
    }
    for (i, o) in out.iter_mut().enumerate() {
        *o = if i < m {
            Influence {
                index: found[i].1,
                weight: w[i] / sum,
            }
        } else {
            Influence::default()
        };
    }
}

/// SkinNet's bind-pose weights of every position, cut to the `keep` strongest joints per
/// vertex and renormalised, into `out` (`positions.len() × keep`).
fn bind_pose_base<W: AsRef<[f32]>>(
    model: &SkinNet<W>,
    positions: &[Vec3],
    keep: usize,
) -> Result<Vec<Influence>, RuntimeError> {
    let mut out = vec![Influence::default(); positions.len() * keep];
    if keep == 0 {
        return Ok(out);
    }
    let j = model.joint_count();
    let mut frame = FrameState::new(model);
    frame.set_pose(model, &model.skeleton().bind_pose())?;
    let mut scratch = Scratch::new(model);
    let mut dense = vec![0.0; BASE_CHUNK.min(positions.len()) * j];
    for (c, chunk) in positions.chunks(BASE_CHUNK).enumerate() {
        let mesh = BoundMesh::bind(model, chunk)?;
        let dense = &mut dense[..chunk.len() * j];
        WeightsJob {
            model,
            mesh: &mesh,
            frame: &frame,
            first_vertex: 0,
            out_weights: dense,
        }
        .run(&mut scratch)?;
        let base = &mut out[c * BASE_CHUNK * keep..(c * BASE_CHUNK + chunk.len()) * keep];
        for (w, b) in dense.chunks_exact(j).zip(base.chunks_exact_mut(keep)) {
            strongest_influences(w, b);
        }
    }
    Ok(out)
}

impl FastMesh {
    /// Binds a triangle mesh (canonical positions, any count ≥ 1; `triangles` index them, may be
    /// empty for a point cloud, which then uses straight-line distances) for the fast path.
    /// Costs one exact SkinNet evaluation of every vertex (the bind-pose base weights) plus
    /// graph searches; see `docs/experiments/fast-path.md` for measured bind times.
    pub fn bind<W: AsRef<[f32]>>(
        model: &SkinNet<W>,
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        options: &FastOptions,
    ) -> Result<Self, RuntimeError> {
        let n = positions.len();
        if n == 0 || n > MAX_BIND_VERTICES {
            return Err(RuntimeError::VertexCount(n));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(RuntimeError::NonFinite {
                field: "positions",
                index: i,
            });
        }
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&v) = tri.iter().find(|&&v| v as usize >= n) {
                return Err(RuntimeError::Index {
                    field: "triangles",
                    index: t,
                    value: v,
                    limit: n,
                });
            }
        }
        let j = model.joint_count();
        setting("nodes", options.nodes, 1, MAX_BIND_VERTICES)?;
        setting("neighbours", options.neighbours, 1, MAX_INFLUENCES)?;
        setting(
            "base_influences",
            options.base_influences,
            0,
            MAX_INFLUENCES,
        )?;
        // More base joints than the model has would only repeat zeros.
        let options = &FastOptions {
            base_influences: options.base_influences.min(j),
            ..*options
        };

        let graph = MeshGraph::new(positions, triangles);
        let welded_pos = |w: u32| positions[graph.first[w as usize] as usize];
        // Start from the welded vertex farthest from the centroid: independent of vertex order.
        let centroid = (0..graph.len() as u32).map(welded_pos).sum::<Vec3>() / graph.len() as f32;
        let start = (0..graph.len() as u32)
            .fold((0, -1.0f32), |(bw, bd), w| {
                let d = welded_pos(w).distance_squared(centroid);
                if d > bd { (w, d) } else { (bw, bd) }
            })
            .0;
        let nodes = farthest_point_nodes(&graph, options.nodes.min(graph.len()), start);
        let node_positions: Vec<Vec3> = nodes.iter().map(|&w| welded_pos(w)).collect();

        let k = options.neighbours;
        let want = k + 1;
        let mut found = match options.metric {
            NodeMetric::AlongMesh if !triangles.is_empty() => {
                nearest_nodes_along_mesh(&graph, &nodes, want)
            }
            _ => vec![(f32::INFINITY, u32::MAX); graph.len() * want],
        };
        let mut copies = vec![0usize; graph.len()];
        for &w in &graph.weld {
            copies[w as usize] += 1;
        }
        let mut fallback = 0;
        let mut welded_interp = vec![Influence::default(); graph.len() * k];
        for (w, (f, out)) in found
            .chunks_exact_mut(want)
            .zip(welded_interp.chunks_exact_mut(k))
            .enumerate()
        {
            if !f[0].0.is_finite() {
                nearest_nodes_in_space(&node_positions, welded_pos(w as u32), f);
                if options.metric == NodeMetric::AlongMesh && !triangles.is_empty() {
                    fallback += copies[w];
                }
            }
            interpolation_weights(f, options.interpolation, out);
        }
        let mut interp = vec![Influence::default(); n * k];
        for (v, out) in interp.chunks_exact_mut(k).enumerate() {
            let w = graph.weld[v] as usize;
            out.copy_from_slice(&welded_interp[w * k..(w + 1) * k]);
        }
        let base = bind_pose_base(model, positions, options.base_influences)?;
        let base_log = base
            .iter()
            .map(|b| {
                if b.weight > 0.0 {
                    libm::logf(b.weight)
                } else {
                    f32::NEG_INFINITY
                }
            })
            .collect();
        let node_vertices: Vec<u32> = nodes.iter().map(|&w| graph.first[w as usize]).collect();
        let node_mesh = BoundMesh::bind(model, &node_positions)?;
        let mut node_bind = vec![0.0; node_positions.len() * j];
        let mut frame = FrameState::new(model);
        frame.set_pose(model, &model.skeleton().bind_pose())?;
        WeightsJob {
            model,
            mesh: &node_mesh,
            frame: &frame,
            first_vertex: 0,
            out_weights: &mut node_bind,
        }
        .run(&mut Scratch::new(model))?;
        Ok(Self {
            model_id: model.id(),
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            joints: j,
            kernel: model.kernel(),
            rest: positions.to_vec(),
            options: FastOptions {
                nodes: nodes.len(),
                ..*options
            },
            node_vertices,
            node_mesh,
            interp,
            base,
            base_log,
            node_bind,
            stats: BindStats {
                welded_vertices: graph.len(),
                euclidean_fallback_vertices: fallback,
            },
        })
    }

    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.rest.len()
    }

    /// Number of nodes (the requested count, capped at the welded vertex count).
    #[must_use]
    pub fn node_count(&self) -> usize {
        self.node_vertices.len()
    }

    /// Number of joints of the model it was bound to.
    #[must_use]
    pub fn joint_count(&self) -> usize {
        self.joints
    }

    /// The options it was bound with (`nodes` = the node count actually used).
    #[must_use]
    pub fn options(&self) -> &FastOptions {
        &self.options
    }

    /// Canonical (rest) positions.
    #[must_use]
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest
    }

    /// The mesh vertex each node sits on.
    #[must_use]
    pub fn node_vertices(&self) -> &[u32] {
        &self.node_vertices
    }

    /// Interpolation: `neighbours` entries per vertex (node index, weight; weights sum to one).
    #[must_use]
    pub fn interpolation(&self) -> &[Influence] {
        &self.interp
    }

    /// Bind-pose base weights: `base_influences` entries per vertex (joint, weight; sum one).
    #[must_use]
    pub fn base(&self) -> &[Influence] {
        &self.base
    }

    /// What binding found.
    #[must_use]
    pub fn stats(&self) -> BindStats {
        self.stats
    }

    /// SkinNet's exact bind-pose weights at the nodes, `J` per node (node order).
    #[must_use]
    pub fn node_bind_weights(&self) -> &[f32] {
        &self.node_bind
    }

    /// The base entries of vertex `v`.
    pub(crate) fn base_of(&self, v: usize) -> &[Influence] {
        let kb = self.options.base_influences;
        &self.base[v * kb..(v + 1) * kb]
    }

    /// `ln` of the base weights of vertex `v` (−∞ for an empty slot).
    pub(crate) fn base_log_of(&self, v: usize) -> &[f32] {
        let kb = self.options.base_influences;
        &self.base_log[v * kb..(v + 1) * kb]
    }

    /// The interpolation entries of vertex `v`.
    pub(crate) fn interp_of(&self, v: usize) -> &[Influence] {
        let k = self.options.neighbours;
        &self.interp[v * k..(v + 1) * k]
    }

    /// The kernel of the model it was bound to (blends the skinning matrices).
    pub(crate) fn kernel(&self) -> Kernel {
        self.kernel
    }

    pub(crate) fn node_mesh(&self) -> &BoundMesh {
        &self.node_mesh
    }

    pub(crate) fn model_id(&self) -> u64 {
        self.model_id
    }

    pub(crate) fn id(&self) -> u64 {
        self.id
    }
}
