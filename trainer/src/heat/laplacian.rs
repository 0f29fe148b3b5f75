//! Cotangent stiffness matrix and mixed Voronoi vertex areas (Meyer, Desbrun, Schröder & Barr
//! 2003) of a welded triangle mesh.
//!
//! The discrete Laplace–Beltrami operator used by the heat solve is the area-normalised form
//!
//! ```text
//! (Δu)_i = 1/A_i · Σ_j ½ (cot α_ij + cot β_ij) (u_j − u_i)      i.e.  Δ = −M⁻¹ K
//! ```
//!
//! where `α_ij`, `β_ij` are the angles opposite edge `ij` in its (one or more) triangles, `A_i`
//! is the mixed Voronoi area of vertex `i` (Voronoi area of each non-obtuse incident triangle;
//! half the triangle's area at an obtuse corner, a quarter at the other two corners of an obtuse
//! triangle), `M = diag(A)` and `K` the symmetric positive semi-definite stiffness matrix
//! `K_ij = −½ (cot α_ij + cot β_ij)`, `K_ii = −Σ_{j≠i} K_ij`.
//!
//! Negative cotangents (obtuse angles) are kept: `K` is the exact P1 finite-element stiffness
//! matrix, positive semi-definite for any non-degenerate triangle whatever its angles, with the
//! constants on each connected component as its null space. Clamping them would change the
//! operator; the weights' possible undershoot below zero is clamped after the solve instead.
//! Triangles that are degenerate (area below `DEGENERATE_RATIO` times their longest edge
//! squared, where cotangents blow up) contribute neither stiffness nor area.

use glam::DVec3;

/// A triangle whose doubled area is below this times its longest edge squared is degenerate
/// (its smallest angle is below about 1e-8 rad; its cotangents would be around 1e8).
pub(crate) const DEGENERATE_RATIO: f64 = 1e-8;

/// Stiffness entries, vertex areas and which triangles took part.
#[derive(Clone, Debug)]
pub(crate) struct Stiffness {
    /// Off-diagonal edge weights `½ (cot α + cot β)` summed over triangles, `(i, j, w)` with
    /// `i > j`, sorted and merged (one entry per edge).
    pub edges: Vec<(u32, u32, f64)>,
    /// Mixed Voronoi area of every vertex (0 for a vertex in no used triangle).
    pub area: Vec<f64>,
    /// Whether each triangle contributed (false: degenerate).
    pub used: Vec<bool>,
}

