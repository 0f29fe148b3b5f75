//! Welding by position, clean-up of degenerate and duplicate triangles, and connected components.
//!
//! Real meshes are split at UV and normal seams, so the same surface point appears as several
//! vertices. Heat must flow across those seams, so the solve runs on a welded copy: vertices
//! within `tolerance` of an earlier representative merge into it, and every file vertex maps to
//! its welded vertex so the result can be copied back.

use std::collections::{HashMap, HashSet};

use glam::{DVec3, Vec3};

/// A welded triangle mesh in `f64`.
#[derive(Clone, Debug)]
pub(crate) struct Welded {
    /// Positions of the welded vertices.
    pub positions: Vec<DVec3>,
    /// Triangles over welded vertices: no repeated corner, no duplicate (in any orientation).
    pub triangles: Vec<[u32; 3]>,
    /// Welded vertex of every input vertex.
    pub of_input: Vec<u32>,
    /// Input vertex each welded vertex was made from (the first of its copies; the others
    /// merged into it).
    pub representative: Vec<u32>,
    /// Triangles that collapsed (two corners welded together) and were dropped.
    pub collapsed_triangles: usize,
    /// Triangles that repeated an earlier one (same three welded corners) and were dropped.
    pub duplicate_triangles: usize,
}

/// Welds `positions` closer than `tolerance` (an absolute distance; `0` welds exact copies only)
/// and re-indexes `triangles`, dropping the collapsed and the duplicated ones.
///
/// A grid of cell size `tolerance` finds candidates: a vertex merges into the first earlier
/// representative within `tolerance` in its own or a neighbouring cell, so the result depends
/// only on the input order and is reproducible.
#[must_use]
pub(crate) fn weld(positions: &[Vec3], triangles: &[[u32; 3]], tolerance: f64) -> Welded {
    // The cell only buckets candidates; the distance test below decides, so any positive size
    // is correct (a floor keeps exact welding, tolerance 0, from overflowing the keys).
    let cell = tolerance.max(1e-12);
    let key = |p: DVec3| -> [i64; 3] { (p / cell).floor().as_i64vec3().to_array() };
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::with_capacity(positions.len());
    let mut welded: Vec<DVec3> = Vec::with_capacity(positions.len());
    let mut of_input = Vec::with_capacity(positions.len());
    let tol2 = tolerance * tolerance;
    let mut representative = Vec::new();
    for (i, p) in positions.iter().enumerate() {
        let p = p.as_dvec3();
        let k = key(p);
        let mut found = None;
        'search: for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let kk = [
                        k[0].wrapping_add(dx),
                        k[1].wrapping_add(dy),
                        k[2].wrapping_add(dz),
                    ];
                    if let Some(list) = grid.get(&kk) {
                        for &w in list {
                            if welded[w as usize].distance_squared(p) <= tol2 {
                                found = Some(w);
                                break 'search;
                            }
                        }
                    }
                }
            }
        }
        let w = found.unwrap_or_else(|| {
            let w = welded.len() as u32;
            welded.push(p);
            representative.push(i as u32);
            grid.entry(k).or_default().push(w);
            w
        });
        of_input.push(w);
    }
    let mut seen = HashSet::with_capacity(triangles.len());
    let (mut collapsed, mut duplicate) = (0, 0);
    let mut tris = Vec::with_capacity(triangles.len());
    for t in triangles {
        let t = t.map(|v| of_input[v as usize]);
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            collapsed += 1;
            continue;
        }
        let mut s = t;
        s.sort_unstable();
        if !seen.insert(s) {
            duplicate += 1;
            continue;
        }
        tris.push(t);
    }
    Welded {
        positions: welded,
        triangles: tris,
        of_input,
        representative,
        collapsed_triangles: collapsed,
        duplicate_triangles: duplicate,
    }
}

/// Connected components of the graph whose edges are the triangles flagged in `used`:
/// the component of every vertex (`u32::MAX` for a vertex in no used triangle) and their count.
#[must_use]
pub(crate) fn components(
    vertices: usize,
    triangles: &[[u32; 3]],
    used: &[bool],
) -> (Vec<u32>, usize) {
    let mut parent: Vec<u32> = (0..vertices as u32).collect();
    fn find(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            // Path halving keeps the trees shallow without recursion.
            parent[v as usize] = parent[parent[v as usize] as usize];
            v = parent[v as usize];
        }
        v
    }
    let mut touched = vec![false; vertices];
    for (t, &u) in triangles.iter().zip(used) {
        if !u {
            continue;
        }
        for &v in t {
            touched[v as usize] = true;
        }
        let r0 = find(&mut parent, t[0]);
        for &v in &t[1..] {
            let r = find(&mut parent, v);
            if r != r0 {
                let (lo, hi) = if r < r0 { (r, r0) } else { (r0, r) };
                parent[hi as usize] = lo;
            }
        }
    }
    let mut label = vec![u32::MAX; vertices];
    let mut of_root: HashMap<u32, u32> = HashMap::new();
    for v in 0..vertices {
        if touched[v] {
            let r = find(&mut parent, v as u32);
            let next = of_root.len() as u32;
            label[v] = *of_root.entry(r).or_insert(next);
        }
    }
    (label, of_root.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welds_seams_and_drops_collapsed_and_duplicate_triangles() {
        // Two triangles sharing an edge, stored unwelded, plus a copy of the first (reversed),
        // plus one that collapses once welded.
        let p = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::X + Vec3::splat(1e-7),
            Vec3::Y,
            Vec3::ONE,
            Vec3::new(0.0, 1e-8, 0.0),
        ];
        let t = [[0, 1, 2], [3, 5, 4], [2, 1, 0], [0, 6, 1]];
        let w = weld(&p, &t, 1e-5);
        assert_eq!(w.positions.len(), 4);
        assert_eq!(w.of_input, vec![0, 1, 2, 1, 2, 3, 0]);
        // Each welded vertex comes from the first of its copies.
        assert_eq!(w.representative, vec![0, 1, 2, 5]);
        assert_eq!(w.triangles, vec![[0, 1, 2], [1, 3, 2]]);
        assert_eq!((w.collapsed_triangles, w.duplicate_triangles), (1, 1));
        // Exact welding keeps the 1e-7 offset apart.
        assert_eq!(weld(&p, &t, 0.0).positions.len(), 6);
    }

    #[test]
    fn counts_components_and_leaves_isolated_vertices_unlabelled() {
        let t = [[0, 1, 2], [2, 3, 0], [4, 5, 6], [7, 8, 9]];
        let (label, n) = components(11, &t, &[true, true, true, false]);
        assert_eq!(n, 2);
        assert_eq!(&label[..4], &[0, 0, 0, 0]);
        assert_eq!(&label[4..7], &[1, 1, 1]);
        assert!(label[7..].iter().all(|&l| l == u32::MAX));
    }
}
