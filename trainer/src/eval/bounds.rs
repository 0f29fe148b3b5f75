//! Ceilings for the table: how well linear blend skinning *could* do on a capture, so that every
//! row's gap has a denominator.
//!
//! - `bound-static`: the best static weights. Per vertex, the weights on the simplex
//!   (`w ≥ 0, Σw = 1`) that minimise the squared distance between the LBS-posed vertex and the
//!   ground truth summed over the *training* frames (constrained least squares over all
//!   joints), then scored on the test frames like any static skinning.
//! - `bound-pose`: the best pose-dependent weights within the model's candidate joints
//!   ([`crate::candidates`]): per test frame and vertex, the simplex weights over the vertex's
//!   candidates that bring the posed vertex closest to the ground truth of that very frame.
//!   No learned model of SkinNet's class can beat it on these frames.
//!
//! Both need evaluation-only ground truth (the capture's `gt_meshes`, for training frames too);
//! the trainer never reads it.
//!
//! The fits are small quadratic programmes `min ‖A w − y‖²` on the simplex (`A` is 3F × n for the
//! static fit, 3 × k per frame for the posed one), solved by accelerated projected gradient
//! (FISTA with adaptive restart) on the normal equations, projecting onto the simplex exactly
//! (Duchi et al. 2008).

use glam::{Mat4, Vec3};
use rayon::prelude::*;
use skinfield_formats::capture::Capture;
use skinfield_formats::{Skeleton, StaticSkin};

use super::EvalError;

/// Projected-gradient iterations per fit.
const ITERATIONS: usize = 800;

/// Euclidean projection of `v` onto the probability simplex, in place.
pub fn project_to_simplex(v: &mut [f64]) {
    let mut u: Vec<f64> = v.to_vec();
    u.sort_by(|a, b| b.total_cmp(a));
    let mut cumulative = 0.0;
    let mut theta = 0.0;
    for (i, &ui) in u.iter().enumerate() {
        cumulative += ui;
        let t = (cumulative - 1.0) / (i + 1) as f64;
        if ui - t > 0.0 {
            theta = t;
        }
    }
    for x in v.iter_mut() {
        *x = (*x - theta).max(0.0);
    }
}

/// `argmin_{w ∈ simplex} wᵀQw − 2cᵀw` for a symmetric positive semi-definite `q` (`n × n`,
/// row-major), starting from the uniform weights.
#[must_use]
pub fn simplex_quadratic(q: &[f64], c: &[f64]) -> Vec<f64> {
    let n = c.len();
    if n == 0 {
        return Vec::new();
    }
    let mul = |x: &[f64], out: &mut [f64]| {
        for (i, o) in out.iter_mut().enumerate() {
            *o = q[i * n..(i + 1) * n]
                .iter()
                .zip(x)
                .map(|(a, b)| a * b)
                .sum();
        }
    };
    let objective = |x: &[f64], qx: &[f64]| -> f64 {
        x.iter().zip(qx).map(|(a, b)| a * b).sum::<f64>()
            - 2.0 * x.iter().zip(c).map(|(a, b)| a * b).sum::<f64>()
    };
    // Largest eigenvalue of Q by power iteration (a few percent over, for a safe step).
    let mut v = vec![1.0 / (n as f64).sqrt(); n];
    let mut qv = vec![0.0; n];
    let mut lambda = 0.0;
    for _ in 0..50 {
        mul(&v, &mut qv);
        let norm = qv.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm <= 0.0 {
            break;
        }
        lambda = norm;
        for (a, b) in v.iter_mut().zip(&qv) {
            *a = b / norm;
        }
    }
    let step = if lambda > 0.0 {
        1.0 / (2.0 * 1.05 * lambda)
    } else {
        1.0
    };
    let mut x = vec![1.0 / n as f64; n];
    let mut y = x.clone();
    let mut t = 1.0f64;
    let mut qy = vec![0.0; n];
    let mut qx = vec![0.0; n];
    mul(&x, &mut qx);
    let mut fx = objective(&x, &qx);
    for _ in 0..ITERATIONS {
        mul(&y, &mut qy);
        let mut next: Vec<f64> = y
            .iter()
            .zip(&qy)
            .zip(c)
            .map(|((yi, qyi), ci)| yi - step * 2.0 * (qyi - ci))
            .collect();
        project_to_simplex(&mut next);
        mul(&next, &mut qx);
        let fnext = objective(&next, &qx);
        if fnext > fx {
            // Adaptive restart: momentum overshot; continue from x without it.
            y.clone_from(&x);
            t = 1.0;
            continue;
        }
        let t_next = 0.5 * (1.0 + (1.0 + 4.0 * t * t).sqrt());
        for ((yi, &ni), &xi) in y.iter_mut().zip(&next).zip(&x) {
            *yi = ni + (t - 1.0) / t_next * (ni - xi);
        }
        x = next;
        fx = fnext;
        t = t_next;
    }
    x
}

/// Skinning matrices of `frame`.
fn matrices(capture: &Capture, frame: usize) -> Result<Vec<Mat4>, EvalError> {
    let skeleton: &Skeleton = &capture.skeleton;
    let mut m = vec![Mat4::IDENTITY; skeleton.len()];
    let pose = capture.poses.get(frame).ok_or_else(|| {
        EvalError::Capture(skinfield_formats::capture::CaptureError::Invalid {
            file: capture.dir.join(skinfield_formats::capture::MANIFEST_FILE),
            field: "frame_count".into(),
            reason: format!("frame {frame} out of range"),
        })
    })?;
    skeleton
        .skinning_matrices(pose, &mut m)
        .map_err(|e| EvalError::Posing {
            frame,
            source: super::PosingError::Runtime(e.into()),
        })?;
    Ok(m)
}

