//! Cleaning a meshed hull: keep the largest connected piece, drop unused vertices, and the
//! topology checks the tests and the report use (closedness, Euler characteristic).

use std::collections::HashMap;

use glam::Vec3;

/// Keeps the connected component with the most triangles (a visual hull from few cameras can
/// have small detached "ghost" pieces where the silhouette cones of different limbs cross) and
/// renumbers its vertices in first-use order.
#[must_use]
pub fn largest_component(positions: &[Vec3], triangles: &[[u32; 3]]) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut parent: Vec<u32> = (0..positions.len() as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            parent[i as usize] = parent[parent[i as usize] as usize];
            i = parent[i as usize];
        }
        i
    }
    for t in triangles {
        for k in 1..3 {
            let (a, b) = (find(&mut parent, t[0]), find(&mut parent, t[k]));
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut size: HashMap<u32, usize> = HashMap::new();
    let roots: Vec<u32> = triangles.iter().map(|t| find(&mut parent, t[0])).collect();
    for &r in &roots {
        *size.entry(r).or_default() += 1;
    }
    // Ties go to the smaller root, so the result does not depend on the map's order.
    let Some(keep) = size
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
        .map(|(&r, _)| r)
    else {
        return (Vec::new(), Vec::new());
    };
    let mut remap = vec![u32::MAX; positions.len()];
    let mut kept = Vec::new();
    let mut out = Vec::new();
    for (t, &r) in triangles.iter().zip(&roots) {
        if r != keep {
            continue;
        }
        out.push(t.map(|i| {
            if remap[i as usize] == u32::MAX {
                remap[i as usize] = kept.len() as u32;
                kept.push(positions[i as usize]);
            }
            remap[i as usize]
        }));
    }
    (kept, out)
}

/// True when every directed edge appears once and its reverse once: a closed, consistently
/// oriented, edge-manifold surface.
#[must_use]
pub fn is_closed(triangles: &[[u32; 3]]) -> bool {
    !triangles.is_empty() && unpaired_edge_vertices(triangles).is_empty()
}

/// The vertices of every directed edge that is not matched by exactly one reverse edge (open
/// borders, pinches where four triangles share an edge), sorted and without repeats.
#[must_use]
pub fn unpaired_edge_vertices(triangles: &[[u32; 3]]) -> Vec<u32> {
    let edges = directed_edges(triangles);
    let mut out: Vec<u32> = edges
        .iter()
        .filter(|&(&(a, b), &n)| n != 1 || edges.get(&(b, a)) != Some(&1))
        .flat_map(|(&(a, b), _)| [a, b])
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

fn directed_edges(triangles: &[[u32; 3]]) -> HashMap<(u32, u32), u32> {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    edges
}

/// Euler characteristic `V − E + F` of the referenced vertices: 2 for a sphere, 0 for a torus,
/// `2 − 2g` for a closed surface of genus `g`.
#[must_use]
pub fn euler_characteristic(triangles: &[[u32; 3]]) -> i64 {
    let mut vertices = std::collections::HashSet::new();
    let mut edges = std::collections::HashSet::new();
    for t in triangles {
        for k in 0..3 {
            vertices.insert(t[k]);
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edges.insert((a.min(b), a.max(b)));
        }
    }
    vertices.len() as i64 - edges.len() as i64 + triangles.len() as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed tetrahedron with vertex offset `o`.
    fn tetrahedron(o: u32) -> Vec<[u32; 3]> {
        vec![
            [o, o + 2, o + 1],
            [o, o + 1, o + 3],
            [o + 1, o + 2, o + 3],
            [o + 2, o, o + 3],
        ]
    }

    #[test]
    fn the_biggest_piece_is_kept_and_renumbered() {
        let positions: Vec<Vec3> = (0..9).map(|i| Vec3::splat(i as f32)).collect();
        // A lone triangle (vertices 4..7) before a tetrahedron (0..4).
        let mut triangles = vec![[4, 5, 6]];
        triangles.extend(tetrahedron(0));
        let (p, t) = largest_component(&positions, &triangles);
        // First-use order: the first triangle [0, 2, 1], then vertex 3.
        assert_eq!(p, [0, 2, 1, 3].map(|i| positions[i]).to_vec());
        assert!(is_closed(&t) && !is_closed(&triangles));
        assert_eq!(euler_characteristic(&t), 2);
        assert_eq!(largest_component(&positions, &[]), (vec![], vec![]));
        // A flipped triangle breaks the orientation.
        let mut flipped = tetrahedron(0);
        flipped[0] = [0, 1, 2];
        assert!(!is_closed(&flipped));
        assert_eq!(unpaired_edge_vertices(&flipped), [0, 1, 2]);
        assert_eq!(unpaired_edge_vertices(&triangles), [4, 5, 6]);
    }
}
