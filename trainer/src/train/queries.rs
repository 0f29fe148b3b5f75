//! Where SkinNet is queried during training when the training template is a simplified one.
//!
//! The image losses need a mesh, and a mesh of the capture's full resolution costs four times
//! as much per iteration, so stage 1 poses a simplified training template (about 2,500 of the
//! built-in capture's 10,000 vertices). Querying SkinNet only at those 2,500 canonical points
//! lets it fit them and do anything in between: on the built-in capture, the stage-1 model of
//! the demo scored 0.897 cm Chamfer on held-out phases of the training motions when posing the
//! training template itself and 1.350 cm posing the full 10,000-vertex template it is evaluated
//! at (bone heat: 1.000), with the error in blotches between training vertices.
//!
//! So each training vertex owns a *cell*: the full-resolution vertices nearer to it than to any
//! other training vertex (Euclidean, among training vertices facing the same way, so a cell
//! does not cross the gap between a leg and the skirt around it). Every iteration draws, per
//! training vertex, one member of its cell from a seeded stream, and SkinNet's weights at that
//! member skin the training vertex. Over the iterations every full-resolution vertex is queried,
//! at the price of the simplified mesh; what a vertex of the cell pays is that its weights are
//! judged at a point a few millimetres to centimetres away, a low-pass of the field at the
//! training template's spacing. The initial weights used as the warm start's target and as the
//! Laplacian's reference are those of the drawn member, so a perfect fit of the initial weights
//! still gives zero loss. The geodesic and part-wise regularisers keep the training vertex's
//! own constants (geodesic distances, rigid mask): a cell spans about one edge of the training
//! template, across which those change little.
//!
//! Measured with the demo's schedule (seed 0), Chamfer at the full 10,000 vertices: held-out
//! phases 1.350 → 0.888 cm, novel test poses 1.166 → 0.953 cm (static baseline 0.962 and
//! 0.989, bone heat 1.000 and 1.003), at the same cost per iteration. The README's *Stage 1*
//! section has the table.

use glam::Vec3;
use rayon::prelude::*;

/// The full-resolution query points and the cell of every training vertex.
#[derive(Clone, Debug, PartialEq)]
pub struct QueryCells {
    /// Canonical positions of the full-resolution template.
    pub positions: Vec<Vec3>,
    /// Their initial weights, dense `[N, J]` row-major.
    pub init_weights: Vec<f32>,
    /// Cell of training vertex `i`: `members[offsets[i]..offsets[i + 1]]` (never empty: a
    /// training vertex is a full-resolution vertex and in its own cell).
    pub offsets: Vec<u32>,
    /// Full-resolution vertex indices, grouped by cell.
    pub members: Vec<u32>,
    /// The full-resolution index of each training vertex.
    pub source: Vec<u32>,
}

/// Minimum cosine between a full-resolution vertex's normal and its training vertex's.
const MIN_NORMAL_COSINE: f32 = 0.0;

impl QueryCells {
    /// Builds the cells of a training template whose vertex `i` is full-resolution vertex
    /// `source[i]`. `positions`/`normals` are the full-resolution template's, `init_weights` its
    /// dense `[N, J]` initial weights. Cost `O(N · V)` (brute force over the training vertices,
    /// in parallel): 25 M distance tests for 10,000 × 2,500.
    ///
    /// Returns `None` when `source` does not index `positions` or repeats a vertex (the cells
    /// would not partition the mesh).
    #[must_use]
    pub fn new(
        positions: &[Vec3],
        normals: &[Vec3],
        init_weights: &[f32],
        source: &[u32],
    ) -> Option<Self> {
        let n = positions.len();
        if normals.len() != n || source.iter().any(|&s| s as usize >= n) {
            return None;
        }
        let mut owner_of_source = vec![u32::MAX; n];
        for (i, &s) in source.iter().enumerate() {
            if owner_of_source[s as usize] != u32::MAX {
                return None;
            }
            owner_of_source[s as usize] = i as u32;
        }
        let owner: Vec<u32> = (0..n)
            .into_par_iter()
            .map(|u| {
                if owner_of_source[u] != u32::MAX {
                    return owner_of_source[u];
                }
                let (p, nu) = (positions[u], normals[u]);
                let nearest = |facing: bool| {
                    source
                        .iter()
                        .enumerate()
                        .filter(|&(_, &s)| {
                            !facing || nu.dot(normals[s as usize]) > MIN_NORMAL_COSINE
                        })
                        .map(|(i, &s)| (i, p.distance_squared(positions[s as usize])))
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                        .map(|(i, _)| i as u32)
                };
                // A vertex with no training vertex facing its way (degenerate normals) takes
                // the nearest one.
                nearest(true).or_else(|| nearest(false)).unwrap_or(0)
            })
            .collect();
        let v = source.len();
        let mut counts = vec![0u32; v + 1];
        for &o in &owner {
            counts[o as usize + 1] += 1;
        }
        for i in 0..v {
            counts[i + 1] += counts[i];
        }
        let offsets = counts;
        let mut next = offsets.clone();
        let mut members = vec![0u32; n];
        for (u, &o) in owner.iter().enumerate() {
            members[next[o as usize] as usize] = u as u32;
            next[o as usize] += 1;
        }
        Some(Self {
            positions: positions.to_vec(),
            init_weights: init_weights.to_vec(),
            offsets,
            members,
            source: source.to_vec(),
        })
    }

