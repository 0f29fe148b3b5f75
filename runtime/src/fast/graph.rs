//! Distances along the mesh for the fast path's bind step: the welded edge graph, geodesic
//! farthest-point sampling of the nodes, and the few nearest nodes of every vertex.
//!
//! Distances are shortest paths along mesh edges (Dijkstra, edge length = Euclidean length in
//! the canonical pose). Edge paths zig-zag, so they overestimate the surface geodesic by a few
//! percent, uniformly enough for choosing and weighting neighbours; what matters is that they
//! follow the surface: a skirt and the leg it touches in the rest pose, or an arm and the
//! torso, are far apart along the mesh (or not connected at all) however close they are in
//! space. Vertices at bitwise-equal positions (UV or normal seams of an unwelded mesh) are one
//! graph vertex, so seams do not cut the surface apart.

use alloc::collections::BinaryHeap;
use alloc::vec;
use alloc::vec::Vec;
use core::cmp::Ordering;

use glam::Vec3;

/// The undirected edge graph of a triangle mesh with coincident vertices welded.
#[derive(Clone, Debug)]
pub(crate) struct MeshGraph {
    /// Welded vertex of each mesh vertex.
    pub weld: Vec<u32>,
    /// A mesh vertex of each welded vertex (the lowest index), hence its position.
    pub first: Vec<u32>,
    /// CSR adjacency of welded vertices: `targets[offsets[w]..offsets[w + 1]]`.
    offsets: Vec<u32>,
    targets: Vec<u32>,
    lengths: Vec<f32>,
}

/// `p` as a hashable key; `+0.0` and `−0.0` are the same point.
fn key(p: Vec3) -> [u32; 3] {
    (p + Vec3::ZERO).to_array().map(f32::to_bits)
}

impl MeshGraph {
    /// Builds the graph; every triangle index must be `< positions.len()` (checked by the
    /// caller). Degenerate triangles contribute only their proper edges.
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let n = positions.len();
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.sort_unstable_by_key(|&v| (key(positions[v as usize]), v));
        let mut weld = vec![0u32; n];
        let mut first = Vec::new();
        for (i, &v) in order.iter().enumerate() {
            let same = i > 0 && key(positions[order[i - 1] as usize]) == key(positions[v as usize]);
            if !same {
                first.push(v);
            }
            weld[v as usize] = (first.len() - 1) as u32;
        }
        let mut edges: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 6);
        for t in triangles {
            for k in 0..3 {
                let (a, b) = (weld[t[k] as usize], weld[t[(k + 1) % 3] as usize]);
                if a != b {
                    edges.push((a, b));
                    edges.push((b, a));
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let w = first.len();
        let mut offsets = vec![0u32; w + 1];
        for &(a, _) in &edges {
            offsets[a as usize + 1] += 1;
        }
        for i in 0..w {
            offsets[i + 1] += offsets[i];
        }
        let targets: Vec<u32> = edges.iter().map(|&(_, b)| b).collect();
        let lengths = edges
            .iter()
            .map(|&(a, b)| {
                positions[first[a as usize] as usize]
                    .distance(positions[first[b as usize] as usize])
            })
            .collect();
        Self {
            weld,
            first,
            offsets,
            targets,
            lengths,
        }
    }

    /// Number of welded vertices.
    pub fn len(&self) -> usize {
        self.first.len()
    }

    fn neighbours(&self, w: u32) -> impl Iterator<Item = (u32, f32)> + '_ {
        let (a, b) = (
            self.offsets[w as usize] as usize,
            self.offsets[w as usize + 1] as usize,
        );
        self.targets[a..b]
            .iter()
            .copied()
            .zip(self.lengths[a..b].iter().copied())
    }
}

/// A heap entry: distance, welded vertex, source; a min-heap with a total, deterministic order.
#[derive(Clone, Copy, PartialEq)]
struct Item(f32, u32, u32);

impl Eq for Item {}

impl Ord for Item {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0)
            .then_with(|| o.1.cmp(&self.1))
            .then_with(|| o.2.cmp(&self.2))
    }
}

impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// `count` welded vertices by farthest-point sampling along the mesh, starting at `start`:
/// each next node is the vertex farthest (geodesically) from every node so far, so nodes
/// cover the surface evenly; a vertex that no node reaches counts as infinitely far, so every
/// connected component gets a node before any gets a second one. Stops early when every
/// welded vertex is a node. Each step runs a Dijkstra pruned to the vertices the new node
/// brings closer, so the total cost stays near one full Dijkstra per log of the node count.
pub(crate) fn farthest_point_nodes(graph: &MeshGraph, count: usize, start: u32) -> Vec<u32> {
    let mut dist = vec![f32::INFINITY; graph.len()];
    let mut nodes = Vec::with_capacity(count);
    let mut heap = BinaryHeap::new();
    let mut next = start;
    while nodes.len() < count {
        nodes.push(next);
        dist[next as usize] = 0.0;
        heap.push(Item(0.0, next, 0));
        while let Some(Item(d, w, _)) = heap.pop() {
            if d > dist[w as usize] {
                continue;
            }
            for (u, len) in graph.neighbours(w) {
                let nd = d + len;
                if nd < dist[u as usize] {
                    dist[u as usize] = nd;
                    heap.push(Item(nd, u, 0));
                }
            }
        }
        // The farthest vertex; ties go to the lowest index (deterministic).
        let (far, d) = dist
            .iter()
            .enumerate()
            .fold((0, f32::NEG_INFINITY), |(bi, bd), (i, &d)| {
                if d > bd { (i, d) } else { (bi, bd) }
            });
        if d <= 0.0 {
            break;
        }
        next = far as u32;
    }
    nodes
}

/// The `want` nearest nodes of every welded vertex along the mesh, nearest first, as
/// `(distance, node index)`, `want` entries per vertex; entries past the nodes a vertex's
/// component holds are `(∞, u32::MAX)`. A Dijkstra from all nodes at once where a vertex is
/// settled once per source, up to `want` sources.
pub(crate) fn nearest_nodes_along_mesh(
    graph: &MeshGraph,
    nodes: &[u32],
    want: usize,
) -> Vec<(f32, u32)> {
    let mut found = vec![(f32::INFINITY, u32::MAX); graph.len() * want];
    let mut count = vec![0u8; graph.len()];
    let has = |found: &[(f32, u32)], count: &[u8], w: u32, s: u32| {
        let at = w as usize * want;
        found[at..at + count[w as usize] as usize]
            .iter()
            .any(|e| e.1 == s)
    };
    let mut heap: BinaryHeap<Item> = nodes
        .iter()
        .enumerate()
        .map(|(s, &w)| Item(0.0, w, s as u32))
        .collect();
    while let Some(Item(d, w, s)) = heap.pop() {
        let c = count[w as usize] as usize;
        if c == want || has(&found, &count, w, s) {
            continue;
        }
        found[w as usize * want + c] = (d, s);
        count[w as usize] += 1;
        for (u, len) in graph.neighbours(w) {
            if (count[u as usize] as usize) < want && !has(&found, &count, u, s) {
                heap.push(Item(d + len, u, s));
            }
        }
    }
    found
}

