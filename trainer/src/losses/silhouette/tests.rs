use super::*;
use candle_core::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A 5 × 5 vertex grid in image space, spacing `s` px from `origin`, jittered, two triangles
/// per cell.
fn grid_uv(origin: [f32; 2], s: f32, jitter: f32, seed: u64) -> (Vec<[f32; 2]>, Vec<[u32; 3]>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let uv = (0..25)
        .map(|i| {
            [
                origin[0] + s * (i % 5) as f32 + rng.random_range(-jitter..=jitter),
                origin[1] + s * (i / 5) as f32 + rng.random_range(-jitter..=jitter),
            ]
        })
        .collect();
    let mut t = Vec::new();
    for y in 0..4u32 {
        for x in 0..4u32 {
            let i = y * 5 + x;
            t.push([i, i + 1, i + 6]);
            t.push([i, i + 6, i + 5]);
        }
    }
    (uv, t)
}

fn rect_mask(
    w: usize,
    h: usize,
    x: std::ops::Range<usize>,
    y: std::ops::Range<usize>,
) -> Vec<bool> {
    (0..w * h)
        .map(|i| x.contains(&(i % w)) && y.contains(&(i / w)))
        .collect()
}

#[test]
fn nearest_points_equals_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let pts: Vec<[f32; 2]> = (0..500)
        .map(|_| [rng.random_range(0.0..300.0), rng.random_range(0.0..200.0)])
        .collect();
    let cand: Vec<u32> = (0..500).filter(|i| i % 3 != 0).collect();
    let queries: Vec<[f32; 2]> = (0..300)
        .map(|_| {
            [
                rng.random_range(-50.0..350.0),
                rng.random_range(-50.0..250.0),
            ]
        })
        .collect();
    let got = nearest_points(&pts, &cand, &queries);
    for (q, g) in queries.iter().zip(&got) {
        let d = |i: u32| (pts[i as usize][0] - q[0]).powi(2) + (pts[i as usize][1] - q[1]).powi(2);
        let best = cand
            .iter()
            .copied()
            .min_by(|&a, &b| d(a).total_cmp(&d(b)))
            .unwrap();
        assert_eq!(d(*g), d(best), "{q:?}");
    }
    assert!(nearest_points(&pts, &[], &queries).is_empty());
}

#[test]
fn coverage_and_boundary_of_a_projected_grid() {
    // Square from (10, 10) to (50, 50): pixel centres 10.5..49.5 → 40 × 40 pixels.
    let (uv, t) = grid_uv([10.0, 10.0], 10.0, 0.0, 0);
    let valid = vec![true; 25];
    let cover = coverage_mask(64, 64, &uv, &valid, &t);
    assert_eq!(cover.iter().filter(|&&c| c).count(), 40 * 40);
    let b = boundary_vertices(64, 64, &uv, &valid, &t);
    let rim: Vec<u32> = (0..25)
        .filter(|i| i % 5 == 0 || i % 5 == 4 || i / 5 == 0 || i / 5 == 4)
        .collect();
    assert_eq!(b, rim);
    // A vertex behind the camera removes its triangles.
    let mut valid = vec![true; 25];
    valid[0] = false;
    let cover2 = coverage_mask(64, 64, &uv, &valid, &t);
    assert!(cover2.iter().filter(|&&c| c).count() < 40 * 40);
}

/// Independent reference of Eq. 10 by brute force over contour pixels (each pulls the nearest
/// projected boundary vertex).
fn brute_terms(mask: &[bool], w: usize, uv: &[[f32; 2]], boundary: &[u32]) -> (f64, f64) {
    let c = crate::distance_transform::mask_contour(w, mask.len() / w, mask).unwrap();
    let centres: Vec<[f64; 2]> = (0..c.len())
        .filter(|&i| c[i])
        .map(|i| [(i % w) as f64 + 0.5, (i / w) as f64 + 0.5])
        .collect();
    let dist = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    // d at a point = bilinear interpolation of the per-pixel exact distances.
    let d_pix = |x: usize, y: usize| {
        centres
            .iter()
            .map(|&p| dist(p, [x as f64 + 0.5, y as f64 + 0.5]))
            .fold(f64::INFINITY, f64::min)
    };
    let mut t1 = 0.0;
    for &i in boundary {
        let [u, v] = uv[i as usize].map(f64::from);
        let (x, y) = (u - 0.5, v - 0.5);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        t1 += d_pix(x0, y0) * (1.0 - fx) * (1.0 - fy)
            + d_pix(x0 + 1, y0) * fx * (1.0 - fy)
            + d_pix(x0, y0 + 1) * (1.0 - fx) * fy
            + d_pix(x0 + 1, y0 + 1) * fx * fy;
    }
    let t2 = centres
        .iter()
        .map(|&p| {
            boundary
                .iter()
                .map(|&i| dist(p, uv[i as usize].map(f64::from)))
                .fold(f64::INFINITY, f64::min)
        })
        .sum();
    (t1, t2)
}

#[test]
fn value_equals_brute_force_reference() {
    let (w, h) = (64, 48);
    // The mask is wider than the projected mesh on the right and shorter at the bottom.
    let mask = rect_mask(w, h, 12..56, 9..40);
    let target = SilhouetteTarget::from_mask(w, h, &mask).unwrap();
    let (uv, t) = grid_uv([10.0, 8.0], 9.0, 1.5, 3);
    let valid = vec![true; 25];
    let x = Tensor::from_vec(
        uv.iter().flatten().copied().collect::<Vec<f32>>(),
        (25, 2),
        &Device::Cpu,
    )
    .unwrap();
    let terms = silhouette_terms(&target, &x, &valid, &t).unwrap();
    assert_eq!(terms.boundary_count, 16);
    let b = boundary_vertices(w, h, &uv, &valid, &t);
    let (t1, t2) = brute_terms(&mask, w, &uv, &b);
    let got1 = f64::from(terms.boundary.to_vec0::<f32>().unwrap());
    let got2 = f64::from(terms.contour.to_vec0::<f32>().unwrap());
    assert!(
        (got1 - t1).abs() < 1e-3 * t1.max(1.0),
        "boundary term {got1} vs {t1}"
    );
    assert!(
        (got2 - t2).abs() < 1e-3 * t2.max(1.0),
        "contour term {got2} vs {t2}"
    );
    assert!(t1 > 1.0 && t2 > 1.0);
    assert_eq!(terms.contour_count, target.contour.len());
}

#[test]
fn gradient_matches_finite_differences() {
    let (w, h) = (64, 48);
    let target = SilhouetteTarget::from_mask(w, h, &rect_mask(w, h, 12..56, 9..40)).unwrap();
    let (uv, t) = grid_uv([10.0, 8.0], 9.0, 1.5, 4);
    let valid = vec![true; 25];
    let x0 = Tensor::from_vec(
        uv.iter()
            .flatten()
            .map(|&v| f64::from(v))
            .collect::<Vec<f64>>(),
        (25, 2),
        &Device::Cpu,
    )
    .unwrap();
    // Selections are constants of a step; with 1e-6 steps on jittered positions they do not flip.
    crate::losses::fd::check(&x0, 1e-6, 1e-6, 1e-5, |x| {
        let terms = silhouette_terms(&target, x, &valid, &t).unwrap();
        (terms.boundary + terms.contour).unwrap()
    });
}

#[test]
fn empty_mask_is_an_error() {
    assert!(SilhouetteTarget::from_mask(4, 4, &[false; 16]).is_err());
}
