//! Laplacian loss on posed vertices (paper Eq. 6): `Σ_i ‖v_i − (1/|N_i|) Σ_{k∈N_i} v_k‖²`.
//!
//! Uniform weights, as the paper writes it. Cotangent weights would have to be recomputed from
//! the posed mesh every step (or frozen from the rest pose, which then penalises any pose change
//! of a curved region differently from the paper), and they turn negative on obtuse triangles; the
//! uniform operator is a constant sparse matrix, so the loss is a plain quadratic in the posed
//! positions. One-rings come from [`MeshGraph`]: vertices at the same position (UV seams) are
//! welded, so a seam vertex sees its whole ring rather than one side of it. The loss is the
//! absolute Laplacian of the positions it is given, as in Eq. 6; the trainer gives it the
//! difference from the initial skinning by default (`train::LaplacianReference`).

use candle_core::{Device, Result, Tensor};
use glam::Vec3;

use crate::geodesic::MeshGraph;

/// The uniform Laplacian as padded neighbour lists: `index` `[V·K]`, `weight` `[V, K]`.
#[derive(Clone, Debug)]
pub struct UniformLaplacian {
    index: Tensor,
    weight: Tensor,
    vertices: usize,
    width: usize,
}

impl UniformLaplacian {
    /// Builds the operator for a mesh. An isolated vertex is its own neighbour (zero Laplacian).
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]], device: &Device) -> Result<Self> {
        let graph = MeshGraph::new(positions, triangles);
        let rep = graph.representatives();
        let node_of = graph.node_of();
        let width = (0..graph.node_count())
            .map(|n| graph.neighbours(n).len())
            .max()
            .unwrap_or(0)
            .max(1);
        let v = positions.len();
        let mut index = vec![0u32; v * width];
        let mut weight = vec![0.0f32; v * width];
        for (i, &node) in node_of.iter().enumerate() {
            let ring = graph.neighbours(node as usize);
            let row = i * width;
            index[row..row + width].fill(i as u32);
            if ring.is_empty() {
                weight[row] = 1.0;
            }
            for (k, &n) in ring.iter().enumerate() {
                index[row + k] = rep[n as usize];
                weight[row + k] = 1.0 / ring.len() as f32;
            }
        }
        Ok(Self {
            index: Tensor::from_vec(index, v * width, device)?,
            weight: Tensor::from_vec(weight, (v, width), device)?,
            vertices: v,
            width,
        })
    }

    /// `δ_i = v_i − mean(N_i)` for posed positions `[F, V, 3]` → `[F, V, 3]`.
    pub fn apply(&self, posed: &Tensor) -> Result<Tensor> {
        let (f, v, _) = posed.dims3()?;
        if v != self.vertices {
            candle_core::bail!("Laplacian built for {} vertices, got {v}", self.vertices);
        }
        let gathered = posed
            .index_select(&self.index, 1)?
            .reshape((f, v, self.width, 3))?;
        let w = self
            .weight
            .to_dtype(posed.dtype())?
            .reshape((1, v, self.width, 1))?;
        let mean = gathered.broadcast_mul(&w)?.sum(2)?;
        posed - mean
    }

    /// Eq. 6 summed over frames: `Σ_f Σ_i ‖δ_i‖²`.
    pub fn loss(&self, posed: &Tensor) -> Result<Tensor> {
        self.apply(posed)?.sqr()?.sum_all()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::DType;

    /// A centre vertex (index 0) with a four-triangle fan around it; vertex 5 duplicates vertex 1
    /// (a seam) and closes the fan.
    fn fan() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = vec![
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::X,
            Vec3::Y,
            -Vec3::X,
            -Vec3::Y,
            Vec3::X,
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]];
        (p, t)
    }

    #[test]
    fn value_on_a_fan() {
        let (p, t) = fan();
        let lap = UniformLaplacian::new(&p, &t, &Device::Cpu).unwrap();
        let x = Tensor::from_vec(
            p.iter().flat_map(|v| v.to_array()).collect::<Vec<f32>>(),
            (1, 6, 3),
            &Device::Cpu,
        )
        .unwrap();
        let d = lap.apply(&x).unwrap().to_vec3::<f32>().unwrap();
        // Centre: its ring is the four rim points (mean 0) → δ = (0, 0, 1).
        assert_eq!(d[0][0], [0.0, 0.0, 1.0]);
        // Rim point X (and its seam copy): ring {centre, Y, −Y} → mean (0, 0, 1/3).
        for i in [1, 5] {
            let e = [1.0, 0.0, -1.0 / 3.0];
            assert!(
                d[0][i].iter().zip(e).all(|(a, b)| (a - b).abs() < 1e-6),
                "{:?}",
                d[0][i]
            );
        }
        // Total: the centre, plus five rim vertices (X and its seam copy) × (1 + 1/9).
        let l = lap.loss(&x).unwrap().to_vec0::<f32>().unwrap();
        let expect = 1.0 + 5.0 * (1.0 + 1.0 / 9.0);
        assert!((l - expect).abs() < 1e-5, "{l} vs {expect}");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (p, t) = fan();
        let lap = UniformLaplacian::new(&p, &t, &Device::Cpu).unwrap();
        let mut v: Vec<f64> = p.iter().flat_map(|v| v.to_array()).map(f64::from).collect();
        v.extend(v.clone().iter().map(|x| 0.5 * x + 0.1));
        let x0 = Tensor::from_vec(v, (2, 6, 3), &Device::Cpu)
            .unwrap()
            .to_dtype(DType::F64)
            .unwrap();
        crate::losses::fd::check(&x0, 1e-5, 1e-8, 1e-7, |x| lap.loss(x).unwrap());
    }
}