    /// Number of training vertices.
    #[must_use]
    pub fn training_vertex_count(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The cell of training vertex `i`.
    #[must_use]
    pub fn cell(&self, i: usize) -> &[u32] {
        &self.members[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// One member per training vertex, drawn uniformly from its cell by `rng`.
    pub fn draw(&self, rng: &mut impl rand::Rng) -> Vec<u32> {
        (0..self.training_vertex_count())
            .map(|i| {
                let c = self.cell(i);
                c[rng.random_range(0..c.len())]
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// A 6 × 1 strip of points on the plane z = 0 facing +z, plus one point under the first
    /// facing −z; training vertices 0, 3 and 5.
    fn strip() -> (Vec<Vec3>, Vec<Vec3>) {
        let mut p: Vec<Vec3> = (0..6).map(|x| Vec3::new(x as f32, 0.0, 0.0)).collect();
        let mut n = vec![Vec3::Z; 6];
        p.push(Vec3::new(0.1, 0.0, -0.01));
        n.push(-Vec3::Z);
        (p, n)
    }

    #[test]
    fn cells_partition_by_nearest_training_vertex_facing_the_same_way() {
        let (p, n) = strip();
        let w = vec![1.0; p.len()];
        let cells = QueryCells::new(&p, &n, &w, &[0, 3, 5]).unwrap();
        let sorted = |i| {
            let mut c = cells.cell(i).to_vec();
            c.sort_unstable();
            c
        };
        // 1 → 0; 2 → 3 (distance 1 vs 2); 4 → 3 or 5 (tie: first wins); the back point faces
        // away from every training vertex and takes the nearest one, 0.
        assert_eq!(sorted(0), [0, 1, 6]);
        assert_eq!(sorted(1), [2, 3, 4]);
        assert_eq!(sorted(2), [5]);
        let mut all = cells.members.clone();
        all.sort_unstable();
        assert_eq!(all, (0..7).collect::<Vec<u32>>());
    }

    #[test]
    fn facing_test_keeps_a_back_point_out_of_a_nearer_front_cell() {
        // Training vertices 0 (front surface) and 1 (back surface, 0.5 behind); point 2 faces
        // the front but lies 5 cm from the back vertex.
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, -0.5),
            Vec3::new(0.05, 0.0, -0.5),
        ];
        let n = vec![Vec3::Z, -Vec3::Z, Vec3::Z];
        let cells = QueryCells::new(&p, &n, &[1.0; 3], &[0, 1]).unwrap();
        assert_eq!(cells.cell(0), [0, 2]);
        assert_eq!(cells.cell(1), [1]);
    }

    #[test]
    fn draws_are_cell_members_seeded_and_cover_every_cell() {
        let (p, n) = strip();
        let cells = QueryCells::new(&p, &n, &[1.0; 7], &[0, 3, 5]).unwrap();
        let draw = |seed| cells.draw(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed));
        assert_eq!(draw(4), draw(4));
        let mut seen = std::collections::BTreeSet::new();
        for seed in 0..64 {
            let d = draw(seed);
            for (i, &m) in d.iter().enumerate() {
                assert!(cells.cell(i).contains(&m));
                seen.insert(m);
            }
        }
        assert_eq!(seen.len(), 7);
    }

    #[test]
    fn bad_sources_are_refused() {
        let (p, n) = strip();
        let w = [1.0; 7];
        assert!(QueryCells::new(&p, &n, &w, &[0, 7]).is_none());
        assert!(QueryCells::new(&p, &n, &w, &[0, 0]).is_none());
        assert!(QueryCells::new(&p, &n[..3], &w, &[0]).is_none());
    }
}
