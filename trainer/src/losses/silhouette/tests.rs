use super::*;
use candle_core::{Device, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A latitude–longitude sphere, outward winding, poles as single vertices.
pub(crate) fn uv_sphere(
    rings: u32,
    segments: u32,
    radius: f32,
    centre: Vec3,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = vec![centre + Vec3::Y * radius];
    for r in 1..rings {
        let th = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let ph = std::f32::consts::TAU * s as f32 / segments as f32;
            p.push(centre + Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin()) * radius);
        }
    }
    p.push(centre - Vec3::Y * radius);
    let south = p.len() as u32 - 1;
    let at = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
    let mut t = Vec::new();
    for s in 0..segments {
        t.push([0, at(1, s + 1), at(1, s)]);
        t.push([south, at(rings - 1, s), at(rings - 1, s + 1)]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            t.push([at(r, s), at(r, s + 1), at(r + 1, s + 1)]);
            t.push([at(r, s), at(r + 1, s + 1), at(r + 1, s)]);
        }
    }
    (p, t)
}

fn camera(w: u32) -> Camera {
    Camera::look_at(
        "c",
        w,
        w,
        0.7,
        Vec3::new(0.3, 0.4, 3.0),
        Vec3::ZERO,
        Vec3::Y,
    )
}

fn normals(p: &[Vec3], centre: Vec3) -> Vec<Vec3> {
    p.iter().map(|&x| (x - centre).normalize()).collect()
}

/// The loss of one view of `positions` (both terms, normalised like the batch op).
fn loss_of(
    camera: &Camera,
    target: &SilhouetteTarget,
    p: &[Vec3],
    t: &[[u32; 3]],
    table: &EdgeTable,
) -> (f64, f64, ViewTerms) {
    let v = view_terms(camera, target, p, t, table, DEFAULT_HUBER_PX);
    (
        v.boundary / v.boundary_count.max(1) as f64,
        v.contour / v.contour_weight.max(1e-12),
        v,
    )
}

#[test]
fn values_equal_brute_force_over_segments_and_edges() {
    let cam = camera(96);
    let (p, t) = uv_sphere(24, 40, 0.5, Vec3::ZERO);
    let table = EdgeTable::new(p.len(), &t);
    // The target: a bigger, shifted sphere's coverage.
    let (q, tq) = uv_sphere(24, 40, 0.56, Vec3::new(0.04, 0.0, 0.0));
    let cov = crate::raster::coverage(&cam, &q, &tq, 4);
    let target = SilhouetteTarget::from_coverage(96, 96, &cov).unwrap();
    let v = view_terms(&cam, &target, &p, &t, &table, DEFAULT_HUBER_PX);
    assert!(v.boundary_count > 40, "{}", v.boundary_count);
    let uv: Vec<Vec2> = p.iter().map(|&x| cam.project(x).unwrap()).collect();
    let brute_d = |x: Vec2| {
        target
            .outline
            .segments
            .iter()
            .map(|&s| (closest_on_segment(s, x).0 - x).length())
            .fold(f32::INFINITY, f32::min)
    };
    let boundary: f64 = v
        .boundary_vertices
        .iter()
        .map(|&i| f64::from(huber(brute_d(uv[i as usize]), DEFAULT_HUBER_PX).0))
        .sum();
    assert!(
        (v.boundary - boundary).abs() < 1e-3 * boundary.max(1.0),
        "{} vs {boundary}",
        v.boundary
    );
    // The outline edges, projected.
    let geometry = ViewGeometry::new(&cam, &p);
    let outline = mesh_outline(&cam, &p, &t, &table, &geometry);
    assert_eq!(outline.vertices, v.boundary_vertices);
    let segs: Vec<[Vec2; 2]> = outline
        .edges
        .iter()
        .map(|&e| table.edges[e as usize].map(|i| uv[i as usize]))
        .collect();
    let mut contour = 0.0f64;
    for (&c, &w) in target.contour.iter().zip(target.contour_weights.iter()) {
        let r = segs
            .iter()
            .map(|&s| (closest_on_segment(s, c).0 - c).length())
            .fold(f32::INFINITY, f32::min);
        contour += f64::from(w * huber(r, DEFAULT_HUBER_PX).0);
    }
    assert!(
        (v.contour - contour).abs() < 1e-3 * contour.max(1.0),
        "{} vs {contour}",
        v.contour
    );
    assert!(
        boundary > 1.0 && contour > 1.0,
        "the scene must have residuals"
    );
}

