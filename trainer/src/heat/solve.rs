//! The linear solve: one sparse Cholesky factorisation of `K + M·H`, one solve per joint.
//!
//! `(−Δ + H) w_j = H p_j` with `Δ = −M⁻¹K` (see `laplacian`) is multiplied through by `M`:
//! `(K + M H) w_j = M H p_j`. The two are the same equations, but the second is symmetric, and
//! positive definite on every connected component that has at least one vertex with `H_ii > 0`
//! (`K` is positive semi-definite with only the per-component constants in its null space,
//! which `M H` removes). The caller passes only such components' vertices as unknowns.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholesky, factorize_symbolic_cholesky};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};

/// A factorised system.
pub(crate) struct Factor {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    n: usize,
}

/// Why the factorisation failed (faer's message).
#[derive(Debug)]
pub(crate) struct FactorError(pub String);

impl Factor {
    /// Factorises the symmetric matrix with off-diagonal `edges` `(i, j, w)` (entry `−w`, i > j,
    /// each edge once, vertices already renumbered to unknowns) and diagonal
    /// `Σ_j w_ij + diag[i]`. Sequential: two threads were slower on this machine.
    pub(crate) fn new(n: usize, edges: &[(u32, u32, f64)], diag: &[f64]) -> Result<Self, FactorError> {
        let mut d = diag.to_vec();
        let mut triplets: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(edges.len() + n);
        for &(i, j, w) in edges {
            d[i as usize] += w;
            d[j as usize] += w;
            // Lower triangle only: row > column.
            triplets.push(Triplet::new(i as usize, j as usize, -w));
        }
        triplets.extend(d.iter().enumerate().map(|(i, &v)| Triplet::new(i, i, v)));
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets)
            .map_err(|e| FactorError(format!("{e:?}")))?;
        let symbolic = factorize_symbolic_cholesky(a.symbolic(), Side::Lower, Default::default(), Default::default())
            .map_err(|e| FactorError(format!("{e:?}")))?;
        let mut values = vec![0.0; symbolic.len_val()];
        let par = Par::Seq;
        let mut mem = MemBuffer::try_new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()))
            .map_err(|e| FactorError(format!("{e:?}")))?;
        symbolic
            .factorize_numeric_llt::<f64>(
                &mut values,
                a.as_ref(),
                Side::Lower,
                Default::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|e| FactorError(format!("{e:?}")))?;
        Ok(Self { symbolic, values, n })
    }

    /// Solves for every column of `rhs` (`n` rows) in place.
    pub(crate) fn solve_in_place(&self, rhs: &mut Mat<f64>) {
        debug_assert_eq!(rhs.nrows(), self.n);
        let par = Par::Seq;
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(rhs.ncols(), par));
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs.as_mut(),
            par,
            MemStack::new(&mut mem),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_path_graph_against_a_dense_reference() {
        // Path 0-1-2-3 with weights 1, 2, 3 and diagonal shifts; compare with Gaussian
        // elimination written out here.
        let edges = [(1, 0, 1.0), (2, 1, 2.0), (3, 2, 3.0)];
        let diag = [0.5, 0.0, 0.1, 2.0];
        let f = Factor::new(4, &edges, &diag).unwrap();
        let mut a = [[0.0f64; 4]; 4];
        for &(i, j, w) in &edges {
            let (i, j) = (i as usize, j as usize);
            a[i][j] -= w;
            a[j][i] -= w;
            a[i][i] += w;
            a[j][j] += w;
        }
        for i in 0..4 {
            a[i][i] += diag[i];
        }
        let b = [1.0, -2.0, 0.5, 3.0];
        let mut rhs = Mat::from_fn(4, 1, |i, _| b[i]);
        f.solve_in_place(&mut rhs);
        // Dense elimination (no pivoting needed: SPD).
        let (mut m, mut y) = (a, b);
        for k in 0..4 {
            for i in k + 1..4 {
                let r = m[i][k] / m[k][k];
                for c in k..4 {
                    m[i][c] -= r * m[k][c];
                }
                y[i] -= r * y[k];
            }
        }
        let mut x = [0.0; 4];
        for i in (0..4).rev() {
            x[i] = (y[i] - (i + 1..4).map(|c| m[i][c] * x[c]).sum::<f64>()) / m[i][i];
        }
        for i in 0..4 {
            assert!((rhs[(i, 0)] - x[i]).abs() < 1e-12, "{i}: {} vs {}", rhs[(i, 0)], x[i]);
        }
    }

    #[test]
    fn a_singular_system_is_an_error_not_a_panic() {
        // Pure Laplacian of a path: constants in the null space.
        assert!(Factor::new(3, &[(1, 0, 1.0), (2, 1, 1.0)], &[0.0; 3]).is_err());
    }
}
