//! Simplification to a target vertex or triangle count with meshoptimizer's edge-collapse
//! simplifier, keeping a subset of the source vertices (the project's one simplifier: the
//! trainer's synthetic body and training template use it too).
//!
//! meshoptimizer takes a target *index* count. For a triangle target that is `3n` and the result
//! has at most `n` triangles. For a vertex target there is no direct control, so the index
//! target is searched (interpolation search, at most [`MAX_PASSES`] simplifier passes) for the
//! result whose vertex count is closest to the target; it is usually exact or off by a few.

use glam::Vec3;
use skinfield_formats::Template;
use skinfield_formats::mesh::area_weighted_normals;

use super::transfer::{SourcePoint, transfer_attributes};
use super::{ResampleError, Resampled, Target};

/// Most simplifier passes spent searching for a vertex target.
pub const MAX_PASSES: usize = 12;

/// meshoptimizer's relative error bound; 1 (the whole mesh extent) leaves the count in charge.
const NO_ERROR_LIMIT: f32 = 1.0;

/// Simplifies a triangle mesh towards `target`; returns, for each kept vertex in first-use
/// order (deterministic), its index in the input, and the triangles over the kept vertices.
/// Degenerate triangles and unreferenced vertices are dropped. A target at or above the input's
/// count returns the input's referenced vertices unchanged.
#[must_use]
pub fn simplify_subset(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    target: Target,
) -> (Vec<u32>, Vec<[u32; 3]>) {
    simplify_subset_locked(positions, triangles, target, &[])
}

/// [`simplify_subset`] that never moves or removes the vertices flagged in `locked`: one flag
/// per input vertex; an empty slice (or one of another length) locks nothing and is exactly
/// [`simplify_subset`].
#[must_use]
pub fn simplify_subset_locked(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    target: Target,
    locked: &[bool],
) -> (Vec<u32>, Vec<[u32; 3]>) {
    let indices: Vec<u32> = triangles.iter().flatten().copied().collect();
    let bytes: Vec<u8> = positions
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    // 12-byte stride, position at offset 0: cannot fail for this layout.
    let Ok(adapter) = meshopt::VertexDataAdapter::new(&bytes, 12, 0) else {
        return compact(positions.len(), &indices);
    };
    let locks = locked.len() == positions.len() && locked.contains(&true);
    let pass = |target_indices: usize| {
        let target_indices = target_indices.min(indices.len());
        let out = if locks {
            meshopt::simplify_with_locks(
                &indices,
                &adapter,
                locked,
                target_indices,
                NO_ERROR_LIMIT,
                meshopt::SimplifyOptions::None,
                None,
            )
        } else {
            meshopt::simplify(
                &indices,
                &adapter,
                target_indices,
                NO_ERROR_LIMIT,
                meshopt::SimplifyOptions::None,
                None,
            )
        };
        compact(positions.len(), &out)
    };
    match target {
        Target::Triangles(n) => pass(3 * n),
        Target::Vertices(n) => {
            let full = compact(positions.len(), &indices);
            if n >= full.0.len() {
                return full;
            }
            search_vertices(n, indices.len(), full, pass)
        }
    }
}

/// Interpolation search over the index target for the result with the vertex count closest to
/// `n` (vertex counts grow with the index target, nearly linearly).
fn search_vertices(
    n: usize,
    max_indices: usize,
    full: (Vec<u32>, Vec<[u32; 3]>),
    pass: impl Fn(usize) -> (Vec<u32>, Vec<[u32; 3]>),
) -> (Vec<u32>, Vec<[u32; 3]>) {
    let (mut lo, mut lo_count) = (0usize, 0usize);
    let (mut hi, mut hi_count) = (max_indices, full.0.len());
    // A closed mesh has about twice as many triangles as vertices: a good first guess.
    let mut guess = (6 * n).clamp(3, max_indices);
    let mut best = full;
    for _ in 0..MAX_PASSES {
        let result = pass(guess);
        let count = result.0.len();
        if count.abs_diff(n) < best.0.len().abs_diff(n) {
            best = result;
        }
        if count == n {
            break;
        }
        if count < n {
            (lo, lo_count) = (guess, count);
        } else {
            (hi, hi_count) = (guess, count);
        }
        if hi <= lo + 3 {
            break;
        }
        let span = (hi_count - lo_count).max(1) as f64;
        let t = lo as f64 + (hi - lo) as f64 * (n - lo_count) as f64 / span;
        // Stay strictly inside (lo, hi) so every pass narrows the bracket.
        guess = (t.round() as usize).clamp(lo + 1, hi - 1);
    }
    best
}