#[test]
fn the_batch_op_gradient_matches_finite_differences() {
    let cam = camera(96);
    let (p, t) = uv_sphere(16, 24, 0.5, Vec3::ZERO);
    let (q, tq) = uv_sphere(16, 24, 0.6, Vec3::new(0.05, -0.03, 0.0));
    let cov = crate::raster::coverage(&cam, &q, &tq, 4);
    let target = SilhouetteTarget::from_coverage(96, 96, &cov).unwrap();
    let table = Arc::new(EdgeTable::new(p.len(), &t));
    let tri: Arc<[[u32; 3]]> = t.clone().into();
    let views = vec![BatchView {
        frame: 0,
        camera: cam.clone(),
        target: target.clone(),
    }];
    let flat: Vec<f32> = p.iter().flat_map(|x| x.to_array()).collect();
    let x =
        Var::from_tensor(&Tensor::from_vec(flat, (1, p.len(), 3), &Device::Cpu).unwrap()).unwrap();
    let out = SilhouetteLoss::new(views, tri, table.clone(), DEFAULT_HUBER_PX)
        .apply(x.as_tensor())
        .unwrap();
    let values = out.to_vec1::<f32>().unwrap();
    // d(boundary + 2·contour)/dx.
    let w = Tensor::new(&[1.0f32, 2.0, 0.0, 0.0], &Device::Cpu).unwrap();
    let g = (out * w).unwrap().sum_all().unwrap().backward().unwrap();
    let g = g
        .get(x.as_tensor())
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1::<f32>()
        .unwrap();
    let (b0, c0, terms) = loss_of(&cam, &target, &p, &t, &table);
    assert!((f64::from(values[0]) - b0).abs() < 1e-5 && (f64::from(values[1]) - c0).abs() < 1e-5);
    let f = |p: &[Vec3]| {
        let (b, c, _) = loss_of(&cam, &target, p, &t, &table);
        b + 2.0 * c
    };
    let mut checked = 0;
    for &i in terms.boundary_vertices.iter().step_by(3) {
        for k in 0..3 {
            // f32 positions: steps much below a millimetre drown in rounding (the projection
            // moves by ~0.04 px at this step, too little to change any selection).
            let h = 1e-3f32;
            let mut a = p.clone();
            let mut b = p.clone();
            a[i as usize][k] += h;
            b[i as usize][k] -= h;
            // Selections are constants of a step: skip a coordinate whose step changes them.
            let sel = |p: &[Vec3]| loss_of(&cam, &target, p, &t, &table).2.boundary_vertices;
            if sel(&a) != terms.boundary_vertices || sel(&b) != terms.boundary_vertices {
                continue;
            }
            let fd = (f(&a) - f(&b)) / (2.0 * f64::from(h));
            let got = f64::from(g[3 * i as usize + k]);
            assert!(
                (got - fd).abs() <= 3e-2 * fd.abs() + 2e-3,
                "vertex {i} axis {k}: {got} vs {fd}"
            );
            checked += usize::from(fd.abs() > 1e-2);
        }
    }
    assert!(checked > 10, "only {checked} non-trivial derivatives");
}

