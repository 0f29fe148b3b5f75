//! The outline of the posed mesh as a camera sees it: silhouette edges (between a triangle that
//! faces the camera and one that faces away, or on an open border such as a skirt's hem) that
//! lie on the outline of the projected mesh, i.e. are not hidden behind another part.
//!
//! "On the outline" is decided exactly rather than on a rendered mask: a silhouette edge (or
//! vertex) is on it when a point a twentieth of a pixel beyond it, away from the triangles it
//! borders, is covered by no projected triangle. A test on a pixel-sampled mask cannot tell a
//! vertex on the outline from one a pixel inside it, and the latter, pulled outwards by the
//! boundary term, biased the loss's minimum outwards by a fifth of a pixel on the built-in
//! capture.

use glam::{Vec2, Vec3};
use skinfield_formats::Camera;

/// No second triangle: a border edge of an open surface.
pub(crate) const BORDER: u32 = u32::MAX;

/// Every edge of a triangle mesh once, with its one or two triangles.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EdgeTable {
    /// Vertex pairs, smaller index first.
    pub edges: Vec<[u32; 2]>,
    /// The triangles on either side (`[t, BORDER]` on a border). Edges shared by more than two
    /// triangles (non-manifold) keep the first two.
    pub faces: Vec<[u32; 2]>,
}

impl EdgeTable {
    /// Builds the table (triangles with repeated or out-of-range vertices are skipped).
    #[must_use]
    pub fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        let mut keyed: Vec<(u32, u32, u32)> = Vec::with_capacity(3 * triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            if tri.iter().any(|&i| i as usize >= vertex_count)
                || tri[0] == tri[1]
                || tri[1] == tri[2]
                || tri[0] == tri[2]
            {
                continue;
            }
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                keyed.push((a.min(b), a.max(b), t as u32));
            }
        }
        keyed.sort_unstable();
        let mut edges = Vec::new();
        let mut faces = Vec::new();
        for run in keyed.chunk_by(|x, y| x.0 == y.0 && x.1 == y.1) {
            edges.push([run[0].0, run[0].1]);
            faces.push([run[0].2, run.get(1).map_or(BORDER, |r| r.2)]);
        }
        Self { edges, faces }
    }
}

/// One view of the posed mesh: projections, validity, and the rendered coverage used to decide
/// which silhouette edges are on the outline.
pub(crate) struct ViewGeometry {
    /// Projected vertices (pixels); meaningless where `valid` is false.
    pub uv: Vec<Vec2>,
    /// In front of the camera.
    pub valid: Vec<bool>,
}

impl ViewGeometry {
    pub(crate) fn new(camera: &Camera, positions: &[Vec3]) -> Self {
        let mut uv = Vec::with_capacity(positions.len());
        let mut valid = Vec::with_capacity(positions.len());
        for &p in positions {
            match camera.project(p) {
                Some(q) if q.is_finite() => {
                    uv.push(q);
                    valid.push(true);
                }
                _ => {
                    uv.push(Vec2::ZERO);
                    valid.push(false);
                }
            }
        }
        Self { uv, valid }
    }
}

/// How far beyond an edge the "is it covered?" probe looks (pixels).
const PROBE_PX: f32 = 0.05;

/// Point-in-any-triangle queries over projected triangles, with a uniform grid.
struct TriangleGrid<'a> {
    uv: &'a [Vec2],
    triangles: Vec<[u32; 3]>,
    origin: Vec2,
    cell: f32,
    dims: [i64; 2],
    start: Vec<usize>,
    items: Vec<u32>,
}

impl<'a> TriangleGrid<'a> {
    fn new(uv: &'a [Vec2], valid: &[bool], triangles: &[[u32; 3]]) -> Self {
        let triangles: Vec<[u32; 3]> = triangles
            .iter()
            .filter(|t| {
                t.iter()
                    .all(|&i| valid.get(i as usize).copied().unwrap_or(false))
            })
            .copied()
            .collect();
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for t in &triangles {
            for &i in t {
                lo = lo.min(uv[i as usize]);
                hi = hi.max(uv[i as usize]);
            }
        }
        if triangles.is_empty() {
            (lo, hi) = (Vec2::ZERO, Vec2::ZERO);
        }
        let extent = (hi - lo).max_element().max(1e-3);
        let side = ((triangles.len() as f32).sqrt().ceil()).clamp(1.0, 512.0);
        let cell = extent / side + 1e-4;
        let dims = [
            ((hi.x - lo.x) / cell) as i64 + 1,
            ((hi.y - lo.y) / cell) as i64 + 1,
        ];
        // Offsets from the minimum are ≥ 0, so truncating is flooring (and cheaper: `floor`
        // is a call into libm, and this runs for every triangle of every view).
        let range = |t: &[u32; 3]| {
            let (mut a, mut b) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
            for &i in t {
                a = a.min(uv[i as usize]);
                b = b.max(uv[i as usize]);
            }
            let a = (a - lo) / cell;
            let b = (b - lo) / cell;
            (a.x as i64, a.y as i64, b.x as i64, b.y as i64)
        };
        let (start, items) = super::cell_lists(&triangles, dims, range);
        Self {
            uv,
            triangles,
            origin: lo,
            cell,
            dims,
            start,
            items,
        }
    }

