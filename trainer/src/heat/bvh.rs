//! A bounding-volume hierarchy over triangles for "does this segment cross the mesh" queries.
//!
//! Built top-down by splitting at the median centroid along the widest axis (no SAH: the
//! queries are short segments from the surface inwards, and build time matters as much).

use glam::DVec3;

const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    min: DVec3,
    max: DVec3,
    /// Leaf: first triangle in `order`; inner: index of the left child (right = left + 1).
    first: u32,
    /// Leaf: triangle count; inner: 0.
    count: u32,
}

/// The hierarchy: nodes and the triangle permutation they index.
#[derive(Clone, Debug)]
pub(crate) struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
    triangles: Vec<[DVec3; 3]>,
    corners: Vec<[u32; 3]>,
}

impl Bvh {
    /// Builds the hierarchy over `triangles` (indices into `positions`).
    #[must_use]
    pub(crate) fn new(positions: &[DVec3], triangles: &[[u32; 3]]) -> Self {
        let tris: Vec<[DVec3; 3]> = triangles.iter().map(|t| t.map(|v| positions[v as usize])).collect();
        let centroids: Vec<DVec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
        nodes.push(Node { min: DVec3::ZERO, max: DVec3::ZERO, first: 0, count: 0 });
        // Explicit stack of (node, start, end) keeps deep trees off the call stack.
        let mut stack = vec![(0usize, 0usize, tris.len())];
        while let Some((node, start, end)) = stack.pop() {
            let (mut min, mut max) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            let (mut cmin, mut cmax) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
            for &t in &order[start..end] {
                for p in tris[t as usize] {
                    min = min.min(p);
                    max = max.max(p);
                }
                cmin = cmin.min(centroids[t as usize]);
                cmax = cmax.max(centroids[t as usize]);
            }
            let extent = cmax - cmin;
            if end - start <= LEAF_SIZE || extent.max_element() <= 0.0 {
                nodes[node] = Node { min, max, first: start as u32, count: (end - start) as u32 };
                continue;
            }
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let mid = (start + end) / 2;
            order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
            });
            let left = nodes.len();
            nodes.push(Node { min: DVec3::ZERO, max: DVec3::ZERO, first: 0, count: 0 });
            nodes.push(Node { min: DVec3::ZERO, max: DVec3::ZERO, first: 0, count: 0 });
            nodes[node] = Node { min, max, first: left as u32, count: 0 };
            stack.push((left, start, mid));
            stack.push((left + 1, mid, end));
        }
        Self { nodes, order, triangles: tris, corners: triangles.to_vec() }
    }

    /// Whether the segment `p → q` crosses a triangle at a parameter `t ∈ (t_min, 1]`, ignoring
    /// triangles that have `skip_vertex` as a corner (the segment starts on them).
    #[must_use]
    pub(crate) fn segment_hits(&self, p: DVec3, q: DVec3, t_min: f64, skip_vertex: u32) -> bool {
        if self.triangles.is_empty() {
            return false;
        }
        let d = q - p;
        let inv = d.recip();
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if !slab_hit(p, inv, node.min, node.max) {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    if self.corners[t as usize].contains(&skip_vertex) {
                        continue;
                    }
                    if let Some(s) = intersect(p, d, &self.triangles[t as usize]) {
                        if s > t_min && s <= 1.0 {
                            return true;
                        }
                    }
                }
            } else if top + 2 <= stack.len() {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
            } else {
                // Deeper than the fixed stack (median splits stay below depth 30 for any mesh
                // we accept): answer the whole query by brute force rather than miss a hit.
                return self.triangles.iter().zip(&self.corners).any(|(tri, c)| {
                    !c.contains(&skip_vertex) && intersect(p, d, tri).is_some_and(|s| s > t_min && s <= 1.0)
                });
            }
        }
        false
    }
}

/// Whether the segment `p + s·d`, `s ∈ [0, 1]`, meets the box (slab test; `inv = 1/d`).
fn slab_hit(p: DVec3, inv: DVec3, min: DVec3, max: DVec3) -> bool {
    let t0 = (min - p) * inv;
    let t1 = (max - p) * inv;
    // NaN appears for 0·∞ (segment parallel to and on a slab plane): treat it as inside.
    let lo = t0.min(t1);
    let hi = t0.max(t1);
    let enter = [lo.x, lo.y, lo.z, 0.0].into_iter().filter(|v| !v.is_nan()).fold(f64::NEG_INFINITY, f64::max);
    let exit = [hi.x, hi.y, hi.z, 1.0].into_iter().filter(|v| !v.is_nan()).fold(f64::INFINITY, f64::min);
    enter <= exit
}

/// Möller–Trumbore: the parameter `s` where `p + s·d` crosses the triangle, if it does.
fn intersect(p: DVec3, d: DVec3, t: &[DVec3; 3]) -> Option<f64> {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let h = d.cross(e2);
    let det = e1.dot(h);
    // Relative test: a segment parallel to the plane cannot cross it.
    if det.abs() <= 1e-14 * d.length() * e1.length() * e2.length() {
        return None;
    }
    let f = 1.0 / det;
    let s = p - t[0];
    let u = f * s.dot(h);
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = f * d.dot(q);
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(f * e2.dot(q))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn agrees_with_brute_force_on_random_soups() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut r = || DVec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
        // Small triangles scattered in a cube, so that some segments hit and some miss.
        let positions: Vec<DVec3> = (0..100).flat_map(|_| {
            let c = r();
            [c + r() * 0.2, c + r() * 0.2, c + r() * 0.2]
        }).collect::<Vec<_>>();
        let triangles: Vec<[u32; 3]> = (0..100).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        let bvh = Bvh::new(&positions, &triangles);
        let mut hits = 0;
        for k in 0..500 {
            let (p, q) = (r(), r() * 0.3);
            let skip = (k % 300) as u32;
            let brute = triangles.iter().any(|t| {
                !t.contains(&skip)
                    && intersect(p, q - p, &t.map(|v| positions[v as usize])).is_some_and(|s| s > 1e-9 && s <= 1.0)
            });
            assert_eq!(bvh.segment_hits(p, q, 1e-9, skip), brute, "query {k}");
            hits += usize::from(brute);
        }
        // The check is meaningful only if both outcomes occur.
        assert!(hits > 20 && hits < 480, "{hits}");
    }

    #[test]
    fn axis_aligned_segment_through_a_square() {
        let p = [DVec3::new(-1.0, 0.0, -1.0), DVec3::new(1.0, 0.0, -1.0), DVec3::new(1.0, 0.0, 1.0), DVec3::new(-1.0, 0.0, 1.0)];
        let bvh = Bvh::new(&p, &[[0, 1, 2], [0, 2, 3]]);
        assert!(bvh.segment_hits(DVec3::new(0.3, 1.0, 0.2), DVec3::new(0.3, -1.0, 0.2), 1e-9, u32::MAX));
        assert!(!bvh.segment_hits(DVec3::new(0.3, 1.0, 0.2), DVec3::new(0.3, 0.5, 0.2), 1e-9, u32::MAX));
        assert!(!bvh.segment_hits(DVec3::new(3.0, 1.0, 0.2), DVec3::new(3.0, -1.0, 0.2), 1e-9, u32::MAX));
        // Starting on the square and skipping its corner 0 still sees triangle [0, 1, 2]: skipped.
        assert!(!bvh.segment_hits(DVec3::new(-0.5, 0.0, -0.6), DVec3::new(-0.5, -1.0, -0.6), 1e-9, 0));
    }
}