/// The loss of a sphere moved along its normals by `delta` (metres) against the coverage of
/// the sphere itself, and the mean absolute outward gradient per boundary vertex.
fn sweep_at(delta: f32) -> (f64, f64) {
    let cam = camera(128);
    let (p, t) = uv_sphere(40, 64, 0.5, Vec3::ZERO);
    let table = EdgeTable::new(p.len(), &t);
    let cov = crate::raster::coverage(&cam, &p, &t, 4);
    let target = SilhouetteTarget::from_coverage(128, 128, &cov).unwrap();
    let n = normals(&p, Vec3::ZERO);
    let moved: Vec<Vec3> = p.iter().zip(&n).map(|(&x, &m)| x + m * delta).collect();
    let (b, c, v) = loss_of(&cam, &target, &moved, &t, &table);
    let mut force = 0.0;
    let mut count = 0;
    let mut g = vec![Vec3::ZERO; p.len()];
    for &(i, d) in v.boundary_grad.iter().chain(&v.contour_grad) {
        g[i as usize] += d;
    }
    for &i in &v.boundary_vertices {
        force += f64::from(g[i as usize].dot(n[i as usize]).abs());
        count += 1;
    }
    (b + c, force / count.max(1) as f64)
}

#[test]
fn the_true_outline_minimises_the_loss_and_feels_no_force() {
    // One pixel ≈ depth / focal length at the sphere's silhouette.
    let cam = camera(128);
    let px = cam.center().length() / cam.fx;
    let deltas: Vec<f32> = (-8..=8).map(|k| k as f32 * 0.125 * px).collect();
    let losses: Vec<f64> = deltas.iter().map(|&d| sweep_at(d).0).collect();
    let best = (0..losses.len())
        .min_by(|&a, &b| losses[a].total_cmp(&losses[b]))
        .unwrap();
    assert!(
        best > 0 && best + 1 < losses.len(),
        "minimum at the sweep's end: {losses:?}"
    );
    // Vertex of the parabola through the minimum and its neighbours.
    let (l0, l1, l2) = (losses[best - 1], losses[best], losses[best + 1]);
    let step = f64::from(0.125f32);
    let offset = 0.5 * step * (l0 - l2) / (l0 - 2.0 * l1 + l2);
    let minimum_px = (best as f64 - 8.0) * step + offset;
    assert!(
        minimum_px.abs() < 0.1,
        "the loss is smallest {minimum_px:.3} px off the truth"
    );
    let (_, force_truth) = sweep_at(0.0);
    let (_, force_off) = sweep_at(0.5 * px);
    assert!(
        force_truth < 0.25 * force_off,
        "mean |outward gradient| per vertex at the truth {force_truth:.3e}, half a pixel out {force_off:.3e}"
    );
}

#[test]
fn hidden_contour_generators_are_not_boundary_vertices() {
    // A small sphere in front of a big one, entirely inside its silhouette.
    let cam = camera(96);
    let (mut p, mut t) = uv_sphere(16, 24, 0.6, Vec3::ZERO);
    let (q, tq) = uv_sphere(10, 16, 0.1, Vec3::new(0.05, 0.05, 0.9));
    let off = p.len() as u32;
    p.extend(q);
    t.extend(tq.iter().map(|tri| tri.map(|i| i + off)));
    let table = EdgeTable::new(p.len(), &t);
    let cov = crate::raster::coverage(&cam, &p, &t, 4);
    let target = SilhouetteTarget::from_coverage(96, 96, &cov).unwrap();
    let v = view_terms(&cam, &target, &p, &t, &table, DEFAULT_HUBER_PX);
    assert!(v.boundary_count > 20);
    assert!(
        v.boundary_vertices.iter().all(|&i| i < off),
        "a hidden vertex counts as boundary"
    );
}