/// The `want` nearest nodes of `p` in straight-line distance, nearest first (ties: lower node
/// index), as `(distance, node index)`; missing entries `(∞, u32::MAX)`.
pub(crate) fn nearest_nodes_in_space(node_positions: &[Vec3], p: Vec3, out: &mut [(f32, u32)]) {
    out.fill((f32::INFINITY, u32::MAX));
    for (i, q) in node_positions.iter().enumerate() {
        let d = p.distance(*q);
        let last = out.len() - 1;
        if d < out[last].0 {
            // Insertion keeps the list sorted; equal distances keep the earlier (lower) node.
            let mut k = last;
            while k > 0 && d < out[k - 1].0 {
                out[k] = out[k - 1];
                k -= 1;
            }
            out[k] = (d, i as u32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strip of `n` unit squares along +X (two triangles each), `2(n+1)` vertices.
    fn strip(n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut p = Vec::new();
        for i in 0..=n {
            p.push(Vec3::new(i as f32, 0.0, 0.0));
            p.push(Vec3::new(i as f32, 1.0, 0.0));
        }
        let t = (0..n)
            .flat_map(|i| {
                let (a, b, c, d) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
                [[a, c, b], [b, c, d]]
            })
            .collect();
        (p, t)
    }

    #[test]
    fn seams_weld_and_distances_follow_edges() {
        let (mut p, mut t) = strip(3);
        // Duplicate vertex 4 (x = 2, y = 0) as a seam copy used by the last two triangles.
        p.push(p[4]);
        for tri in t.iter_mut().skip(4) {
            for c in tri.iter_mut() {
                if *c == 4 {
                    *c = 8;
                }
            }
        }
        let g = MeshGraph::new(&p, &t);
        assert_eq!(g.len(), 8);
        assert_eq!(g.weld[8], g.weld[4]);
        // From (0,0): to (3,0) along the bottom edge is 3 edges of length 1.
        let found = nearest_nodes_along_mesh(&g, &[g.weld[0]], 1);
        assert_eq!(found[g.weld[6] as usize], (3.0, 0));
        // (3,1): the diagonals of this strip run from (i+1, 0) back to (i, 1), so they never
        // shorten a path towards +X: 3 along the bottom and 1 up.
        assert_eq!(found[g.weld[7] as usize], (4.0, 0));
    }

    #[test]
    fn touching_components_are_unreachable_and_each_gets_a_node_first() {
        let (p0, t0) = strip(4);
        // A second strip 1 mm above the first: close in space, not connected.
        let mut p = p0.clone();
        p.extend(p0.iter().map(|q| *q + Vec3::new(0.0, 0.0, 0.001)));
        let off = p0.len() as u32;
        let mut t = t0.clone();
        t.extend(t0.iter().map(|tri| tri.map(|i| i + off)));
        let g = MeshGraph::new(&p, &t);
        let nodes = farthest_point_nodes(&g, 2, g.weld[0]);
        assert_eq!(nodes.len(), 2);
        let comp = |w: u32| g.first[w as usize] >= off;
        assert_ne!(comp(nodes[0]), comp(nodes[1]), "{nodes:?}");
        let found = nearest_nodes_along_mesh(&g, &nodes, 2);
        for w in 0..g.len() {
            let (first, second) = (found[2 * w], found[2 * w + 1]);
            assert_eq!(comp(nodes[first.1 as usize]), comp(w as u32));
            assert_eq!(second, (f32::INFINITY, u32::MAX), "one node per component");
        }
    }

    #[test]
    fn farthest_point_sampling_spreads_nodes_along_a_strip() {
        let (p, t) = strip(8);
        let g = MeshGraph::new(&p, &t);
        let nodes = farthest_point_nodes(&g, 3, g.weld[0]);
        let xs: Vec<f32> = nodes
            .iter()
            .map(|&w| p[g.first[w as usize] as usize].x)
            .collect();
        // Start at x = 0, then the far end, then the middle.
        assert_eq!(xs[0], 0.0);
        assert_eq!(xs[1], 8.0);
        assert!((xs[2] - 4.0).abs() <= 1.0, "{xs:?}");
        // Asking for more nodes than vertices stops at the vertex count.
        assert_eq!(farthest_point_nodes(&g, 100, 0).len(), g.len());
    }

    #[test]
    fn nearest_nodes_match_brute_force_dijkstra() {
        let (p, t) = strip(6);
        let g = MeshGraph::new(&p, &t);
        let nodes = [0u32, 5, 9, 13];
        let found = nearest_nodes_along_mesh(&g, &nodes, 3);
        // Reference: one Dijkstra per node, then sort.
        let per_node: Vec<Vec<(f32, u32)>> = nodes
            .iter()
            .map(|&s| nearest_nodes_along_mesh(&g, &[s], 1))
            .collect();
        for w in 0..g.len() {
            let mut all: Vec<(f32, u32)> = per_node
                .iter()
                .enumerate()
                .map(|(i, f)| (f[w].0, i as u32))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            for k in 0..3 {
                assert!((found[3 * w + k].0 - all[k].0).abs() < 1e-5, "{w} {k}");
            }
        }
        let mut out = [(0.0, 0); 2];
        let nodes_p: Vec<Vec3> = nodes
            .iter()
            .map(|&w| p[g.first[w as usize] as usize])
            .collect();
        nearest_nodes_in_space(&nodes_p, Vec3::new(2.2, 0.0, 0.0), &mut out);
        assert_eq!(out.map(|e| e.1), [1, 2].map(|i: u32| i));
    }
}
