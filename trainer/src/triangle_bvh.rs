//! One bounding-volume hierarchy over the triangles of a mesh, for the two questions the
//! trainer asks of a surface: the closest point to a query (evaluation distances, exact) and
//! whether a segment crosses the mesh (bone heat's visibility test).
//!
//! Binary tree, built top-down by splitting the triangles at the median centroid along the
//! longest axis of their centroid box (O(n log n), no tuning knobs); leaves hold at most
//! [`LEAF_SIZE`] triangles. Positions and boxes are kept in f64: a mesh given in f32 is stored
//! exactly, and the segment test gets the precision it needs. A closest-point query descends
//! nearer children first and prunes every box farther than the best triangle so far, so the
//! answer equals brute force over all triangles (same [`closest_point_on_triangle`], in f32 on
//! the f32 input, same tie order up to equal distances).

use std::ops::ControlFlow;

use glam::{DVec3, Vec3};

use crate::eval::distance::closest_point_on_triangle;

/// Most triangles in a leaf.
pub const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    min: DVec3,
    max: DVec3,
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
    positions: Vec<DVec3>,
    triangles: Vec<[u32; 3]>,
    nodes: Vec<Node>,
    order: Vec<u32>,
}

impl TriangleBvh {
    /// Builds the tree over an f32 mesh. Triangles whose indices are out of range are skipped
    /// (validate the mesh first); an empty mesh gives a tree whose queries find nothing.
    #[must_use]
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let positions: Vec<DVec3> = positions.iter().map(|p| p.as_dvec3()).collect();
        Self::new_f64(&positions, triangles)
    }

    /// Builds the tree over an f64 mesh (as [`TriangleBvh::new`]).
    #[must_use]
    pub fn new_f64(positions: &[DVec3], triangles: &[[u32; 3]]) -> Self {
        let n = positions.len();
        let triangles: Vec<[u32; 3]> = triangles
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&i| (i as usize) < n))
            .collect();
        let centroids: Vec<DVec3> = triangles
            .iter()
            .map(|t| t.iter().map(|&i| positions[i as usize]).sum::<DVec3>() / 3.0)
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

    fn corners(&self, t: u32) -> [DVec3; 3] {
        self.triangles[t as usize].map(|i| self.positions[i as usize])
    }

    /// Builds the subtree over `order[start..end]` and returns its node index. Recursion depth
    /// is about log2(n / LEAF_SIZE): median splits halve the range.
    fn build(&mut self, centroids: &[DVec3], start: usize, end: usize) -> u32 {
        let (mut min, mut max) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        let (mut cmin, mut cmax) = (min, max);
        for &t in &self.order[start..end] {
            for p in self.corners(t) {
                min = min.min(p);
                max = max.max(p);
            }
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
        let pd = p.as_dvec3();
        let mut best: Option<Closest> = None;
        let mut bound = max_distance_squared;
        // Depth is about log2(n / LEAF_SIZE) for a median split; 64 covers any mesh we accept,
        // and the Vec grows if a degenerate input ever needs more.
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, box_distance_squared(pd, &self.nodes[0])));
        while let Some((i, d2)) = stack.pop() {
            if d2 > f64::from(bound) {
                continue;
            }
            let node = &self.nodes[i as usize];
            if node.count > 0 {
                let (s, e) = (
                    node.start as usize,
                    node.start as usize + node.count as usize,
                );
                for &t in &self.order[s..e] {
                    // f32 in, f32 out: the f64 copy of an f32 mesh converts back exactly.
                    let [a, b, c] = self.corners(t).map(|v| v.as_vec3());
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
                let dl = box_distance_squared(pd, &self.nodes[l as usize]);
                let dr = box_distance_squared(pd, &self.nodes[r as usize]);
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

    /// Whether the segment `p → q` crosses a triangle at a parameter `t ∈ (t_min, 1]`, ignoring
    /// triangles that have `skip_vertex` as a corner (the segment starts on them).
    #[must_use]
    pub(crate) fn segment_hits(&self, p: DVec3, q: DVec3, t_min: f64, skip_vertex: u32) -> bool {
        let d = q - p;
        let mut hit = false;
        self.walk_segment(p, q, |t| {
            if self.triangles[t as usize].contains(&skip_vertex) {
                return ControlFlow::Continue(1.0);
            }
            if intersect(p, d, &self.corners(t)).is_some_and(|s| s > t_min && s <= 1.0) {
                hit = true;
                return ControlFlow::Break(());
            }
            ControlFlow::Continue(1.0)
        });
        hit
    }

    /// The smallest parameter `t ∈ (0, 1]` at which the segment `p → q` crosses a triangle
    /// (`p + t (q − p)` is the crossing), or `None` if it crosses none: where a ray from inside a
    /// closed surface leaves it.
    #[must_use]
    pub(crate) fn first_hit(&self, p: DVec3, q: DVec3) -> Option<f64> {
        let d = q - p;
        let mut best: Option<f64> = None;
        self.walk_segment(p, q, |t| {
            if let Some(s) = intersect(p, d, &self.corners(t)).filter(|&s| s > 0.0 && s <= 1.0) {
                best = Some(best.map_or(s, |b| b.min(s)));
            }
            // A box that the segment up to the best crossing so far misses holds no nearer one.
            ControlFlow::Continue(best.unwrap_or(1.0))
        });
        best
    }

    /// Calls `visit(triangle)` for every triangle of every leaf whose box the segment
    /// `p + s (q − p)`, `s ∈ [0, reach]`, meets, where `reach` starts at 1 and is what `visit`
    /// last returned (boxes beyond it hold nothing the caller still wants); `Break` stops the
    /// walk.
    fn walk_segment(&self, p: DVec3, q: DVec3, mut visit: impl FnMut(u32) -> ControlFlow<(), f64>) {
        if self.nodes.is_empty() {
            return;
        }
        let inv = (q - p).recip();
        let mut reach = 1.0;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(i) = stack.pop() {
            let node = self.nodes[i as usize];
            if !slab_hit(p, inv * (1.0 / reach), node.min, node.max) {
                continue;
            }
            if node.count > 0 {
                let (s, e) = (
                    node.start as usize,
                    node.start as usize + node.count as usize,
                );
                for &t in &self.order[s..e] {
                    match visit(t) {
                        ControlFlow::Continue(r) => reach = r,
                        ControlFlow::Break(()) => return,
                    }
                }
            } else {
                stack.push(node.start);
                stack.push(node.right);
            }
        }
    }
}

fn box_distance_squared(p: DVec3, node: &Node) -> f64 {
    let d = (node.min - p).max(p - node.max).max(DVec3::ZERO);
    d.length_squared()
}

/// Whether the segment `p + s·d`, `s ∈ [0, 1]`, meets the box (slab test; `inv = 1/d`).
fn slab_hit(p: DVec3, inv: DVec3, min: DVec3, max: DVec3) -> bool {
    let t0 = (min - p) * inv;
    let t1 = (max - p) * inv;
    // NaN appears for 0·∞ (segment parallel to and on a slab plane): treat it as inside.
    let lo = t0.min(t1);
    let hi = t0.max(t1);
    let enter = [lo.x, lo.y, lo.z, 0.0]
        .into_iter()
        .filter(|v| !v.is_nan())
        .fold(f64::NEG_INFINITY, f64::max);
    let exit = [hi.x, hi.y, hi.z, 1.0]
        .into_iter()
        .filter(|v| !v.is_nan())
        .fold(f64::INFINITY, f64::min);
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

    /// A point uniform in [-1, 1]³.
    fn random_point(rng: &mut ChaCha8Rng) -> DVec3 {
        DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
    }

    /// `n` separate triangles, each corner within `spread` (per axis) of a centre uniform in
    /// [-1, 1]³, and the generator that drew them, for the queries.
    fn random_soup(seed: u64, n: u32, spread: f64) -> (ChaCha8Rng, Vec<DVec3>, Vec<[u32; 3]>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut positions = Vec::new();
        for _ in 0..n {
            let c = random_point(&mut rng);
            for _ in 0..3 {
                positions.push(c + random_point(&mut rng) * spread);
            }
        }
        let triangles = (0..n).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        (rng, positions, triangles)
    }

    #[test]
    fn agrees_with_brute_force_on_random_soups() {
        // Small triangles scattered in a cube, so that some segments hit and some miss.
        let (mut rng, positions, triangles) = random_soup(7, 100, 0.2);
        let mut r = || random_point(&mut rng);
        let bvh = TriangleBvh::new_f64(&positions, &triangles);
        let mut hits = 0;
        for k in 0..500 {
            let (p, q) = (r(), r() * 0.3);
            let skip = (k % 300) as u32;
            let brute = triangles.iter().any(|t| {
                !t.contains(&skip)
                    && intersect(p, q - p, &t.map(|v| positions[v as usize]))
                        .is_some_and(|s| s > 1e-9 && s <= 1.0)
            });
            assert_eq!(bvh.segment_hits(p, q, 1e-9, skip), brute, "query {k}");
            hits += usize::from(brute);
        }
        // The check is meaningful only if both outcomes occur.
        assert!(hits > 20 && hits < 480, "{hits}");
    }

    #[test]
    fn first_hit_is_the_nearest_crossing_of_brute_force() {
        let (mut rng, positions, triangles) = random_soup(11, 200, 0.3);
        let mut r = || random_point(&mut rng);
        let bvh = TriangleBvh::new_f64(&positions, &triangles);
        let (mut hits, mut several) = (0, 0);
        for k in 0..500 {
            let (p, q) = (r(), r() * 1.5);
            let crossings: Vec<f64> = triangles
                .iter()
                .filter_map(|t| {
                    intersect(p, q - p, &t.map(|v| positions[v as usize]))
                        .filter(|&s| s > 0.0 && s <= 1.0)
                })
                .collect();
            let brute = crossings.iter().copied().reduce(f64::min);
            assert_eq!(bvh.first_hit(p, q), brute, "query {k}");
            hits += usize::from(brute.is_some());
            several += usize::from(crossings.len() > 1);
        }
        // Meaningful only if segments miss, hit once and hit several triangles.
        assert!(hits > 50 && hits < 450 && several > 20, "{hits} {several}");
        assert_eq!(
            TriangleBvh::new(&[], &[]).first_hit(DVec3::ZERO, DVec3::X),
            None
        );
    }

    #[test]
    fn axis_aligned_segment_through_a_square() {
        let p = [
            DVec3::new(-1.0, 0.0, -1.0),
            DVec3::new(1.0, 0.0, -1.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(-1.0, 0.0, 1.0),
        ];
        let bvh = TriangleBvh::new_f64(&p, &[[0, 1, 2], [0, 2, 3]]);
        assert!(bvh.segment_hits(
            DVec3::new(0.3, 1.0, 0.2),
            DVec3::new(0.3, -1.0, 0.2),
            1e-9,
            u32::MAX
        ));
        assert!(!bvh.segment_hits(
            DVec3::new(0.3, 1.0, 0.2),
            DVec3::new(0.3, 0.5, 0.2),
            1e-9,
            u32::MAX
        ));
        assert!(!bvh.segment_hits(
            DVec3::new(3.0, 1.0, 0.2),
            DVec3::new(3.0, -1.0, 0.2),
            1e-9,
            u32::MAX
        ));
        // Starting on the square and skipping its corner 0 still sees triangle [0, 1, 2]: skipped.
        assert!(!bvh.segment_hits(
            DVec3::new(-0.5, 0.0, -0.6),
            DVec3::new(-0.5, -1.0, -0.6),
            1e-9,
            0
        ));
    }
}
