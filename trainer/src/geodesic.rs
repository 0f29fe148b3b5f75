//! Geodesic distances on the template, for the skinning regulariser (paper Eqs. 7–8).
//!
//! Approximation: shortest paths along mesh edges (exact Dijkstra on the edge graph, edge length
//! = Euclidean length in the canonical pose). Edge paths zig-zag, so they overestimate the true
//! surface geodesic — by a few percent on a well-shaped triangulation (at most ≈ 8% for paths
//! across a regular triangle grid at the worst angle) — and never underestimate it. The
//! regulariser only needs distances relative to their maximum, raised to the power r = 3, where a
//! uniform few-percent stretch cancels; what matters is that distances follow the surface (an arm
//! is far from the torso it touches in the rest pose), which edge paths do.
//!
//! Vertices at the same position (seams of an unwelded mesh) are one graph node, so UV or normal
//! splits do not cut the surface apart. Vertices in a component with no source get `+∞`.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

use glam::Vec3;
use rayon::prelude::*;

/// Undirected edge graph of a triangle mesh, with coincident vertices welded.
#[derive(Clone, Debug)]
pub struct MeshGraph {
    /// Graph node of each mesh vertex.
    node_of: Vec<u32>,
    /// CSR adjacency: neighbours of node `n` are `targets[offsets[n]..offsets[n + 1]]`.
    offsets: Vec<usize>,
    targets: Vec<u32>,
    lengths: Vec<f64>,
}

#[derive(PartialEq)]
struct Item(f64, u32);

impl Eq for Item {}

impl Ord for Item {
    fn cmp(&self, o: &Self) -> Ordering {
        // Min-heap on distance; ties broken by node so the order is total and deterministic.
        o.0.total_cmp(&self.0).then_with(|| o.1.cmp(&self.1))
    }
}

impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