#[test]
fn nearest_segments_equal_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let segs: Vec<[Vec2; 2]> = (0..300)
        .map(|_| {
            let a = Vec2::new(rng.random_range(0.0..300.0), rng.random_range(0.0..200.0));
            [
                a,
                a + Vec2::new(rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0)),
            ]
        })
        .collect();
    let grid = SegmentGrid::new(&segs);
    for _ in 0..500 {
        let q = Vec2::new(
            rng.random_range(-50.0..350.0),
            rng.random_range(-50.0..250.0),
        );
        let (_, _, d) = grid.nearest(&segs, q).unwrap();
        let want = segs
            .iter()
            .map(|&s| (closest_on_segment(s, q).0 - q).length_squared())
            .fold(f32::INFINITY, f32::min);
        assert!(
            (d - want).abs() <= 1e-3 * want.max(1.0),
            "{q}: {d} vs {want}"
        );
    }
}

#[test]
fn huber_is_quadratic_then_linear_and_continuous() {
    assert_eq!(huber(0.0, 1.0), (0.0, 0.0));
    assert_eq!(huber(0.5, 1.0), (0.125, 0.5));
    assert_eq!(huber(3.0, 1.0), (2.5, 1.0));
    let (a, _) = huber(1.0 - 1e-6, 1.0);
    let (b, _) = huber(1.0 + 1e-6, 1.0);
    assert!((a - b).abs() < 1e-5);
}

#[test]
fn empty_mask_is_an_error() {
    assert!(SilhouetteTarget::from_mask(4, 4, &[false; 16]).is_err());
}

#[test]
fn cell_lists_equal_brute_force() {
    // Random inclusive cell ranges on a 7 × 5 grid, one-cell and whole-grid ranges included.
    let dims = [7i64, 5];
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut ranges: Vec<(i64, i64, i64, i64)> = (0..60)
        .map(|_| {
            let (xa, xb) = (rng.random_range(0..7), rng.random_range(0..7));
            let (ya, yb) = (rng.random_range(0..5), rng.random_range(0..5));
            (xa.min(xb), ya.min(yb), xa.max(xb), ya.max(yb))
        })
        .collect();
    ranges.extend([(3, 2, 3, 2), (0, 0, 6, 4), (6, 4, 6, 4)]);
    let (start, items) = cell_lists(&ranges, dims, |r| *r);
    assert_eq!(start.len(), 36);
    for y in 0..5 {
        for x in 0..7 {
            let c = (y * 7 + x) as usize;
            let expected: Vec<u32> = (0..ranges.len() as u32)
                .filter(|&i| {
                    let (x0, y0, x1, y1) = ranges[i as usize];
                    (x0..=x1).contains(&x) && (y0..=y1).contains(&y)
                })
                .collect();
            assert_eq!(
                &items[start[c]..start[c + 1]],
                &expected[..],
                "cell ({x}, {y})"
            );
        }
    }
}

/// The two objectives of a mesh `p` against `target` at outline offset `b`: the Huber terms
/// the weights fit and the distances the offsets fit, each normalised like the batch op.
fn objectives_at(
    cam: &Camera,
    target: &SilhouetteTarget,
    p: &[Vec3],
    t: &[[u32; 3]],
    table: &EdgeTable,
    b: f32,
) -> (f64, f64) {
    let v = view_terms_with_offset(cam, target, p, t, table, DEFAULT_HUBER_PX, b);
    let count = v.boundary_count.max(1) as f64;
    let weight = v.contour_weight.max(1e-12);
    (
        v.boundary / count + v.contour / weight,
        v.boundary_distance / count + v.contour_distance / weight,
    )
}

/// The offset of `offsets` at which `losses` is smallest.
fn argmin(offsets: &[f32], losses: &[f64]) -> f32 {
    let best = (0..losses.len())
        .min_by(|&a, &b| losses[a].total_cmp(&losses[b]))
        .unwrap();
    offsets[best]
}

