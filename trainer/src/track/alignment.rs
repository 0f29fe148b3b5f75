//! The global alignment layer (DeepCap Eqs. 2–5): the translation `t` that best places rotated
//! landmarks on the rays through their 2D detections, in closed form, and its derivative with
//! respect to the landmarks (the layer is differentiated through by the tracker).
//!
//! ```text
//! t = argmin Σ_r w_r ‖(X_r + t − o_r) × d_r‖²
//!   = W⁻¹ Σ_r w_r (I − d_r d_rᵀ)(o_r − X_r),        W = Σ_r w_r (I − d_r d_rᵀ)
//! ```
//!
//! since `‖v × d‖² = vᵀ(I − d dᵀ)v` for a unit `d` (the squared distance of `X + t` to the ray).
//! DeepCap weights each ray by its detection confidence (zero below 0.4); the tracker adds its
//! keypoint weights and robust reweighting. `∂t/∂X_r = −W⁻¹ w_r (I − d_r d_rᵀ)`.

use glam::{DMat3, DVec3};

/// A ray from a camera centre through a detection, with its weight in Eq. 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Camera centre `o`.
    pub origin: DVec3,
    /// Unit direction `d`.
    pub direction: DVec3,
    /// Weight (confidence times keypoint weight; ≥ 0).
    pub weight: f64,
}

impl Ray {
    /// `w (I − d dᵀ)`.
    fn projector(&self) -> DMat3 {
        let d = self.direction;
        (DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z)) * self.weight
    }
}

/// The solved translation and what its derivative needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// The translation `t` (world units).
    pub translation: DVec3,
    w_inverse: DMat3,
}

/// Smallest accepted `|det W|` relative to the cube of its trace: below it the rays do not pin
/// `t` down in every direction (all parallel, or fewer than two cameras).
const MIN_RELATIVE_DET: f64 = 1e-12;

/// Solves Eq. 4 for landmarks `points[r]` seen along `rays[r]`. `None` when the weighted rays
/// do not determine the translation (`W` singular: no rays, or all parallel).
#[must_use]
pub fn global_alignment(points: &[DVec3], rays: &[Ray]) -> Option<Alignment> {
    let mut w = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for (x, ray) in points.iter().zip(rays) {
        let p = ray.projector();
        w += p;
        b += p * (ray.origin - *x);
    }
    let trace = w.x_axis.x + w.y_axis.y + w.z_axis.z;
    let det = w.determinant();
    if !(trace > 0.0 && det.abs() > MIN_RELATIVE_DET * trace * trace * trace) {
        return None;
    }
    let w_inverse = w.inverse();
    Some(Alignment {
        translation: w_inverse * b,
        w_inverse,
    })
}