impl MeshGraph {
    /// Builds the graph. Triangle indices must be valid for `positions` (a validated
    /// [`skinfield_formats::Template`]); out-of-range indices are skipped.
    #[must_use]
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
        let mut node_pos: Vec<Vec3> = Vec::new();
        let node_of: Vec<u32> = positions
            .iter()
            .map(|p| {
                // +0.0 and −0.0 are the same point.
                let key = (*p + Vec3::ZERO).to_array().map(f32::to_bits);
                *weld.entry(key).or_insert_with(|| {
                    node_pos.push(*p);
                    (node_pos.len() - 1) as u32
                })
            })
            .collect();
        let n = node_pos.len();
        let mut edges: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 6);
        for t in triangles {
            if t.iter().any(|&i| i as usize >= positions.len()) {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (node_of[t[k] as usize], node_of[t[(k + 1) % 3] as usize]);
                if a != b {
                    edges.push((a, b));
                    edges.push((b, a));
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let mut offsets = vec![0usize; n + 1];
        for &(a, _) in &edges {
            offsets[a as usize + 1] += 1;
        }
        for i in 0..n {
            offsets[i + 1] += offsets[i];
        }
        let targets: Vec<u32> = edges.iter().map(|e| e.1).collect();
        let lengths = edges
            .iter()
            .map(|&(a, b)| f64::from(node_pos[a as usize].distance(node_pos[b as usize])))
            .collect();
        Self {
            node_of,
            offsets,
            targets,
            lengths,
        }
    }

    /// Graph node of each mesh vertex.
    #[must_use]
    pub fn node_of(&self) -> &[u32] {
        &self.node_of
    }

    /// Neighbouring nodes of `node` (empty for an out-of-range node).
    #[must_use]
    pub fn neighbours(&self, node: usize) -> &[u32] {
        match (self.offsets.get(node), self.offsets.get(node + 1)) {
            (Some(&a), Some(&b)) => &self.targets[a..b],
            _ => &[],
        }
    }

    /// One mesh vertex per node (the first with that position).
    #[must_use]
    pub fn representatives(&self) -> Vec<u32> {
        let mut rep = vec![u32::MAX; self.node_count()];
        for (v, &n) in self.node_of.iter().enumerate().rev() {
            rep[n as usize] = v as u32;
        }
        rep
    }

    /// Number of graph nodes (distinct positions).
    #[must_use]
    pub fn node_count(&self) -> usize {
        self.offsets.len() - 1
    }

    fn dijkstra_nodes(&self, sources: impl Iterator<Item = u32>) -> Vec<f64> {
        let mut dist = vec![f64::INFINITY; self.node_count()];
        let mut heap = BinaryHeap::new();
        for s in sources {
            if dist[s as usize] > 0.0 {
                dist[s as usize] = 0.0;
                heap.push(Item(0.0, s));
            }
        }
        while let Some(Item(d, n)) = heap.pop() {
            if d > dist[n as usize] {
                continue;
            }
            for e in self.offsets[n as usize]..self.offsets[n as usize + 1] {
                let (m, nd) = (self.targets[e], d + self.lengths[e]);
                if nd < dist[m as usize] {
                    dist[m as usize] = nd;
                    heap.push(Item(nd, m));
                }
            }
        }
        dist
    }

    /// Edge-path distance from each mesh vertex to the nearest of `sources` (vertex indices;
    /// out-of-range ones are ignored); `+∞` where no source is reachable.
    #[must_use]
    pub fn distances_from(&self, sources: &[usize]) -> Vec<f64> {
        let d = self.dijkstra_nodes(sources.iter().filter_map(|&s| self.node_of.get(s).copied()));
        self.node_of.iter().map(|&n| d[n as usize]).collect()
    }

    /// Largest finite edge-path distance between two vertices (`d_geo^max`). Exact (one Dijkstra
    /// per node, in parallel) up to `exact_limit` nodes; above that, the largest distance found
    /// by 8 rounds of the double sweep (farthest node from the farthest node, restarted in every
    /// component): a lower bound, not exact in general (on a square it finds the diagonal, not
    /// the longer edge path between the other two corners).
    #[must_use]
    pub fn max_distance(&self, exact_limit: usize) -> f64 {
        let n = self.node_count();
        let finite_max = |d: &[f64]| {
            d.iter()
                .copied()
                .filter(|x| x.is_finite())
                .fold(0.0f64, f64::max)
        };
        if n <= exact_limit {
            return (0..n as u32)
                .into_par_iter()
                .map(|s| finite_max(&self.dijkstra_nodes(std::iter::once(s))))
                .reduce(|| 0.0, f64::max);
        }
        let mut best = 0.0f64;
        let mut seen = vec![false; n];
        for start in 0..n {
            if seen[start] {
                continue;
            }
            let mut s = start as u32;
            for _ in 0..8 {
                let d = self.dijkstra_nodes(std::iter::once(s));
                let (far, dmax) = d.iter().enumerate().filter(|(_, x)| x.is_finite()).fold(
                    (s, 0.0),
                    |acc, (i, &x)| if x > acc.1 { (i as u32, x) } else { acc },
                );
                for (i, x) in d.iter().enumerate() {
                    seen[i] |= x.is_finite();
                }
                best = best.max(dmax);
                if far == s {
                    break;
                }
                s = far;
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An `n × n` vertex grid of unit spacing in the XY plane, split along one diagonal.
    fn grid(n: usize) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32, 0.0))
            .collect();
        let mut t = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                let n = n as u32;
                t.push([i, i + 1, i + n + 1]);
                t.push([i, i + n + 1, i + n]);
            }
        }
        (p, t)
    }

    #[test]
    fn grid_distances_are_the_edge_path_lengths() {
        let (p, t) = grid(5);
        let g = MeshGraph::new(&p, &t);
        let d = g.distances_from(&[0]);
        // Diagonal edges go (x, y) → (x+1, y+1): shortest path = diagonal steps then straight.
        for (i, &di) in d.iter().enumerate() {
            let (x, y) = ((i % 5) as f64, (i / 5) as f64);
            let expect = x.min(y) * 2f64.sqrt() + (x - y).abs();
            assert!((di - expect).abs() < 1e-6, "{i}: {di} vs {expect}");
        }
        // Exact and double-sweep diameters agree here: the anti-diagonal corners, where no
        // diagonal edge helps (4 + 4).
        let exact = g.max_distance(usize::MAX);
        assert!((exact - 8.0).abs() < 1e-6, "{exact}");
        // The double sweep from (0, 0) finds (4, 4) and back: 4√2, a lower bound only.
        let approx = g.max_distance(0);
        assert!(
            approx <= exact + 1e-9 && (approx - 4.0 * 2f64.sqrt()).abs() < 1e-6,
            "{approx}"
        );
    }

    #[test]
    fn distances_follow_the_surface_not_space() {
        // A folded strip: two 1×4 strips meeting at x = 4 and folded back so that the far end
        // is 0.1 away in space from the start but 8 away along the surface.
        let mut p = Vec::new();
        for x in 0..=4 {
            p.push(Vec3::new(x as f32, 0.0, 0.0));
            p.push(Vec3::new(x as f32, 1.0, 0.0));
        }
        for x in (0..4).rev() {
            p.push(Vec3::new(x as f32, 0.0, 0.1 * (4 - x) as f32 / 4.0));
            p.push(Vec3::new(x as f32, 1.0, 0.1 * (4 - x) as f32 / 4.0));
        }
        let mut t = Vec::new();
        for s in 0..8u32 {
            let a = 2 * s;
            t.push([a, a + 2, a + 3]);
            t.push([a, a + 3, a + 1]);
        }
        let g = MeshGraph::new(&p, &t);
        let d = g.distances_from(&[0]);
        assert!(d[16] > 7.9, "{}", d[16]);
        assert!(p[0].distance(p[16]) < 0.11);
        let (approx, exact) = (g.max_distance(0), g.max_distance(usize::MAX));
        assert!(
            approx <= exact + 1e-9 && approx > 0.9 * exact,
            "{approx} vs {exact}"
        );
    }

    #[test]
    fn seams_are_welded_and_components_unreachable() {
        // Two triangles sharing an edge by position only (duplicated vertices), plus a separate one.
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::X,
            Vec3::Y,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(5.0, 1.0, 0.0),
        ];
        let t = vec![[0, 1, 2], [3, 5, 4], [6, 7, 8]];
        let g = MeshGraph::new(&p, &t);
        assert_eq!(g.node_count(), 7);
        let d = g.distances_from(&[0]);
        assert!((d[5] - 2.0).abs() < 1e-6, "{}", d[5]);
        assert!(d[6].is_infinite() && d[8].is_infinite());
        assert!((g.max_distance(100) - 2.0).abs() < 1e-6);
    }
}