/// Drops degenerate triangles and renumbers the used vertices in first-use order.
fn compact(vertex_count: usize, indices: &[u32]) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut remap = vec![u32::MAX; vertex_count];
    let mut source = Vec::new();
    let mut out = Vec::new();
    for t in indices.chunks_exact(3) {
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

/// `source` simplified to about `target` (below its count): kept vertices keep their
/// attributes exactly, normals are recomputed from the new triangles.
pub fn simplify(source: &Template, target: Target) -> Result<Resampled, ResampleError> {
    source.validate()?;
    let have = target.of(source);
    if target.count() == 0 || target.count() >= have {
        return Err(ResampleError::Target {
            target: target.count(),
            unit: target.unit(),
            source_count: have,
            reason: "must be at least 1 and below the source's count to simplify",
        });
    }
    let (kept, triangles) = simplify_subset(&source.positions, &source.triangles, target);
    let positions: Vec<Vec3> = kept.iter().map(|&i| source.positions[i as usize]).collect();
    let normals = area_weighted_normals(&positions, &triangles);
    let points: Vec<SourcePoint> = kept.iter().map(|&i| SourcePoint::vertex(i)).collect();
    let template = transfer_attributes(source, &points, positions, triangles, Some(normals))?;
    Ok(Resampled {
        template,
        source: points,
    })
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{
        closed_when_welded, color_of, label_of, seam_sphere, sphere, uv_of,
    };
    use super::*;

    #[test]
    fn vertex_targets_are_met_within_one_percent() {
        let s = sphere(60, 80); // 4,722 vertices
        for n in [200, 1000, 2500] {
            let r = simplify(&s, Target::Vertices(n)).unwrap();
            let got = r.template.vertex_count();
            assert!(got.abs_diff(n) * 100 <= n, "{n}: got {got}");
            r.template.validate().unwrap();
        }
    }

    #[test]
    fn triangle_targets_are_not_exceeded() {
        let s = sphere(40, 50);
        for n in [100, 1000, 3000] {
            let r = simplify(&s, Target::Triangles(n)).unwrap();
            let got = r.template.triangles.len();
            assert!(got <= n && got * 100 >= 95 * n, "{n}: got {got}");
        }
    }

    #[test]
    fn kept_vertices_carry_their_own_attributes_exactly() {
        let s = sphere(30, 40);
        let r = simplify(&s, Target::Vertices(300)).unwrap();
        let t = &r.template;
        for (v, p) in r.source.iter().enumerate() {
            let i = p.vertices[0] as usize;
            assert_eq!(p.vertices, [i as u32; 3]);
            assert_eq!(t.positions[v], s.positions[i]);
            let x = t.positions[v];
            assert!((t.uvs.as_ref().unwrap()[v] - uv_of(x)).length() < 1e-6);
            assert!((t.colors.as_ref().unwrap()[v] - color_of(x)).length() < 1e-6);
            assert_eq!(t.part_labels.as_ref().unwrap()[v], label_of(x));
            // Recomputed normals of a coarse sphere still point outwards.
            assert!(t.normals[v].dot(x) > 0.9, "{v}");
        }
    }

    #[test]
    fn a_closed_mesh_stays_closed() {
        let s = sphere(30, 40);
        let t = simplify(&s, Target::Vertices(250)).unwrap().template;
        // Closed and manifold: every undirected edge is used by exactly two triangles, once in
        // each direction; and the Euler characteristic of a sphere is 2.
        let mut edges = std::collections::HashMap::new();
        for tri in &t.triangles {
            for k in 0..3 {
                *edges.entry((tri[k], tri[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        assert!(
            edges
                .iter()
                .all(|(&(a, b), &c)| c == 1 && edges.get(&(b, a)) == Some(&1))
        );
        let euler = t.vertex_count() as i64 - edges.len() as i64 / 2 + t.triangles.len() as i64;
        assert_eq!(euler, 2);
    }

    #[test]
    fn a_uv_seam_stays_closed_and_keeps_both_sides_uvs() {
        let s = seam_sphere(30, 40);
        assert!(closed_when_welded(&s));
        let r = simplify(&s, Target::Vertices(300)).unwrap();
        assert!(closed_when_welded(&r.template), "the seam opened");
        // Kept vertices keep their own side's UV (u = 0 and u = 1 copies both survive).
        let uvs = r.template.uvs.as_ref().unwrap();
        for (v, p) in r.source.iter().enumerate() {
            assert_eq!(uvs[v], s.uvs.as_ref().unwrap()[p.vertices[0] as usize]);
        }
        assert!(uvs.iter().any(|uv| uv.x == 0.0) && uvs.iter().any(|uv| uv.x == 1.0));
    }

    #[test]
    fn unreachable_targets_are_typed_errors() {
        let s = sphere(10, 12);
        for target in [Target::Vertices(0), Target::Vertices(s.vertex_count())] {
            let err = simplify(&s, target).unwrap_err();
            assert!(matches!(err, ResampleError::Target { .. }), "{err}");
            assert!(err.to_string().contains("`target`"), "{err}");
        }
        let mut bad = s;
        bad.triangles[0][1] = 10_000;
        assert!(matches!(
            simplify(&bad, Target::Vertices(10)),
            Err(ResampleError::Mesh(_))
        ));
    }
}
