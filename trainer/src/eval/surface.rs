//! Surface-to-surface distances: area-uniform sampling and the M2S / S2M / Chamfer metrics.
//!
//! M2S is the mean distance from points sampled uniformly by area on the recovered surface to the
//! ground-truth surface; S2M is the reverse; Chamfer is their sum (see `docs/design.md`,
//! *Evaluation*).
//! Distances are exact point-to-triangle distances found through a [`TriangleBvh`].

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::triangle_bvh::TriangleBvh;

/// Points sampled per surface per frame by [`surface_metrics`] callers by default.
///
/// Chosen from the seed-to-seed spread it gives on the built-in capture (see the `eval` module
/// docs): the standard deviation of a frame-averaged M2S between seeds is far below the
/// differences between skinning methods.
pub const DEFAULT_SAMPLES: usize = 20_000;

/// A triangle surface borrowed from a mesh.
#[derive(Clone, Copy, Debug)]
pub struct Surface<'a> {
    /// Vertex positions (metres).
    pub positions: &'a [Vec3],
    /// Triangles indexing `positions`.
    pub triangles: &'a [[u32; 3]],
}

/// Why a surface cannot be measured.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SurfaceError {
    /// The surface has no triangle of positive, finite area.
    #[error("the {which} surface has no triangle of positive area")]
    NoArea {
        /// `recovered` or `ground truth`.
        which: &'static str,
    },
    /// A triangle refers to a vertex that does not exist.
    #[error("the {which} surface's triangle {triangle} refers to a missing vertex")]
    BadIndex {
        /// `recovered` or `ground truth`.
        which: &'static str,
        /// The triangle.
        triangle: usize,
    },
}

/// `count` points distributed uniformly by area over the surface, reproducible from `seed`.
///
/// A triangle is chosen with probability proportional to its area (inverse CDF over cumulative
/// areas in f64), then a point uniformly inside it (`√r₁` barycentric warp). Zero-area triangles
/// are never chosen.
pub fn sample_surface(
    surface: Surface<'_>,
    count: usize,
    seed: u64,
    which: &'static str,
) -> Result<Vec<Vec3>, SurfaceError> {
    let n = surface.positions.len();
    let mut cumulative = Vec::with_capacity(surface.triangles.len());
    let mut total = 0.0f64;
    for (i, t) in surface.triangles.iter().enumerate() {
        if t.iter().any(|&k| k as usize >= n) {
            return Err(SurfaceError::BadIndex { which, triangle: i });
        }
        let [a, b, c] = t.map(|k| surface.positions[k as usize].as_dvec3());
        let area = 0.5 * (b - a).cross(c - a).length();
        if area.is_finite() {
            total += area;
        }
        cumulative.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(SurfaceError::NoArea { which });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = Vec::with_capacity(count);
    for _ in 0..count {
        let x = rng.random::<f64>() * total;
        // First triangle whose cumulative area exceeds x: zero-area triangles share the previous
        // total and can never be the first to exceed it.
        let i = cumulative
            .partition_point(|&c| c <= x)
            .min(cumulative.len() - 1);
        let [a, b, c] = surface.triangles[i].map(|k| surface.positions[k as usize]);
        let (r1, r2): (f32, f32) = (rng.random(), rng.random());
        let s = r1.sqrt();
        points.push(a * (1.0 - s) + b * (s * (1.0 - r2)) + c * (s * r2));
    }
    Ok(points)
}

/// Distance from every point to the surface held by `bvh` (metres), in point order.
#[must_use]
pub fn distances_to(points: &[Vec3], bvh: &TriangleBvh) -> Vec<f32> {
    points
        .par_iter()
        .with_min_len(256)
        .map(|&p| {
            bvh.closest(p)
                .map_or(f32::INFINITY, |c| c.distance_squared.sqrt())
        })
        .collect()
}

/// Mean of distances, summed in f64 in order (deterministic whatever the thread count).
#[must_use]
pub fn mean(values: &[f32]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len() as f64
}

/// M2S and S2M of one frame, and the recovered mesh's vertex furthest off the truth, in metres.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SurfaceMetrics {
    /// Mean distance from the recovered surface to the ground truth.
    pub m2s: f64,
    /// Mean distance from the ground truth to the recovered surface.
    pub s2m: f64,
    /// Largest distance from a vertex of the recovered surface to the ground truth.
    pub max_vertex_off: f64,
}

impl SurfaceMetrics {
    /// `m2s + s2m`.
    #[must_use]
    pub fn chamfer(&self) -> f64 {
        self.m2s + self.s2m
    }
}