/// The best static weights (see the module docs), fitted to the capture's training frames.
pub fn best_static_weights(capture: &Capture) -> Result<StaticSkin, EvalError> {
    let j = capture.skeleton.len();
    let frames: Vec<(Vec<Mat4>, Vec<Vec3>)> = capture
        .train_frames
        .iter()
        .map(|&f| Ok((matrices(capture, f)?, capture.evaluation_gt_mesh(f)?)))
        .collect::<Result<_, EvalError>>()?;
    let rest = &capture.template.positions;
    let dense: Vec<f32> = rest
        .par_iter()
        .enumerate()
        .flat_map_iter(|(v, &x)| {
            let mut q = vec![0.0f64; j * j];
            let mut c = vec![0.0f64; j];
            let mut cols = vec![Vec3::ZERO; j];
            for (m, truth) in &frames {
                for (k, col) in cols.iter_mut().enumerate() {
                    *col = m[k].transform_point3(x);
                }
                let y = truth[v];
                for a in 0..j {
                    c[a] += f64::from(cols[a].dot(y));
                    for b in a..j {
                        let d = f64::from(cols[a].dot(cols[b]));
                        q[a * j + b] += d;
                        if a != b {
                            q[b * j + a] += d;
                        }
                    }
                }
            }
            simplex_quadratic(&q, &c).into_iter().map(|w| w as f32)
        })
        .collect();
    // The fits lie on the simplex, so the only way this fails is a capture without vertices.
    StaticSkin::from_dense(&dense, j).map_err(|e| EvalError::Template {
        path: capture.dir.clone(),
        reason: format!("best static weights: {e}"),
    })
}

/// The best pose-dependent weights of test frame `frame` within each vertex's `candidates`
/// (dense `[V, J]`), and the template posed with them.
pub fn best_posed_weights(
    capture: &Capture,
    candidates: &[Vec<u16>],
    frame: usize,
) -> Result<Vec<Vec3>, EvalError> {
    let m = matrices(capture, frame)?;
    let truth = capture.evaluation_gt_mesh(frame)?;
    Ok(capture
        .template
        .positions
        .par_iter()
        .zip(candidates)
        .zip(&truth)
        .map(|((&x, set), &y)| {
            let cols: Vec<Vec3> = set
                .iter()
                .map(|&k| m[k as usize].transform_point3(x))
                .collect();
            let n = cols.len();
            let mut q = vec![0.0f64; n * n];
            let mut c = vec![0.0f64; n];
            for a in 0..n {
                c[a] = f64::from(cols[a].dot(y));
                for b in 0..n {
                    q[a * n + b] = f64::from(cols[a].dot(cols[b]));
                }
            }
            let w = simplex_quadratic(&q, &c);
            cols.iter()
                .zip(&w)
                .fold(Vec3::ZERO, |acc, (p, &wi)| acc + *p * wi as f32)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn simplex_projection_is_the_nearest_point_of_the_simplex() {
        let mut v = vec![0.2, 0.3, 0.5];
        project_to_simplex(&mut v);
        assert_eq!(v, vec![0.2, 0.3, 0.5]);
        let mut v = vec![2.0, 0.0, -1.0];
        project_to_simplex(&mut v);
        assert_eq!(v, vec![1.0, 0.0, 0.0]);
        let mut v = vec![0.5, 0.5, 0.5];
        project_to_simplex(&mut v);
        for x in &v {
            assert!((x - 1.0 / 3.0).abs() < 1e-12);
        }
    }

    /// Brute force over a fine grid of the 2-simplex (three weights).
    fn brute(q: &[f64], c: &[f64]) -> (f64, [f64; 3]) {
        let mut best = (f64::INFINITY, [0.0; 3]);
        let n = 600;
        for a in 0..=n {
            for b in 0..=(n - a) {
                let w = [
                    a as f64 / n as f64,
                    b as f64 / n as f64,
                    (n - a - b) as f64 / n as f64,
                ];
                let mut f = 0.0;
                for i in 0..3 {
                    for j in 0..3 {
                        f += w[i] * q[i * 3 + j] * w[j];
                    }
                    f -= 2.0 * c[i] * w[i];
                }
                if f < best.0 {
                    best = (f, w);
                }
            }
        }
        best
    }

    #[test]
    fn the_fit_matches_brute_force_inside_and_on_the_border_of_the_simplex() {
        // Three joints moving a point to a, b, c; targets inside the triangle (exact fit), and
        // outside it (the fit lands on an edge or a corner).
        let (a, b, c) = (
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.5),
        );
        for y in [
            Vec3::new(0.5, 0.3, 0.15),
            Vec3::new(3.0, 2.0, 0.0),
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -0.5, 1.0),
        ] {
            let cols = [a, b, c];
            let mut q = vec![0.0; 9];
            let mut cc = vec![0.0; 3];
            for i in 0..3 {
                cc[i] = f64::from(cols[i].dot(y));
                for j in 0..3 {
                    q[i * 3 + j] = f64::from(cols[i].dot(cols[j]));
                }
            }
            let w = simplex_quadratic(&q, &cc);
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-9 && w.iter().all(|&x| x >= 0.0));
            let f = |w: &[f64]| -> f64 {
                let mut f = 0.0;
                for i in 0..3 {
                    for j in 0..3 {
                        f += w[i] * q[i * 3 + j] * w[j];
                    }
                    f -= 2.0 * cc[i] * w[i];
                }
                f
            };
            let (fb, _) = brute(&q, &cc);
            assert!(f(&w) <= fb + 1e-6, "{y}: fit {} vs brute force {fb}", f(&w));
        }
    }
}
