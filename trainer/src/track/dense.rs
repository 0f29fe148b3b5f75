//! Small dense linear algebra for the tracker's Levenberg–Marquardt fits: the normal
//! equations of a row-major Jacobian and a Cholesky solve of them.

/// Solves `A x = b` for a symmetric positive definite `A` (`n × n`, overwritten by its
/// Cholesky factor); `None` when `A` is not positive definite.
pub(super) fn cholesky_solve(a: &mut [f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    if !cholesky_factor(a, n) {
        return None;
    }
    let mut x = b.to_vec();
    cholesky_substitute(a, n, &mut x);
    Some(x)
}

/// Cholesky factor of the symmetric positive definite `a` (`n × n`) in place (lower triangle);
/// `false` when it is not positive definite.
pub(super) fn cholesky_factor(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    true
}

/// Solves `L Lᵀ x = b` in place for the factor `l` of [`cholesky_factor`].
pub(super) fn cholesky_substitute(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        for k in 0..i {
            b[i] -= l[i * n + k] * b[k];
        }
        b[i] /= l[i * n + i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            b[i] -= l[k * n + i] * b[k];
        }
        b[i] /= l[i * n + i];
    }
}

/// `Jᵀ J` (row-major `n × n`), and `Jᵀ r`, of a row-major `m × n` `jac`: faer's blocked
/// matrix product on one thread (its summation order, and so the fit, does not depend on the
/// machine).
pub(super) fn normal_equations(jac: &[f64], r: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    use faer::linalg::matmul::matmul;
    use faer::{Accum, ColRef, Mat, MatRef, Par};
    let m = r.len();
    let j = MatRef::from_row_major_slice(jac, m, n);
    let mut jtj = Mat::<f64>::zeros(n, n);
    matmul(
        jtj.as_mut(),
        Accum::Replace,
        j.transpose(),
        j,
        1.0,
        Par::Seq,
    );
    let mut jtr = Mat::<f64>::zeros(n, 1);
    let rv = ColRef::from_slice(r).as_mat();
    matmul(
        jtr.as_mut(),
        Accum::Replace,
        j.transpose(),
        rv,
        1.0,
        Par::Seq,
    );
    let mut out = vec![0.0; n * n];
    for i in 0..n {
        for k in 0..n {
            // Symmetric by construction up to rounding; take one triangle for exact symmetry.
            out[i * n + k] = if k >= i { jtj[(i, k)] } else { jtj[(k, i)] };
        }
    }
    (out, (0..n).map(|i| jtr[(i, 0)]).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row-major `m × n` matrix with entries from a fixed integer pattern (no generator:
    /// the values only need to be generic).
    fn pattern(m: usize, n: usize) -> Vec<f64> {
        (0..m * n)
            .map(|k| ((k * 7 + 3) % 11) as f64 - 5.0 + 0.25 * (k % 3) as f64)
            .collect()
    }

    #[test]
    fn normal_equations_equal_the_textbook_sums() {
        let (m, n) = (9, 4);
        let jac = pattern(m, n);
        let r: Vec<f64> = (0..m).map(|i| i as f64 * 0.5 - 2.0).collect();
        let (jtj, jtr) = normal_equations(&jac, &r, n);
        for i in 0..n {
            let g: f64 = (0..m).map(|row| jac[row * n + i] * r[row]).sum();
            assert!((jtr[i] - g).abs() < 1e-12, "Jᵀr[{i}] {} vs {g}", jtr[i]);
            for k in 0..n {
                let s: f64 = (0..m).map(|row| jac[row * n + i] * jac[row * n + k]).sum();
                assert!((jtj[i * n + k] - s).abs() < 1e-12, "JᵀJ[{i},{k}]");
                assert_eq!(jtj[i * n + k], jtj[k * n + i], "JᵀJ symmetric at [{i},{k}]");
            }
        }
    }

    #[test]
    fn cholesky_solve_recovers_a_known_solution() {
        // A = JᵀJ + I is symmetric positive definite; b = A x for a chosen x.
        let n = 5;
        let (mut a, _) = normal_equations(&pattern(8, n), &[0.0; 8], n);
        for i in 0..n {
            a[i * n + i] += 1.0;
        }
        let x: Vec<f64> = (0..n).map(|i| 1.0 - 0.3 * i as f64).collect();
        let b: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|k| a[i * n + k] * x[k]).sum())
            .collect();
        let solved = cholesky_solve(&mut a.clone(), &b, n).expect("positive definite");
        for (s, t) in solved.iter().zip(&x) {
            assert!((s - t).abs() < 1e-10, "{s} vs {t}");
        }
        // The factor is lower triangular with L Lᵀ = A.
        let mut l = a.clone();
        assert!(cholesky_factor(&mut l, n));
        for i in 0..n {
            for k in 0..=i {
                let s: f64 = (0..=k).map(|j| l[i * n + j] * l[k * n + j]).sum();
                assert!((s - a[i * n + k]).abs() < 1e-10, "(L Lᵀ)[{i},{k}]");
            }
        }
    }

    #[test]
    fn cholesky_refuses_matrices_that_are_not_positive_definite() {
        // Indefinite (eigenvalues 3 and −1), singular, and NaN.
        assert!(cholesky_solve(&mut [1.0, 2.0, 2.0, 1.0], &[1.0, 1.0], 2).is_none());
        assert!(cholesky_solve(&mut [1.0, 1.0, 1.0, 1.0], &[1.0, 1.0], 2).is_none());
        assert!(cholesky_solve(&mut [f64::NAN, 0.0, 0.0, 1.0], &[1.0, 1.0], 2).is_none());
    }
}