/// Both objectives of the mesh `p` against the coverage of `q` (both of triangles `t`) at every
/// offset of `offsets`.
fn offset_sweep(p: &[Vec3], q: &[Vec3], t: &[[u32; 3]], offsets: &[f32]) -> Vec<(f64, f64)> {
    let cam = camera(128);
    let table = EdgeTable::new(p.len(), t);
    let cov = crate::raster::coverage(&cam, q, t, 4);
    let target = SilhouetteTarget::from_coverage(128, 128, &cov).unwrap();
    offsets
        .iter()
        .map(|&b| objectives_at(&cam, &target, p, t, &table, b))
        .collect()
}

/// The size of a pixel at the sphere's distance from [`camera`] (world units).
fn pixel_size() -> f32 {
    let cam = camera(128);
    cam.center().length() / cam.fx
}

#[test]
fn a_mask_grown_by_a_margin_is_explained_at_that_outline_offset() {
    let offsets: Vec<f32> = (-64..=64).map(|k| k as f32 / 32.0).collect();
    let (p, t) = uv_sphere(40, 64, 0.5, Vec3::ZERO);
    for grow in [0.0f32, 1.0, -0.75] {
        let (q, _) = uv_sphere(40, 64, 0.5 + grow * pixel_size(), Vec3::ZERO);
        let sweep = offset_sweep(&p, &q, &t, &offsets);
        let huber: Vec<f64> = sweep.iter().map(|s| s.0).collect();
        let distance: Vec<f64> = sweep.iter().map(|s| s.1).collect();
        for (name, losses) in [("Huber terms", &huber), ("distances", &distance)] {
            let at = argmin(&offsets, losses);
            assert!(
                (at - grow).abs() < 0.1,
                "masks grown by {grow} px: the {name} are smallest at offset {at:.3} px"
            );
        }
    }
    // At offset 0 the loss is the plain one, bit for bit.
    let cam = camera(96);
    let (p, t) = uv_sphere(16, 24, 0.5, Vec3::ZERO);
    let (q, tq) = uv_sphere(16, 24, 0.55, Vec3::new(0.03, 0.0, 0.0));
    let cov = crate::raster::coverage(&cam, &q, &tq, 4);
    let target = SilhouetteTarget::from_coverage(96, 96, &cov).unwrap();
    let table = EdgeTable::new(p.len(), &t);
    let plain = view_terms(&cam, &target, &p, &t, &table, DEFAULT_HUBER_PX);
    let zero = view_terms_with_offset(&cam, &target, &p, &t, &table, DEFAULT_HUBER_PX, 0.0);
    assert_eq!(plain, zero);
}

#[test]
fn the_offset_is_the_median_margin_where_the_mesh_is_thinner_on_part_of_its_outline() {
    // A sphere flattened on the side facing +x (its cap beyond x = 0.35 pulled in by up to
    // 2 px, about a quarter of its outline), against masks of the whole sphere grown by half
    // a pixel: the uniform margin is 0.5 px, the mesh's own shortfall is not a margin.
    let (q, t) = uv_sphere(40, 64, 0.5 + 0.5 * pixel_size(), Vec3::ZERO);
    let (sphere, _) = uv_sphere(40, 64, 0.5, Vec3::ZERO);
    let depth = 2.0 * pixel_size();
    let p: Vec<Vec3> = sphere
        .iter()
        .map(|&x| {
            let over = (x.x - 0.35).max(0.0) / 0.15;
            x - Vec3::X * depth * over
        })
        .collect();
    let offsets: Vec<f32> = (-32..=96).map(|k| k as f32 / 32.0).collect();
    let sweep = offset_sweep(&p, &q, &t, &offsets);
    let huber = argmin(&offsets, &sweep.iter().map(|s| s.0).collect::<Vec<_>>());
    let distance = argmin(&offsets, &sweep.iter().map(|s| s.1).collect::<Vec<_>>());
    assert!(
        (distance - 0.5).abs() < 0.1,
        "the distances are smallest at {distance:.3} px, not at the 0.5 px margin"
    );
    // The Huber terms average the shortfall into the offset: this is why the offsets do not
    // fit them.
    assert!(
        huber > distance + 0.1,
        "Huber terms {huber:.3} px, distances {distance:.3} px"
    );
}

