//! Mesh simplification that keeps a subset of the original vertices.
//!
//! meshoptimizer's edge-collapse simplifier only removes vertices, so the result can be
//! expressed as indices into the input: attributes (colours, labels, weights) carry over exactly,
//! with no interpolation.

use glam::Vec3;

/// Simplifies a closed triangle mesh to about `target_vertices` vertices; returns, for each kept
/// vertex in first-use order (deterministic), its index in the input, and the triangles over the
/// kept vertices. Degenerate triangles and unreferenced vertices are dropped.
#[must_use]
pub fn simplify_subset(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    target_vertices: usize,
) -> (Vec<u32>, Vec<[u32; 3]>) {
    let identity = || ((0..positions.len() as u32).collect(), triangles.to_vec());
    let indices: Vec<u32> = triangles.iter().flatten().copied().collect();
    let bytes: Vec<u8> = positions
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    // 12-byte stride, position at offset 0: cannot fail for this layout.
    let Ok(adapter) = meshopt::VertexDataAdapter::new(&bytes, 12, 0) else {
        return identity();
    };
    // A closed mesh has about twice as many triangles as vertices.
    let target_indices = (target_vertices * 2 * 3).min(indices.len());
    let simplified = meshopt::simplify(
        &indices,
        &adapter,
        target_indices,
        0.05,
        meshopt::SimplifyOptions::None,
        None,
    );
    let mut remap = vec![u32::MAX; positions.len()];
    let mut source = Vec::new();
    let mut out = Vec::new();
    for t in simplified.chunks_exact(3) {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            continue;
        }
        out.push([t[0], t[1], t[2]].map(|i| {
            if remap[i as usize] == u32::MAX {
                remap[i as usize] = source.len() as u32;
                source.push(i);
            }
            remap[i as usize]
        }));
    }
    (source, out)
}
