//! Geodesic skinning regulariser (paper Eqs. 7–8):
//! `L_skin = Σ_i Σ_j w_ij · (min_{k∈A_j} d_geo(v̄_i, v̄_k) / d_geo^max)^r`, with
//! `A_j = {k | j = argmax_t w_init,k,t}` and r = 3.
//!
//! The penalty matrix `P_ij = (d(i, A_j)/d_max)^r` depends only on the template and the initial
//! weights, so it is computed once ([`MeshGraph`] edge-path distances: see `geodesic.rs` for the
//! approximation) and the loss is `Σ w ⊙ P`, linear in the weights. Conventions for the cases the
//! paper leaves open: `argmax` ties go to the lowest joint index; a joint that is nobody's argmax
//! (`A_j = ∅`, e.g. an end effector) and a vertex that cannot reach `A_j` (another mesh
//! component) get the largest penalty, 1; distances are clamped to `d_max` (a double-sweep
//! `d_max` can be a slight underestimate on large meshes).

use candle_core::{Device, Result, Tensor};

use crate::geodesic::MeshGraph;

/// The paper's exponent r.
pub const PAPER_R: f32 = 3.0;

/// `P_ij` row-major `[V, J]` for dense initial weights `init` `[V, J]`, with `d_max` given.
#[must_use]
pub fn penalty_matrix(
    graph: &MeshGraph,
    init: &[f32],
    joints: usize,
    r: f32,
    d_max: f64,
) -> Vec<f32> {
    let v = init.len() / joints.max(1);
    let mut sets: Vec<Vec<usize>> = vec![Vec::new(); joints];
    for (i, row) in init.chunks(joints).enumerate() {
        let best = row
            .iter()
            .enumerate()
            .fold(0, |b, (j, &w)| if w > row[b] { j } else { b });
        sets[best].push(i);
    }
    let mut p = vec![1.0f32; v * joints];
    for (j, set) in sets.iter().enumerate() {
        if set.is_empty() || d_max <= 0.0 {
            continue;
        }
        for (i, d) in graph.distances_from(set).into_iter().enumerate() {
            if d.is_finite() {
                p[i * joints + j] = ((d / d_max).min(1.0) as f32).powf(r);
            }
        }
    }
    p
}

/// Eqs. 7–8 with a precomputed penalty.
#[derive(Clone, Debug)]
pub struct GeodesicSkinningReg {
    penalty: Tensor,
}

impl GeodesicSkinningReg {
    /// Computes the penalty for a template (`d_max` exact up to `exact_limit` graph nodes).
    pub fn new(
        graph: &MeshGraph,
        init: &[f32],
        joints: usize,
        r: f32,
        exact_limit: usize,
        device: &Device,
    ) -> Result<Self> {
        if joints == 0
            || !init.len().is_multiple_of(joints)
            || init.len() / joints != graph.node_of().len()
        {
            candle_core::bail!(
                "geodesic regulariser: {} initial weights for {} vertices × {joints} joints",
                init.len(),
                graph.node_of().len()
            );
        }
        let p = penalty_matrix(graph, init, joints, r, graph.max_distance(exact_limit));
        Ok(Self {
            penalty: Tensor::from_vec(p, (init.len() / joints, joints), device)?,
        })
    }

    /// The penalty `[V, J]`.
    #[must_use]
    pub fn penalty(&self) -> &Tensor {
        &self.penalty
    }

    /// `Σ_f Σ_i Σ_j w_fij P_ij` for weights `[F, V, J]`.
    pub fn loss(&self, weights: &Tensor) -> Result<Tensor> {
        weights
            .broadcast_mul(&self.penalty.to_dtype(weights.dtype())?)?
            .sum_all()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::DType;
    use glam::Vec3;

    /// 5 × 5 grid, diagonals (x, y) → (x+1, y+1), unit spacing.
    fn grid() -> MeshGraph {
        let n = 5u32;
        let p: Vec<Vec3> = (0..25)
            .map(|i| Vec3::new((i % 5) as f32, (i / 5) as f32, 0.0))
            .collect();
        let mut t = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = y * n + x;
                t.push([i, i + 1, i + n + 1]);
                t.push([i, i + n + 1, i + n]);
            }
        }
        MeshGraph::new(&p, &t)
    }

    /// Joint 0 owns columns x ≤ 1, joint 1 column 2, joint 2 columns x ≥ 3, joint 3 nothing.
    fn init() -> Vec<f32> {
        (0..25)
            .flat_map(|i| match i % 5 {
                0 | 1 => [0.9, 0.1, 0.0, 0.0],
                2 => [0.3, 0.4, 0.3, 0.0],
                _ => [0.0, 0.2, 0.8, 0.0],
            })
            .collect()
    }

    #[test]
    fn penalty_and_value_on_a_grid() {
        let g = grid();
        let reg = GeodesicSkinningReg::new(&g, &init(), 4, PAPER_R, 1000, &Device::Cpu).unwrap();
        let p = reg.penalty().to_vec2::<f32>().unwrap();
        let dmax = 8.0; // (4, 0) ↔ (0, 4): no diagonal edge helps
        let cube = |d: f64| ((d / dmax).powi(3)) as f32;
        // Vertex (4, 0): 3 edges from column 1 (joint 0), 2 from column 2 (joint 1), and it is
        // itself in A_2.
        assert!(
            (p[4][0] - cube(3.0)).abs() < 1e-6
                && (p[4][1] - cube(2.0)).abs() < 1e-6
                && p[4][2] == 0.0
        );
        // Vertex (0, 3): column 2 is 2 edges away, column 3 three.
        assert!((p[15][1] - cube(2.0)).abs() < 1e-6 && (p[15][2] - cube(3.0)).abs() < 1e-6);
        assert_eq!(p[4][3], 1.0);
        assert!(p[0][0] == 0.0 && p[12][1] == 0.0);
        // Loss: a one-hot weight on joint 0 at (4, 0) in frame 0, on joint 3 at vertex 0 in frame 1.
        let mut w = vec![0.0f32; 2 * 25 * 4];
        w[4 * 4] = 1.0;
        w[100 + 3] = 0.5;
        let w = Tensor::from_vec(w, (2, 25, 4), &Device::Cpu).unwrap();
        let l = reg.loss(&w).unwrap().to_vec0::<f32>().unwrap();
        assert!((l - (cube(3.0) + 0.5)).abs() < 1e-6, "{l}");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let g = grid();
        let reg = GeodesicSkinningReg::new(&g, &init(), 4, PAPER_R, 1000, &Device::Cpu).unwrap();
        let w: Vec<f64> = (0..25 * 4).map(|i| ((i * 37 % 11) as f64) / 11.0).collect();
        let w0 = Tensor::from_vec(w, (1, 25, 4), &Device::Cpu)
            .unwrap()
            .to_dtype(DType::F64)
            .unwrap();
        crate::losses::fd::check(&w0, 1e-5, 1e-8, 1e-6, |w| reg.loss(w).unwrap());
    }

    #[test]
    fn rejects_mismatched_weights() {
        assert!(
            GeodesicSkinningReg::new(&grid(), &[0.5; 12], 4, PAPER_R, 10, &Device::Cpu).is_err()
        );
    }
}
