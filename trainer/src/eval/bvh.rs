//! A bounding-volume hierarchy over a triangle mesh for exact closest-point queries.
//!
//! Binary tree, built top-down by splitting the triangles at the median centroid along the
//! longest axis of their centroid box (O(n log n), no tuning knobs); leaves hold at most
//! [`LEAF_SIZE`] triangles. A query descends nearer children first and prunes every box whose
//! distance exceeds the best triangle found so far, so the answer equals brute force over all
//! triangles (same [`closest_point_on_triangle`], same tie order up to equal distances).

use glam::Vec3;

use super::distance::closest_point_on_triangle;

/// Most triangles in a leaf.
pub const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Leaf: first index into `order`; inner: index of the left child.
    start: u32,
    /// Leaf: triangle count (> 0); inner: 0.
    count: u32,
    /// Inner: index of the right child.
    right: u32,
}

/// The closest point of a mesh to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// Squared distance.
    pub distance_squared: f32,
    /// The closest point.
    pub point: Vec3,
    /// The triangle it lies on.
    pub triangle: u32,
}

/// A BVH over the triangles of a mesh (it keeps its own copy of the positions).
#[derive(Clone, Debug)]
pub struct TriangleBvh {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    nodes: Vec<Node>,
    order: Vec<u32>,
}

impl TriangleBvh {
    /// Builds the tree. Triangles whose indices are out of range are skipped (validate the mesh
    /// first); an empty mesh gives a tree whose queries return `None`.
    #[must_use]
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let n = positions.len();
        let triangles: Vec<[u32; 3]> = triangles
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&i| (i as usize) < n))
            .collect();
        let centroids: Vec<Vec3> = triangles
            .iter()
            .map(|t| {
                (positions[t[0] as usize] + positions[t[1] as usize] + positions[t[2] as usize])
                    / 3.0
            })
            .collect();
        let mut bvh = Self {
            positions: positions.to_vec(),
            triangles,
            nodes: Vec::new(),
            order: (0..centroids.len() as u32).collect(),
        };
        if !bvh.triangles.is_empty() {
            bvh.nodes.reserve(2 * bvh.triangles.len() / LEAF_SIZE + 1);
            bvh.build(&centroids, 0, centroids.len());
        }
        bvh
    }

    /// Number of triangles in the tree.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    fn triangle_box(&self, t: u32) -> (Vec3, Vec3) {
        let [a, b, c] = self.triangles[t as usize].map(|i| self.positions[i as usize]);
        (a.min(b).min(c), a.max(b).max(c))
    }

    /// Builds the subtree over `order[start..end]` and returns its node index.
    fn build(&mut self, centroids: &[Vec3], start: usize, end: usize) -> u32 {
        let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let (mut cmin, mut cmax) = (min, max);
        for &t in &self.order[start..end] {
            let (lo, hi) = self.triangle_box(t);
            min = min.min(lo);
            max = max.max(hi);
            cmin = cmin.min(centroids[t as usize]);
            cmax = cmax.max(centroids[t as usize]);
        }
        let index = self.nodes.len() as u32;
        self.nodes.push(Node {
            min,
            max,
            start: start as u32,
            count: (end - start) as u32,
            right: 0,
        });
        if end - start <= LEAF_SIZE {
            return index;
        }
        let extent = cmax - cmin;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mid = start + (end - start) / 2;
        self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
        });
        let left = self.build(centroids, start, mid);
        let right = self.build(centroids, mid, end);
        let node = &mut self.nodes[index as usize];
        node.start = left;
        node.count = 0;
        node.right = right;
        index
    }

    /// The closest point of the mesh to `p`, or `None` for an empty mesh.
    #[must_use]
    pub fn closest(&self, p: Vec3) -> Option<Closest> {
        self.closest_within(p, f32::INFINITY)
    }

    /// The closest point of the mesh to `p` if it is within `sqrt(max_distance_squared)`.
    #[must_use]
    pub fn closest_within(&self, p: Vec3, max_distance_squared: f32) -> Option<Closest> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: Option<Closest> = None;
        let mut bound = max_distance_squared;
        // Depth is about log2(n / LEAF_SIZE) for a median split; 64 covers any mesh we accept,
        // and the Vec grows if a degenerate input ever needs more.
        let mut stack: Vec<(u32, f32)> = Vec::with_capacity(64);
        stack.push((0, box_distance_squared(p, &self.nodes[0])));
        while let Some((i, d2)) = stack.pop() {
            if d2 > bound {
                continue;
            }
            let node = &self.nodes[i as usize];
            if node.count > 0 {
                let (s, e) = (
                    node.start as usize,
                    node.start as usize + node.count as usize,
                );
                for &t in &self.order[s..e] {
                    let [a, b, c] = self.triangles[t as usize].map(|k| self.positions[k as usize]);
                    let q = closest_point_on_triangle(p, a, b, c).0;
                    let dq = (q - p).length_squared();
                    if dq <= bound {
                        bound = dq;
                        best = Some(Closest {
                            distance_squared: dq,
                            point: q,
                            triangle: t,
                        });
                    }
                }
            } else {
                let (l, r) = (node.start, node.right);
                let dl = box_distance_squared(p, &self.nodes[l as usize]);
                let dr = box_distance_squared(p, &self.nodes[r as usize]);
                // Push the farther child first so the nearer one is searched first.
                if dl <= dr {
                    stack.push((r, dr));
                    stack.push((l, dl));
                } else {
                    stack.push((l, dl));
                    stack.push((r, dr));
                }
            }
        }
        best
    }
}

fn box_distance_squared(p: Vec3, node: &Node) -> f32 {
    let d = (node.min - p).max(p - node.max).max(Vec3::ZERO);
    d.length_squared()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::distance::point_triangle_distance_squared;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn equals_brute_force_on_a_random_triangle_soup() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut r = |s: f32| {
            Vec3::new(
                rng.random_range(-s..s),
                rng.random_range(-s..s),
                rng.random_range(-s..s),
            )
        };
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for t in 0..500u32 {
            let centre = r(1.0);
            positions.extend([centre + r(0.1), centre + r(0.1), centre + r(0.1)]);
            triangles.push([3 * t, 3 * t + 1, 3 * t + 2]);
        }
        let bvh = TriangleBvh::new(&positions, &triangles);
        for _ in 0..2000 {
            let p = r(1.5);
            let brute = triangles
                .iter()
                .map(|t| {
                    point_triangle_distance_squared(
                        p,
                        positions[t[0] as usize],
                        positions[t[1] as usize],
                        positions[t[2] as usize],
                    )
                })
                .fold(f32::INFINITY, f32::min);
            let got = bvh.closest(p).unwrap();
            assert_eq!(got.distance_squared, brute, "at {p}");
            let t = triangles[got.triangle as usize];
            let own = point_triangle_distance_squared(
                p,
                positions[t[0] as usize],
                positions[t[1] as usize],
                positions[t[2] as usize],
            );
            assert_eq!(own, got.distance_squared);
        }
    }

    #[test]
    fn empty_and_out_of_range_inputs_do_not_panic() {
        let bvh = TriangleBvh::new(&[], &[]);
        assert!(bvh.closest(Vec3::ZERO).is_none());
        let bvh = TriangleBvh::new(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2], [0, 1, 9]]);
        assert_eq!(bvh.triangle_count(), 1);
        let c = bvh.closest(Vec3::new(0.25, 0.25, 2.0)).unwrap();
        assert!((c.distance_squared - 4.0).abs() < 1e-6);
        assert!(
            bvh.closest_within(Vec3::new(0.25, 0.25, 2.0), 1.0)
                .is_none()
        );
    }
}