/// Builds the cotangent stiffness and mixed Voronoi areas of `triangles` over `positions`.
#[must_use]
pub(crate) fn cotangent_stiffness(positions: &[DVec3], triangles: &[[u32; 3]]) -> Stiffness {
    let mut area = vec![0.0; positions.len()];
    let mut used = vec![false; triangles.len()];
    let mut entries: Vec<(u32, u32, f64)> = Vec::with_capacity(3 * triangles.len());
    for (t, tri) in triangles.iter().enumerate() {
        let p = tri.map(|v| positions[v as usize]);
        // e[k] is the edge opposite corner k.
        let e = [p[2] - p[1], p[0] - p[2], p[1] - p[0]];
        let l2 = e.map(|e| e.length_squared());
        let double_area = e[0].cross(e[1]).length();
        let longest = l2[0].max(l2[1]).max(l2[2]);
        if !(double_area > DEGENERATE_RATIO * longest) {
            continue;
        }
        used[t] = true;
        // cot at corner k = (a · b) / |a × b| with a, b the edges leaving corner k.
        let cot = [0, 1, 2].map(|k| {
            let a = p[(k + 1) % 3] - p[k];
            let b = p[(k + 2) % 3] - p[k];
            a.dot(b) / double_area
        });
        for k in 0..3 {
            let (i, j) = (tri[(k + 1) % 3], tri[(k + 2) % 3]);
            let w = 0.5 * cot[k];
            entries.push((i.max(j), i.min(j), w));
        }
        let tri_area = 0.5 * double_area;
        let obtuse = (0..3).find(|&k| cot[k] < 0.0);
        for k in 0..3 {
            area[tri[k] as usize] += match obtuse {
                None => {
                    // Voronoi region of corner k: the two edges at k, each with the cotangent of
                    // the angle opposite it.
                    let (k1, k2) = ((k + 1) % 3, (k + 2) % 3);
                    (l2[k2] * cot[k2] + l2[k1] * cot[k1]) / 8.0
                }
                Some(o) if o == k => tri_area / 2.0,
                Some(_) => tri_area / 4.0,
            };
        }
    }
    entries.sort_unstable_by_key(|&(i, j, _)| (i, j));
    let mut edges: Vec<(u32, u32, f64)> = Vec::with_capacity(entries.len() / 2 + 1);
    for (i, j, w) in entries {
        match edges.last_mut() {
            Some(last) if last.0 == i && last.1 == j => last.2 += w,
            _ => edges.push((i, j, w)),
        }
    }
    Stiffness { edges, area, used }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dense `K` from the edge list.
    fn dense(s: &Stiffness, n: usize) -> Vec<Vec<f64>> {
        let mut k = vec![vec![0.0; n]; n];
        for &(i, j, w) in &s.edges {
            let (i, j) = (i as usize, j as usize);
            k[i][j] -= w;
            k[j][i] -= w;
            k[i][i] += w;
            k[j][j] += w;
        }
        k
    }

    #[test]
    fn right_isoceles_triangle_matches_hand_values() {
        // Right angle at vertex 0: cot 0 there, cot 1 at the two 45° corners.
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let s = cotangent_stiffness(&p, &[[0, 1, 2]]);
        let w = |a: u32, b: u32| s.edges.iter().find(|e| (e.0, e.1) == (a.max(b), a.min(b))).unwrap().2;
        assert!((w(1, 2) - 0.0).abs() < 1e-12);
        assert!((w(0, 1) - 0.5).abs() < 1e-12);
        assert!((w(0, 2) - 0.5).abs() < 1e-12);
        // Non-obtuse: Voronoi areas; the right-angle corner gets a quarter of 0.5 + ... : the
        // circumcentre is the hypotenuse midpoint, so corner 0 gets 1/4 and corners 1, 2 get 1/8.
        assert!((s.area[0] - 0.25).abs() < 1e-12, "{:?}", s.area);
        assert!((s.area[1] - 0.125).abs() < 1e-12);
        assert!((s.area[2] - 0.125).abs() < 1e-12);
    }

    #[test]
    fn areas_sum_to_the_surface_area_and_linear_functions_are_harmonic_inside() {
        // A 4x4 grid of unit squares with jittered interior vertices and an obtuse triangle or two.
        let n = 5;
        let mut p = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let interior = x > 0 && y > 0 && x < n - 1 && y < n - 1;
                let j = if interior { 0.3 * (((x * 7 + y * 3) % 5) as f64 / 4.0 - 0.5) } else { 0.0 };
                p.push(DVec3::new(x as f64 + j, y as f64 - j, 0.0));
            }
        }
        let mut t = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let v = (y * n + x) as u32;
                let (a, b, c, d) = (v, v + 1, v + n as u32 + 1, v + n as u32);
                t.push([a, b, c]);
                t.push([a, c, d]);
            }
        }
        let s = cotangent_stiffness(&p, &t);
        let total: f64 = t.iter().map(|t| 0.5 * (p[t[1] as usize] - p[t[0] as usize]).cross(p[t[2] as usize] - p[t[0] as usize]).length()).sum();
        assert!((s.area.iter().sum::<f64>() - total).abs() < 1e-9);
        // The cotangent Laplacian reproduces linear functions exactly at interior vertices
        // (K u = 0 there for u = a·x + b·y + c), on any planar triangulation.
        let k = dense(&s, p.len());
        let u: Vec<f64> = p.iter().map(|q| 0.7 * q.x - 1.3 * q.y + 2.0).collect();
        for y in 1..n - 1 {
            for x in 1..n - 1 {
                let i = y * n + x;
                let ku: f64 = (0..p.len()).map(|j| k[i][j] * u[j]).sum();
                assert!(ku.abs() < 1e-9, "vertex {i}: {ku}");
            }
        }
        // Rows sum to zero (constants are in the null space).
        for row in &k {
            assert!(row.iter().sum::<f64>().abs() < 1e-9);
        }
    }

    #[test]
    fn degenerate_triangles_contribute_nothing() {
        let p = [DVec3::ZERO, DVec3::X, DVec3::new(2.0, 0.0, 0.0), DVec3::X];
        let s = cotangent_stiffness(&p, &[[0, 1, 2], [0, 1, 3]]);
        assert!(s.edges.is_empty());
        assert!(s.area.iter().all(|&a| a == 0.0));
        assert_eq!(s.used, vec![false, false]);
    }
}