#[test]
fn the_batch_op_offset_gradient_matches_finite_differences() {
    let cam = camera(96);
    let (p, t) = uv_sphere(16, 24, 0.5, Vec3::ZERO);
    let (q, tq) = uv_sphere(16, 24, 0.56, Vec3::new(0.04, -0.02, 0.0));
    let cov = crate::raster::coverage(&cam, &q, &tq, 4);
    let target = SilhouetteTarget::from_coverage(96, 96, &cov).unwrap();
    let table = Arc::new(EdgeTable::new(p.len(), &t));
    let tri: Arc<[[u32; 3]]> = t.clone().into();
    // Two frames, the second the sphere moved; three views with their own offsets.
    let moved: Vec<Vec3> = p.iter().map(|&x| x + Vec3::new(0.03, 0.02, 0.0)).collect();
    let flat: Vec<f32> = p.iter().chain(&moved).flat_map(|x| x.to_array()).collect();
    let views: Vec<BatchView> = [0, 1, 1]
        .iter()
        .map(|&frame| BatchView {
            frame,
            camera: cam.clone(),
            target: target.clone(),
        })
        .collect();
    let op = || SilhouetteLoss::new(views.clone(), tri.clone(), table.clone(), DEFAULT_HUBER_PX);
    // d(boundary distance + 2·contour distance)/db: the offsets' objective.
    let weights = Tensor::new(&[0.0f32, 0.0, 1.0, 2.0], &Device::Cpu).unwrap();
    let value = |b: &[f32]| -> f64 {
        let posed = Tensor::from_vec(flat.clone(), (2, p.len(), 3), &Device::Cpu).unwrap();
        let offsets = Tensor::new(b, &Device::Cpu).unwrap();
        let out = op().apply_with_offsets(&posed, &offsets).unwrap();
        f64::from(
            (out * &weights)
                .unwrap()
                .sum_all()
                .unwrap()
                .to_vec0::<f32>()
                .unwrap(),
        )
    };
    let at = [0.3f32, -0.4, 0.8];
    // Every output's gradient, to see which input each one reaches.
    let gradients = |w: [f32; 4]| -> (Vec<f32>, Vec<f32>) {
        let x = Var::from_tensor(
            &Tensor::from_vec(flat.clone(), (2, p.len(), 3), &Device::Cpu).unwrap(),
        )
        .unwrap();
        let offsets = Var::new(&at, &Device::Cpu).unwrap();
        let out = op()
            .apply_with_offsets(x.as_tensor(), offsets.as_tensor())
            .unwrap();
        let w = Tensor::new(&w, &Device::Cpu).unwrap();
        let grads = (out * w).unwrap().sum_all().unwrap().backward().unwrap();
        let get = |v: &Var| -> Vec<f32> {
            grads
                .get(v.as_tensor())
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        (get(&x), get(&offsets))
    };
    let (to_positions, g) = gradients([0.0, 0.0, 1.0, 2.0]);
    assert!(
        to_positions.iter().all(|&v| v == 0.0),
        "the distances move no vertex"
    );
    for k in 0..3 {
        let h = 1e-2f32;
        let (mut a, mut b) = (at, at);
        a[k] += h;
        b[k] -= h;
        let fd = (value(&a) - value(&b)) / (2.0 * f64::from(h));
        assert!(
            (f64::from(g[k]) - fd).abs() <= 2e-2 * fd.abs() + 1e-3,
            "view {k}: {} vs {fd}",
            g[k]
        );
        assert!(fd.abs() > 1e-2, "view {k}: the offset must matter ({fd})");
    }
    let (to_positions, to_offsets) = gradients([1.0, 2.0, 0.0, 0.0]);
    assert!(
        to_offsets.iter().all(|&v| v == 0.0),
        "the Huber terms move no offset"
    );
    assert!(to_positions.iter().any(|&v| v != 0.0));
}