impl Alignment {
    /// `∂t/∂X_r` for the point seen along `ray`: `−W⁻¹ w_r (I − d_r d_rᵀ)` (column `k` is the
    /// change of `t` per unit change of `X_r`'s coordinate `k`).
    #[must_use]
    pub fn jacobian(&self, ray: &Ray) -> DMat3 {
        -(self.w_inverse * ray.projector())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_rays(rng: &mut ChaCha8Rng, n: usize) -> (Vec<DVec3>, Vec<Ray>) {
        let mut v = || {
            DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let points: Vec<DVec3> = (0..n).map(|_| v() * 0.5).collect();
        let rays = (0..n)
            .map(|_| {
                let origin = v() * 3.0 + DVec3::new(0.0, 0.0, 4.0);
                let direction = (v() - origin).normalize();
                Ray {
                    origin,
                    direction,
                    weight: 0.5 + (v().x + 1.0),
                }
            })
            .collect();
        (points, rays)
    }

    /// Σ w ‖(X + t − o) × d‖².
    fn energy(points: &[DVec3], rays: &[Ray], t: DVec3) -> f64 {
        points
            .iter()
            .zip(rays)
            .map(|(x, r)| r.weight * (*x + t - r.origin).cross(r.direction).length_squared())
            .sum()
    }

    #[test]
    fn closed_form_equals_a_brute_force_least_squares_solve() {
        // Brute force: stack the cross-product residuals √w (X + t − o) × d, linear in t, as a
        // 3R × 3 system A t = c and solve its normal equations by Gaussian elimination with
        // partial pivoting (independent of the projector algebra above).
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for n in [2, 3, 10, 40] {
            let (points, rays) = random_rays(&mut rng, n);
            let t = global_alignment(&points, &rays).unwrap().translation;
            let mut ata = [[0.0f64; 3]; 3];
            let mut atc = [0.0f64; 3];
            for (x, r) in points.iter().zip(&rays) {
                let s = r.weight.sqrt();
                // (X − o + t) × d = (X − o) × d − d × t; rows of −[d]× times t.
                let d = r.direction;
                let cross_d = [[0.0, d.z, -d.y], [-d.z, 0.0, d.x], [d.y, -d.x, 0.0]];
                let rhs = -((*x - r.origin).cross(d));
                for row in 0..3 {
                    let a: Vec<f64> = (0..3).map(|k| s * cross_d[row][k]).collect();
                    for i in 0..3 {
                        for k in 0..3 {
                            ata[i][k] += a[i] * a[k];
                        }
                        atc[i] += a[i] * s * rhs[row];
                    }
                }
            }
            let mut m = [[0.0; 4]; 3];
            for i in 0..3 {
                m[i][..3].copy_from_slice(&ata[i]);
                m[i][3] = atc[i];
            }
            for c in 0..3 {
                let p = (c..3)
                    .max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs()))
                    .unwrap();
                m.swap(c, p);
                let pivot = m[c];
                for (r, row) in m.iter_mut().enumerate() {
                    if r != c {
                        let f = row[c] / pivot[c];
                        for (x, p) in row.iter_mut().zip(pivot).skip(c) {
                            *x -= f * p;
                        }
                    }
                }
            }
            let brute = DVec3::new(m[0][3] / m[0][0], m[1][3] / m[1][1], m[2][3] / m[2][2]);
            assert!((t - brute).length() < 1e-10, "{n} rays: {t} vs {brute}");
            // And it is a minimum: every small step raises the energy.
            let e0 = energy(&points, &rays, t);
            for dir in [DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE.normalize()] {
                assert!(energy(&points, &rays, t + dir * 1e-4) > e0);
                assert!(energy(&points, &rays, t - dir * 1e-4) > e0);
            }
        }
    }

    #[test]
    fn jacobian_matches_central_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (points, rays) = random_rays(&mut rng, 12);
        let a = global_alignment(&points, &rays).unwrap();
        let h = 1e-6;
        for r in [0, 5, 11] {
            let jac = a.jacobian(&rays[r]);
            for k in 0..3 {
                let mut plus = points.clone();
                let mut minus = points.clone();
                plus[r][k] += h;
                minus[r][k] -= h;
                let tp = global_alignment(&plus, &rays).unwrap().translation;
                let tm = global_alignment(&minus, &rays).unwrap().translation;
                let fd = (tp - tm) / (2.0 * h);
                let col = jac.col(k);
                assert!(
                    (fd - col).length() < 1e-8,
                    "ray {r} axis {k}: {fd} vs {col}"
                );
            }
        }
    }

    #[test]
    fn exact_rays_recover_the_translation_and_parallel_rays_are_refused() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (points, mut rays) = random_rays(&mut rng, 6);
        let truth = DVec3::new(0.3, -1.2, 0.7);
        for (x, r) in points.iter().zip(&mut rays) {
            r.direction = (*x + truth - r.origin).normalize();
        }
        let t = global_alignment(&points, &rays).unwrap().translation;
        assert!((t - truth).length() < 1e-12, "{t}");
        // One camera looking along one direction: `t` is free along it.
        for r in &mut rays {
            r.direction = DVec3::Z;
        }
        assert!(global_alignment(&points, &rays).is_none());
        assert!(global_alignment(&[], &[]).is_none());
    }
}
