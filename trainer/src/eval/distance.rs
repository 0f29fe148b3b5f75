//! Exact closest point on a triangle (Ericson, *Real-Time Collision Detection*, §5.1.5).
//!
//! The point's Voronoi region of the triangle (one of three vertices, three edges or the face)
//! is found from six dot products; the closest point follows in closed form. Degenerate
//! (zero-area) triangles fall back to the closest point on their three edges, so the result is
//! always finite for finite input.

use glam::Vec3;

/// The Voronoi region of a triangle that a query point falls in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Region {
    /// Closest to vertex `a`, `b` or `c` (index 0, 1, 2).
    Vertex(u8),
    /// Closest to the interior of edge `ab` (0), `bc` (1) or `ca` (2).
    Edge(u8),
    /// Projects into the interior of the face.
    Face,
}

/// Closest point of the segment `[a, b]` to `p`; `t` is clamped, so a zero-length segment gives `a`.
#[must_use]
pub fn closest_point_on_segment(p: Vec3, a: Vec3, b: Vec3) -> Vec3 {
    let ab = b - a;
    let len2 = ab.length_squared();
    if len2 <= 0.0 {
        return a;
    }
    let t = ((p - a).dot(ab) / len2).clamp(0.0, 1.0);
    a + ab * t
}

/// Closest point of triangle `(a, b, c)` to `p` and the Voronoi region it lies in.
#[must_use]
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, Region) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, Region::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, Region::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, Region::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, Region::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, Region::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, Region::Edge(1));
    }
    let sum = va + vb + vc;
    let q = a + ab * (vb / sum) + ac * (vc / sum);
    if sum > 0.0 && q.is_finite() {
        return (q, Region::Face);
    }
    // Zero area: the face region is empty, so the answer is on one of the edges.
    let candidates = [
        (closest_point_on_segment(p, a, b), Region::Edge(0)),
        (closest_point_on_segment(p, b, c), Region::Edge(1)),
        (closest_point_on_segment(p, c, a), Region::Edge(2)),
    ];
    let mut best = candidates[0];
    for cand in &candidates[1..] {
        if (cand.0 - p).length_squared() < (best.0 - p).length_squared() {
            best = *cand;
        }
    }
    best
}

/// Squared distance from `p` to triangle `(a, b, c)`.
#[must_use]
pub fn point_triangle_distance_squared(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
    (closest_point_on_triangle(p, a, b, c).0 - p).length_squared()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::collections::HashSet;

    /// An independent reference: the plane projection when it lands inside the triangle
    /// (tested with barycentric coordinates in f64), otherwise the nearest of the three edges.
    fn reference_distance(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f64 {
        let (p, a, b, c) = (p.as_dvec3(), a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
        let n = (b - a).cross(c - a);
        let n2 = n.length_squared();
        let mut best = f64::INFINITY;
        if n2 > 1e-24 {
            let q = p - n * ((p - a).dot(n) / n2);
            // Barycentric coordinates from signed sub-areas.
            let u = (b - q).cross(c - q).dot(n) / n2;
            let v = (c - q).cross(a - q).dot(n) / n2;
            let w = 1.0 - u - v;
            if u >= 0.0 && v >= 0.0 && w >= 0.0 {
                best = (p - q).length();
            }
        }
        for (s, e) in [(a, b), (b, c), (c, a)] {
            let d = e - s;
            let t = if d.length_squared() > 0.0 {
                ((p - s).dot(d) / d.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            best = best.min((p - (s + d * t)).length());
        }
        best
    }

    fn random_vec(rng: &mut ChaCha8Rng, scale: f32) -> Vec3 {
        Vec3::new(
            rng.random_range(-scale..scale),
            rng.random_range(-scale..scale),
            rng.random_range(-scale..scale),
        )
    }

    #[test]
    fn matches_an_independent_reference_in_every_voronoi_region() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut regions = HashSet::new();
        for _ in 0..200 {
            let (a, b, c) = (
                random_vec(&mut rng, 1.0),
                random_vec(&mut rng, 1.0),
                random_vec(&mut rng, 1.0),
            );
            for _ in 0..100 {
                let p = random_vec(&mut rng, 2.0);
                let (q, region) = closest_point_on_triangle(p, a, b, c);
                regions.insert(region);
                let got = f64::from((q - p).length());
                let want = reference_distance(p, a, b, c);
                assert!(
                    (got - want).abs() < 1e-5 * (1.0 + want),
                    "{got} vs {want} for {p} in {region:?}"
                );
                // The answer must be a point of the triangle: its distance to the triangle is ~0.
                assert!(reference_distance(q, a, b, c) < 1e-5);
            }
        }
        assert_eq!(
            regions.len(),
            7,
            "not every region was exercised: {regions:?}"
        );
    }

    #[test]
    fn no_point_of_a_fine_barycentric_grid_is_closer() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 60;
        for _ in 0..40 {
            let (a, b, c) = (
                random_vec(&mut rng, 1.0),
                random_vec(&mut rng, 1.0),
                random_vec(&mut rng, 1.0),
            );
            let p = random_vec(&mut rng, 2.0);
            let got = point_triangle_distance_squared(p, a, b, c).sqrt();
            let mut grid_min = f32::INFINITY;
            for i in 0..=n {
                for j in 0..=(n - i) {
                    let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                    let q = a + (b - a) * u + (c - a) * v;
                    grid_min = grid_min.min((q - p).length());
                }
            }
            // The exact minimum is below every grid point and within one grid step of the best one.
            let step = ((b - a).length() + (c - a).length()) / n as f32;
            assert!(got <= grid_min + 1e-5, "{got} > grid {grid_min}");
            assert!(grid_min - got <= step, "{got} far below grid {grid_min}");
        }
    }

    #[test]
    fn degenerate_triangles_give_the_distance_to_their_segment() {
        let (a, b) = (Vec3::ZERO, Vec3::X);
        // Collinear: c in the middle of ab; and fully collapsed to a point.
        let p = Vec3::new(0.5, 1.0, 0.0);
        let d = point_triangle_distance_squared(p, a, b, Vec3::new(0.5, 0.0, 0.0)).sqrt();
        assert!((d - 1.0).abs() < 1e-6, "{d}");
        let d = point_triangle_distance_squared(p, a, a, a).sqrt();
        assert!((d - p.length()).abs() < 1e-6, "{d}");
        let p = Vec3::new(2.0, 0.0, 0.0);
        let d = point_triangle_distance_squared(p, a, b, Vec3::new(0.5, 0.0, 0.0)).sqrt();
        assert!((d - 1.0).abs() < 1e-6, "{d}");
    }
}