    /// Whether `p` is strictly inside some projected triangle (either winding).
    fn covers(&self, p: Vec2) -> bool {
        let c = (p - self.origin) / self.cell;
        // Left of or above the grid (truncation below would round -0.5 up to cell 0).
        if c.x < 0.0 || c.y < 0.0 {
            return false;
        }
        let (x, y) = (c.x as i64, c.y as i64);
        if x >= self.dims[0] || y >= self.dims[1] {
            return false;
        }
        let cell = (y * self.dims[0] + x) as usize;
        self.items[self.start[cell]..self.start[cell + 1]]
            .iter()
            .any(|&k| {
                let [a, b, c] = self.triangles[k as usize].map(|i| self.uv[i as usize]);
                let e = |p0: Vec2, p1: Vec2| (p1 - p0).perp_dot(p - p0);
                let (d0, d1, d2) = (e(a, b), e(b, c), e(c, a));
                (d0 > 0.0 && d1 > 0.0 && d2 > 0.0) || (d0 < 0.0 && d1 < 0.0 && d2 < 0.0)
            })
    }
}

/// The parts of the mesh on its projected outline: edge indices into the [`EdgeTable`], and the
/// vertices (sorted).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct MeshOutline {
    pub edges: Vec<u32>,
    pub vertices: Vec<u32>,
}

/// Adds 1 to `counts[i]` for every vertex `i` on the projected outline ([`mesh_outline`]) of the
/// posed mesh (`positions`, `triangles`, edge table `table`) seen by each of `cameras`: how many
/// views could show a silhouette term that vertex.
pub(crate) fn count_outline_views<'a>(
    counts: &mut [u32],
    cameras: impl IntoIterator<Item = &'a Camera>,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    table: &EdgeTable,
) {
    for camera in cameras {
        let view = ViewGeometry::new(camera, positions);
        for i in mesh_outline(camera, positions, triangles, table, &view).vertices {
            counts[i as usize] += 1;
        }
    }
}

/// The silhouette edges of the posed mesh seen by `camera`, and their ends, that are on the
/// projected outline (see the module docs).
pub(crate) fn mesh_outline(
    camera: &Camera,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    table: &EdgeTable,
    view: &ViewGeometry,
) -> MeshOutline {
    let eye = camera.center();
    let facing: Vec<bool> = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::NAN));
            (b - a).cross(c - a).dot(a - eye) < 0.0
        })
        .collect();
    let grid = TriangleGrid::new(&view.uv, &view.valid, triangles);
    let mut outward = vec![Vec2::ZERO; positions.len()];
    let mut edges = Vec::new();
    for (k, (e, f)) in table.edges.iter().zip(&table.faces).enumerate() {
        let silhouette = f[1] == BORDER || facing[f[0] as usize] != facing[f[1] as usize];
        let [i, j] = e.map(|v| v as usize);
        if !silhouette || !view.valid[i] || !view.valid[j] {
            continue;
        }
        let (a, b) = (view.uv[i], view.uv[j]);
        // Away from the first face's third vertex (at a fold both faces lie on the same side).
        let third = triangles[f[0] as usize]
            .iter()
            .map(|&v| v as usize)
            .find(|&v| v != i && v != j)
            .unwrap_or(i);
        if !view.valid[third] {
            continue;
        }
        let mut n = (b - a).perp().normalize_or_zero();
        if n.dot(view.uv[third] - a) > 0.0 {
            n = -n;
        }
        outward[i] += n;
        outward[j] += n;
        if !grid.covers((a + b) * 0.5 + n * PROBE_PX) {
            edges.push(k as u32);
        }
    }
    let mut vertices: Vec<u32> = edges
        .iter()
        .flat_map(|&k| table.edges[k as usize])
        .collect();
    vertices.sort_unstable();
    vertices.dedup();
    vertices.retain(|&v| {
        let n = outward[v as usize].normalize_or_zero();
        n != Vec2::ZERO && !grid.covers(view.uv[v as usize] + n * PROBE_PX)
    });
    MeshOutline { edges, vertices }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tetrahedron_has_six_interior_edges_and_an_open_quad_four_borders() {
        let tet = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let t = EdgeTable::new(4, &tet);
        assert_eq!(t.edges.len(), 6);
        assert!(t.faces.iter().all(|f| f[1] != BORDER));
        let quad = [[0, 1, 2], [0, 2, 3], [0, 0, 1], [0, 1, 9]];
        let q = EdgeTable::new(4, &quad);
        assert_eq!(q.edges, vec![[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]);
        let borders = q.faces.iter().filter(|f| f[1] == BORDER).count();
        assert_eq!(borders, 4, "the diagonal is interior, the rim is border");
    }

    #[test]
    fn the_probe_sees_triangles_of_either_winding_and_nothing_outside() {
        let uv = [
            Vec2::new(0.0, 0.0),
            Vec2::new(4.0, 0.0),
            Vec2::new(0.0, 4.0),
            Vec2::new(10.0, 10.0),
            Vec2::new(12.0, 10.0),
            Vec2::new(10.0, 12.0),
        ];
        let grid = TriangleGrid::new(&uv, &[true; 6], &[[0, 1, 2], [3, 5, 4]]);
        assert!(grid.covers(Vec2::new(1.0, 1.0)));
        assert!(grid.covers(Vec2::new(10.5, 10.5)));
        assert!(!grid.covers(Vec2::new(3.0, 3.0)));
        assert!(!grid.covers(Vec2::new(-1.0, 1.0)));
        assert!(!grid.covers(Vec2::new(50.0, 1.0)));
        // A triangle with a vertex behind the camera is not drawn.
        let grid = TriangleGrid::new(&uv, &[false, true, true, true, true, true], &[[0, 1, 2]]);
        assert!(!grid.covers(Vec2::new(1.0, 1.0)));
    }
}
