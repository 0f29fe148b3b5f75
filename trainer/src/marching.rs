//! Marching tetrahedra: the zero level set of a scalar field sampled on a regular grid, as a
//! welded, outward-oriented triangle mesh.
//!
//! Each grid cube is split into six tetrahedra around its main diagonal (the same split in
//! every cube, so the face diagonals of neighbouring cubes agree and the surface has no
//! cracks). This is the table-free variant of marching cubes: it has no ambiguous cases, at the
//! price of about twice as many (thinner) triangles, which the simplifier then removes.

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

/// The six tetrahedra of a cube, as corner indices `x + 2y + 4z`, all sharing the 0–7 diagonal.
const TETS: [[usize; 4]; 6] = [
    [0, 1, 3, 7],
    [0, 3, 2, 7],
    [0, 2, 6, 7],
    [0, 6, 4, 7],
    [0, 4, 5, 7],
    [0, 5, 1, 7],
];

/// Meshes `{p : f(p) = 0}` inside the box `[min, max]` with cubes of side `cell`; `f` is
/// negative inside. Returns positions and counter-clockwise (seen from outside) triangles.
pub fn marching_tetrahedra(
    f: impl Fn(Vec3) -> f32 + Sync,
    min: Vec3,
    max: Vec3,
    cell: f32,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let dims = ((max - min) / cell).ceil().as_uvec3() + 1;
    let (nx, ny, nz) = (dims.x as usize, dims.y as usize, dims.z as usize);
    let point = |x: usize, y: usize, z: usize| min + Vec3::new(x as f32, y as f32, z as f32) * cell;
    let mut values = vec![0.0f32; nx * ny * nz];
    values
        .par_chunks_mut(nx * ny)
        .enumerate()
        .for_each(|(z, slab)| {
            for y in 0..ny {
                for x in 0..nx {
                    let v = f(point(x, y, z));
                    // An exact zero would put a vertex on a grid point shared by several edges;
                    // nudging it outside keeps every vertex on exactly one edge.
                    slab[y * nx + x] = if v == 0.0 { 1e-9 } else { v };
                }
            }
        });
    let id = |x: usize, y: usize, z: usize| (z * ny + y) * nx + x;
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    for z in 0..nz - 1 {
        for y in 0..ny - 1 {
            for x in 0..nx - 1 {
                let corner_ids: [usize; 8] =
                    std::array::from_fn(|c| id(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2)));
                let vals = corner_ids.map(|i| values[i]);
                let inside = vals.iter().filter(|v| **v < 0.0).count();
                if inside == 0 || inside == 8 {
                    continue;
                }
                let corner_pos: [Vec3; 8] =
                    std::array::from_fn(|c| point(x + (c & 1), y + ((c >> 1) & 1), z + (c >> 2)));
                for tet in TETS {
                    let (ins, outs): (Vec<usize>, Vec<usize>) =
                        tet.iter().partition(|&&c| vals[c] < 0.0);
                    if ins.is_empty() || outs.is_empty() {
                        continue;
                    }
                    let mut vertex = |a: usize, b: usize| -> (u32, Vec3) {
                        let (ia, ib) = (corner_ids[a], corner_ids[b]);
                        let key = (ia.min(ib), ia.max(ib));
                        let id = *edge_vertex.entry(key).or_insert_with(|| {
                            let t = vals[a] / (vals[a] - vals[b]);
                            positions.push(corner_pos[a] + (corner_pos[b] - corner_pos[a]) * t);
                            (positions.len() - 1) as u32
                        });
                        (id, (corner_pos[a] + corner_pos[b]) * 0.5)
                    };
                    let polygon: Vec<(u32, Vec3)> = match (ins.len(), outs.len()) {
                        (1, 3) => outs.iter().map(|&o| vertex(ins[0], o)).collect(),
                        (3, 1) => ins.iter().map(|&i| vertex(i, outs[0])).collect(),
                        // Two in, two out: a quad whose corners go round the tetrahedron.
                        _ => vec![
                            vertex(ins[0], outs[0]),
                            vertex(ins[0], outs[1]),
                            vertex(ins[1], outs[1]),
                            vertex(ins[1], outs[0]),
                        ],
                    };
                    let outward = outs.iter().map(|&o| corner_pos[o]).sum::<Vec3>()
                        / outs.len() as f32
                        - ins.iter().map(|&i| corner_pos[i]).sum::<Vec3>() / ins.len() as f32;
                    for k in 1..polygon.len() - 1 {
                        let (a, b, c) = (polygon[0], polygon[k], polygon[k + 1]);
                        // Orientation is decided on the edge midpoints, where the triangle is
                        // well shaped; sliding the vertices along their edges to the actual
                        // crossings cannot flip it (they never become collinear), whereas the
                        // actual triangle can be a sliver whose normal is all rounding error.
                        let flip = (b.1 - a.1).cross(c.1 - a.1).dot(outward) < 0.0;
                        let t = if flip {
                            [a.0, c.0, b.0]
                        } else {
                            [a.0, b.0, c.0]
                        };
                        triangles.push(t);
                    }
                }
            }
        }
    }
    (positions, triangles)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_is_closed_outward_and_on_the_level_set() {
        let r = 0.5;
        let (p, t) = marching_tetrahedra(
            |q| q.length() - r,
            Vec3::splat(-0.7),
            Vec3::splat(0.7),
            0.05,
        );
        // On the surface to within the linear interpolation error of one cell.
        assert!(p.iter().all(|q| (q.length() - r).abs() < 0.01));
        // Closed: every edge is shared by exactly two triangles, in opposite directions.
        let mut edges = HashMap::new();
        for tri in &t {
            for k in 0..3 {
                *edges.entry((tri[k], tri[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        assert!(
            edges
                .iter()
                .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
        );
        // Outward: the enclosed volume (divergence theorem) is positive and near 4/3 π r³.
        let vol: f32 = t
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|i| p[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        let want = 4.0 / 3.0 * std::f32::consts::PI * r * r * r;
        assert!((vol - want).abs() < 0.03 * want, "{vol} vs {want}");
    }
}