/// M2S and S2M between two surfaces from `samples` points on each, and the largest distance
/// from a vertex of `recovered` to `ground_truth` (against the same BVH as M2S).
///
/// The two sample sets use different streams derived from `seed`, and the same `seed` on
/// surfaces with the same triangles gives the same triangle choices, so comparing methods on
/// one frame uses common random numbers.
pub fn surface_metrics(
    recovered: Surface<'_>,
    ground_truth: Surface<'_>,
    samples: usize,
    seed: u64,
) -> Result<SurfaceMetrics, SurfaceError> {
    let on_recovered = sample_surface(recovered, samples, seed, "recovered")?;
    let on_truth = sample_surface(
        ground_truth,
        samples,
        seed ^ 0x05EE_D0F5_7A7E,
        "ground truth",
    )?;
    let truth_bvh = TriangleBvh::new(ground_truth.positions, ground_truth.triangles);
    let recovered_bvh = TriangleBvh::new(recovered.positions, recovered.triangles);
    Ok(SurfaceMetrics {
        m2s: mean(&distances_to(&on_recovered, &truth_bvh)),
        s2m: mean(&distances_to(&on_truth, &recovered_bvh)),
        max_vertex_off: f64::from(
            distances_to(recovered.positions, &truth_bvh)
                .into_iter()
                .fold(0.0f32, f32::max),
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An icosphere of radius `r` with `levels` subdivisions: vertices on the sphere, flat faces.
    pub(crate) fn icosphere(r: f32, levels: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let mut v: Vec<Vec3> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
        .collect();
        let mut f: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..levels {
            let mut mid = std::collections::HashMap::new();
            let mut next = Vec::with_capacity(f.len() * 4);
            let mut midpoint = |a: u32, b: u32, v: &mut Vec<Vec3>| -> u32 {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                    (v.len() - 1) as u32
                })
            };
            for [a, b, c] in f {
                let (ab, bc, ca) = (
                    midpoint(a, b, &mut v),
                    midpoint(b, c, &mut v),
                    midpoint(c, a, &mut v),
                );
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            f = next;
        }
        (v.into_iter().map(|p| p * r).collect(), f)
    }

    #[test]
    fn sphere_against_a_scaled_sphere_is_within_the_tessellation_bound() {
        // Both meshes are the same convex polyhedron P scaled by r1 and r2 about the centre.
        // For a point on face f of the inner one, the distance to the outer surface is
        // min over faces g of (r2 - r1)·h_g + (r1·h_g - n_g·p) ≥ (r2 - r1)·h_min and, with g = f,
        // ≤ (r2 - r1)·h_f ≤ r2 - r1 (h_g: face-plane distance of the unit polyhedron). From the
        // outer surface, the distance is ≥ the separation from the inner face plane under it,
        // (r2 - r1)·h_f, and ≤ the distance to the radially scaled point, ≤ r2 - r1. So both
        // means lie in [(r2 - r1)·h_min, r2 - r1] whatever the samples are.
        let (unit, faces) = icosphere(1.0, 3);
        let h_min = faces
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|k| unit[k as usize]);
                (b - a).cross(c - a).normalize().dot(a).abs()
            })
            .fold(f32::INFINITY, f32::min);
        assert!(h_min > 0.98 && h_min < 1.0, "{h_min}");
        let (r1, r2) = (0.5f32, 0.56f32);
        let inner: Vec<Vec3> = unit.iter().map(|p| *p * r1).collect();
        let outer: Vec<Vec3> = unit.iter().map(|p| *p * r2).collect();
        let m = surface_metrics(
            Surface {
                positions: &inner,
                triangles: &faces,
            },
            Surface {
                positions: &outer,
                triangles: &faces,
            },
            4000,
            1,
        )
        .unwrap();
        let (lo, hi) = (
            f64::from((r2 - r1) * h_min) - 1e-6,
            f64::from(r2 - r1) + 1e-6,
        );
        for (name, d) in [("m2s", m.m2s), ("s2m", m.s2m)] {
            assert!(d >= lo && d <= hi, "{name} = {d} outside [{lo}, {hi}]");
        }
        assert!((m.chamfer() - m.m2s - m.s2m).abs() < 1e-12);
    }

    /// A plane `[x0, x0 + 1] × [0, 1]` at height `z`, with columns of uneven width so that
    /// triangle areas differ (a sampler that ignores area would be biased).
    fn strip(x0: f32, z: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let xs = [0.0, 0.05, 0.1, 0.4, 0.45, 0.5, 0.9, 1.0];
        let ys = [0.0, 0.3, 1.0];
        let mut p = Vec::new();
        for &y in &ys {
            for &x in &xs {
                p.push(Vec3::new(x0 + x, y, z));
            }
        }
        let w = xs.len() as u32;
        let mut t = Vec::new();
        for j in 0..ys.len() as u32 - 1 {
            for i in 0..w - 1 {
                let a = j * w + i;
                t.extend([[a, a + 1, a + w + 1], [a, a + w + 1, a + w]]);
            }
        }
        (p, t)
    }

    #[test]
    fn plane_against_a_shifted_plane() {
        // Shifted along the normal only: every point is exactly d from the other plane.
        let d = 0.03f32;
        let (p0, t0) = strip(0.0, 0.0);
        let (p1, t1) = strip(0.0, d);
        let m = surface_metrics(
            Surface {
                positions: &p0,
                triangles: &t0,
            },
            Surface {
                positions: &p1,
                triangles: &t1,
            },
            5000,
            2,
        )
        .unwrap();
        assert!(
            (m.m2s - f64::from(d)).abs() < 1e-6 && (m.s2m - f64::from(d)).abs() < 1e-6,
            "{m:?}"
        );

        // Shifted by 0.5 sideways as well: half of each strip lies over the other (distance d),
        // the other half at distance sqrt(d² + u²), u uniform in [0, 0.5]. Analytic mean:
        // d/2 + ∫₀^½ sqrt(d² + u²) du, with ∫₀^a = (a·sqrt(a² + d²) + d²·asinh(a/d)) / 2.
        let (d, a) = (0.03f64, 0.5f64);
        let expected = d / 2.0 + (a * (a * a + d * d).sqrt() + d * d * (a / d).asinh()) / 2.0;
        let (p1, t1) = strip(0.5, d as f32);
        let n = 200_000;
        let m = surface_metrics(
            Surface {
                positions: &p0,
                triangles: &t0,
            },
            Surface {
                positions: &p1,
                triangles: &t1,
            },
            n,
            3,
        )
        .unwrap();
        // Per-sample distances lie in [d, sqrt(d² + a²)], so their standard deviation is at most
        // half that range; 5 standard errors of the mean is the tolerance.
        let tol = 5.0 * ((a * a + d * d).sqrt() - d) / 2.0 / (n as f64).sqrt();
        assert!(
            (m.m2s - expected).abs() < tol,
            "m2s {} vs {expected} ± {tol}",
            m.m2s
        );
        assert!(
            (m.s2m - expected).abs() < tol,
            "s2m {} vs {expected} ± {tol}",
            m.s2m
        );
    }

    #[test]
    fn identical_meshes_are_at_distance_zero() {
        let (p, t) = icosphere(0.8, 2);
        let s = Surface {
            positions: &p,
            triangles: &t,
        };
        let m = surface_metrics(s, s, 3000, 9).unwrap();
        assert!(m.m2s < 1e-6 && m.s2m < 1e-6, "{m:?}");
    }

    #[test]
    fn samples_are_reproducible_on_the_surface_and_skip_zero_area_triangles() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(5.0, 5.0, 5.0)];
        // Triangle 1 is degenerate (repeated vertex) and far away: it must never be sampled.
        let t = vec![[0, 1, 2], [3, 3, 3]];
        let s = Surface {
            positions: &p,
            triangles: &t,
        };
        let a = sample_surface(s, 1000, 4, "x").unwrap();
        assert_eq!(a, sample_surface(s, 1000, 4, "x").unwrap());
        assert_ne!(a, sample_surface(s, 1000, 5, "x").unwrap());
        for q in &a {
            assert!(
                q.z == 0.0 && q.x >= 0.0 && q.y >= 0.0 && q.x + q.y <= 1.0 + 1e-6,
                "{q}"
            );
        }
        // Uniform over the triangle: the mean is its centroid (1/3, 1/3) within sampling error.
        let c = a.iter().copied().sum::<Vec3>() / a.len() as f32;
        assert!(
            (c.x - 1.0 / 3.0).abs() < 0.03 && (c.y - 1.0 / 3.0).abs() < 0.03,
            "{c}"
        );
        let bad = vec![[0, 1, 7]];
        assert_eq!(
            sample_surface(
                Surface {
                    positions: &p,
                    triangles: &bad
                },
                10,
                0,
                "x"
            ),
            Err(SurfaceError::BadIndex {
                which: "x",
                triangle: 0
            })
        );
        let flat = vec![[3, 3, 3]];
        assert_eq!(
            sample_surface(
                Surface {
                    positions: &p,
                    triangles: &flat
                },
                10,
                0,
                "x"
            ),
            Err(SurfaceError::NoArea { which: "x" })
        );
    }
}
