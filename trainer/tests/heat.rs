//! Bone heat on generated meshes with known answers: a capped two-bone cylinder (monotone,
//! mirror-symmetric, ~1 mid-bone, scale-invariant), unwelded and multi-component variants, and
//! degenerate input.

use glam::{Mat4, Vec3};
use skinfield_formats::{Skeleton, StaticSkin, Template, Transform};
use skinfield_trainer::heat::{HeatOptions, bone_heat};

const RINGS: usize = 41; // rings at y = 0, 0.05, …, 2
const SIDES: usize = 24;
const RADIUS: f32 = 0.1;

/// A closed cylinder along +Y from `base` (height 2, radius 0.1): RINGS×SIDES side vertices then
/// the bottom and top cap centres. The quad diagonals flip at mid-height so that the mesh is
/// exactly mirror-symmetric about y = 1.
fn cylinder(base: Vec3) -> Template {
    let mut positions = Vec::new();
    for k in 0..RINGS {
        let y = 2.0 * k as f32 / (RINGS - 1) as f32;
        for i in 0..SIDES {
            let a = std::f32::consts::TAU * i as f32 / SIDES as f32;
            positions.push(base + Vec3::new(RADIUS * a.cos(), y, RADIUS * a.sin()));
        }
    }
    let bottom = positions.len() as u32;
    positions.push(base);
    positions.push(base + Vec3::new(0.0, 2.0, 0.0));
    let top = bottom + 1;
    let v = |k: usize, i: usize| (k * SIDES + i % SIDES) as u32;
    let mut triangles = Vec::new();
    for k in 0..RINGS - 1 {
        for i in 0..SIDES {
            let (a, b, c, d) = (v(k, i), v(k, i + 1), v(k + 1, i + 1), v(k + 1, i));
            // Outward (counter-clockwise seen from outside): a → d → c, a → c → b.
            if k < (RINGS - 1) / 2 {
                triangles.push([a, d, c]);
                triangles.push([a, c, b]);
            } else {
                triangles.push([a, d, b]);
                triangles.push([b, d, c]);
            }
        }
    }
    for i in 0..SIDES {
        triangles.push([bottom, v(0, i), v(0, i + 1)]);
        triangles.push([top, v(RINGS - 1, i + 1), v(RINGS - 1, i)]);
    }
    let mut t = Template {
        positions,
        triangles,
        ..Default::default()
    };
    t.compute_normals();
    t
}

/// root at `base` → knee at `base + (0, 1, 0)`; the knee is a leaf continuing for 1 (to y = 2).
/// Joint names, parents and bind locals of one chain.
type Chain = (Vec<String>, Vec<Option<usize>>, Vec<Transform>);

fn two_bones(base: Vec3, names: [&str; 2]) -> Chain {
    (
        names.map(String::from).to_vec(),
        vec![None, Some(0)],
        vec![
            Transform::from_translation(base),
            Transform::from_translation(Vec3::Y),
        ],
    )
}

fn skeleton(parts: Vec<Chain>) -> Skeleton {
    let (mut names, mut parents, mut locals) = (Vec::new(), Vec::new(), Vec::new());
    for (n, p, l) in parts {
        let off = names.len();
        names.extend(n);
        parents.extend(p.into_iter().map(|p| p.map(|p| p + off)));
        locals.extend(l);
    }
    Skeleton::new(names, parents, locals, None, None, Mat4::IDENTITY).unwrap()
}

fn options() -> HeatOptions {
    HeatOptions {
        leaf_fraction: 1.0,
        ..Default::default()
    }
}

fn weight(skin: &StaticSkin, v: usize, j: u32) -> f32 {
    let (js, ws) = skin.influences(v);
    js.iter()
        .zip(ws)
        .find(|(a, _)| **a == j)
        .map_or(0.0, |(_, w)| *w)
}

fn assert_valid(skin: &StaticSkin, vertices: usize) {
    assert_eq!(skin.vertex_count(), vertices);
    for v in 0..vertices {
        let (_, ws) = skin.influences(v);
        assert!(!ws.is_empty(), "vertex {v} has no weight");
        assert!(
            ws.iter().all(|w| w.is_finite() && *w >= 0.0),
            "vertex {v}: {ws:?}"
        );
        assert!(
            (ws.iter().sum::<f32>() - 1.0).abs() < 1e-5,
            "vertex {v}: {ws:?}"
        );
    }
}

#[test]
fn two_bone_cylinder_is_monotone_symmetric_and_solid_mid_bone() {
    let mesh = cylinder(Vec3::ZERO);
    let skel = skeleton(vec![two_bones(Vec3::ZERO, ["root", "knee"])]);
    let r = bone_heat(&mesh, &skel, &options()).unwrap();
    assert_valid(&r.skin, mesh.vertex_count());
    assert_eq!(
        (
            r.stats.components,
            r.stats.fallback_components,
            r.stats.fallback_vertices
        ),
        (1, 0, 0)
    );
    // Before clamping, Σ_j w_j solves the same system with right-hand side M H · 1, whose
    // solution is exactly 1: the raw weights are a partition of unity up to solver round-off.
    assert!(
        r.stats.raw_sum_deviation < 1e-8,
        "{}",
        r.stats.raw_sum_deviation
    );
    // Heat undershoots zero only slightly (negative cotangents exist only on the caps).
    assert!(r.stats.raw_min > -1e-3, "{}", r.stats.raw_min);
    let knee = |v: usize| weight(&r.skin, v, 1);
    for i in 0..SIDES {
        for k in 0..RINGS {
            let v = k * SIDES + i;
            // Monotone along the axis.
            if k + 1 < RINGS {
                assert!(
                    knee(v + SIDES) >= knee(v) - 1e-6,
                    "ring {k} side {i}: {} then {}",
                    knee(v),
                    knee(v + SIDES)
                );
            }
            // Mirror symmetry about the joint: w_knee(y) = w_root(2 − y) = 1 − w_knee(2 − y).
            let mirror = (RINGS - 1 - k) * SIDES + i;
            assert!(
                (knee(v) - (1.0 - knee(mirror))).abs() < 1e-4,
                "ring {k}: {} vs {}",
                knee(v),
                knee(mirror)
            );
        }
        // Half-way along each bone (y = 0.5, 1.5; 5 radii from the joint) a vertex is ~fully bound.
        assert!(knee(10 * SIDES + i) < 0.01 && knee(30 * SIDES + i) > 0.99);
        // At the joint the two bones split the vertex evenly (by the symmetry).
        assert!(
            (knee(20 * SIDES + i) - 0.5).abs() < 1e-3,
            "{}",
            knee(20 * SIDES + i)
        );
    }
    // The transition really happens: some ring is neither fully one nor the other.
    assert!((0..mesh.vertex_count()).any(|v| (0.2..0.8).contains(&knee(v)) && v != 20 * SIDES));
}

#[test]
fn uniform_scale_of_mesh_and_skeleton_leaves_weights_unchanged() {
    let mesh = cylinder(Vec3::ZERO);
    let skel = skeleton(vec![two_bones(Vec3::ZERO, ["root", "knee"])]);
    let r = bone_heat(&mesh, &skel, &options()).unwrap();
    let s = 37.5f32;
    let mut big = mesh.clone();
    for p in &mut big.positions {
        *p *= s;
    }
    let (names, parents, mut locals) = two_bones(Vec3::ZERO, ["root", "knee"]);
    for l in &mut locals {
        l.translation *= s;
    }
    let big_skel = skeleton(vec![(names, parents, locals)]);
    let rb = bone_heat(&big, &big_skel, &options()).unwrap();
    let (a, b) = (r.skin.to_dense(), rb.skin.to_dense());
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "{worst}");
}

#[test]
fn unwelded_input_gives_the_welded_weights_on_every_copy() {
    let mesh = cylinder(Vec3::ZERO);
    let skel = skeleton(vec![two_bones(Vec3::ZERO, ["root", "knee"])]);
    let welded = bone_heat(&mesh, &skel, &options()).unwrap().skin;
    // A triangle soup: every triangle gets its own three vertices (as in files split at every
    // UV seam).
    let mut soup = Template::default();
    let mut source = Vec::new();
    for t in &mesh.triangles {
        let base = soup.positions.len() as u32;
        for &v in t {
            soup.positions.push(mesh.positions[v as usize]);
            source.push(v as usize);
        }
        soup.triangles.push([base, base + 1, base + 2]);
    }
    soup.compute_normals();
    let r = bone_heat(&soup, &skel, &options()).unwrap();
    assert_eq!(r.stats.welded_vertices, mesh.vertex_count());
    assert_valid(&r.skin, soup.vertex_count());
    for (v, &s) in source.iter().enumerate() {
        for j in 0..2 {
            assert!(
                (weight(&r.skin, v, j) - weight(&welded, s, j)).abs() < 1e-5,
                "copy {v} of {s}"
            );
        }
    }
}

#[test]
fn each_component_takes_heat_from_the_bones_it_sees() {
    // Two separate limbs, one bone chain in each, and a closed box far away that sees no bone.
    let mut mesh = cylinder(Vec3::ZERO);
    let other = cylinder(Vec3::new(1.0, 0.0, 0.0));
    let off = mesh.positions.len() as u32;
    mesh.positions.extend(&other.positions);
    mesh.triangles
        .extend(other.triangles.iter().map(|t| t.map(|v| v + off)));
    let box_first = mesh.positions.len();
    let c = Vec3::new(4.0, 1.0, 0.0);
    for z in [-0.2f32, 0.2] {
        for y in [-0.2f32, 0.2] {
            for x in [-0.2f32, 0.2] {
                mesh.positions.push(c + Vec3::new(x, y, z));
            }
        }
    }
    let b = box_first as u32;
    let faces = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    for f in faces {
        mesh.triangles.push([b + f[0], b + f[1], b + f[2]]);
        mesh.triangles.push([b + f[0], b + f[2], b + f[3]]);
    }
    mesh.compute_normals();
    let skel = skeleton(vec![
        two_bones(Vec3::ZERO, ["a0", "a1"]),
        two_bones(Vec3::new(1.0, 0.0, 0.0), ["b0", "b1"]),
    ]);
    let r = bone_heat(&mesh, &skel, &options()).unwrap();
    assert_valid(&r.skin, mesh.vertex_count());
    assert_eq!(r.stats.components, 3);
    assert_eq!(r.stats.fallback_components, 1);
    for v in 0..box_first {
        let (js, _) = r.skin.influences(v);
        let own = if v < off as usize { [0, 1] } else { [2, 3] };
        assert!(js.iter().all(|j| own.contains(j)), "vertex {v}: {js:?}");
    }
    // The blind box is weighted by distance: its nearest segments are limb b's, the lower bone
    // (joint 2) for its lower half and the upper one (joint 3) for its upper half.
    for v in box_first..mesh.vertex_count() {
        let j = if mesh.positions[v].y < 1.0 { 2 } else { 3 };
        assert!(weight(&r.skin, v, j) > 0.5, "{:?}", r.skin.influences(v));
        assert!(r.skin.influences(v).0.iter().all(|j| [2, 3].contains(j)));
    }
    // And limb a is unaffected by the rest: the same weights as alone.
    let alone = bone_heat(
        &cylinder(Vec3::ZERO),
        &skeleton(vec![two_bones(Vec3::ZERO, ["a0", "a1"])]),
        &options(),
    )
    .unwrap();
    for v in 0..off as usize {
        assert!((weight(&r.skin, v, 1) - weight(&alone.skin, v, 1)).abs() < 1e-5);
    }
}

#[test]
fn degenerate_duplicate_interior_and_isolated_geometry_do_not_break_it() {
    let mut mesh = cylinder(Vec3::ZERO);
    let n = mesh.positions.len() as u32;
    // A zero-area sliver (three collinear points), a duplicate triangle in the other orientation,
    // an isolated vertex, and an interior disk at y = 0.5 whose rim is welded onto the wall
    // (non-manifold edges).
    mesh.positions.extend([
        Vec3::new(0.0, 0.3, 0.0),
        Vec3::new(0.0, 0.4, 0.0),
        Vec3::new(0.0, 0.5, 0.0),
    ]);
    mesh.triangles.push([n, n + 1, n + 2]);
    let t0 = mesh.triangles[0];
    mesh.triangles.push([t0[0], t0[2], t0[1]]);
    mesh.positions.push(Vec3::new(0.05, 1.5, 0.0));
    let isolated = n as usize + 3;
    let centre = mesh.positions.len() as u32;
    mesh.positions.push(Vec3::new(0.0, 0.5, 0.02));
    let rim_first = mesh.positions.len() as u32;
    for i in 0..SIDES {
        mesh.positions.push(mesh.positions[10 * SIDES + i]);
    }
    for i in 0..SIDES as u32 {
        mesh.triangles
            .push([centre, rim_first + i, rim_first + (i + 1) % SIDES as u32]);
    }
    mesh.compute_normals();
    let skel = skeleton(vec![two_bones(Vec3::ZERO, ["root", "knee"])]);
    let r = bone_heat(&mesh, &skel, &options()).unwrap();
    assert_valid(&r.skin, mesh.vertex_count());
    assert_eq!(r.stats.duplicate_triangles, 1);
    assert!(r.stats.degenerate_triangles >= 1);
    assert!(r.stats.fallback_vertices >= 4, "{:?}", r.stats); // the sliver's three and the isolated one
    // The isolated vertex sits at y = 1.5 beside the knee's bone.
    assert_eq!(r.skin.influences(isolated), (&[1u32][..], &[1.0f32][..]));
}

#[test]
fn bad_input_is_an_error() {
    let skel = skeleton(vec![two_bones(Vec3::ZERO, ["root", "knee"])]);
    let mut mesh = cylinder(Vec3::ZERO);
    mesh.positions[3].x = f32::NAN;
    assert!(bone_heat(&mesh, &skel, &options()).is_err());
    let mesh = cylinder(Vec3::ZERO);
    assert!(
        bone_heat(
            &mesh,
            &skel,
            &HeatOptions {
                bone_tails: Some(vec![Vec3::ZERO]),
                ..options()
            }
        )
        .is_err()
    );
    assert!(
        bone_heat(
            &mesh,
            &skel,
            &HeatOptions {
                cone_cos: 2.0,
                ..options()
            }
        )
        .is_err()
    );
}

#[test]
fn a_component_that_sees_only_far_bones_is_weighted_by_distance() {
    // A limb (bones a0, a1 inside a cylinder) and, 0.3 in front of its bone, a 0.4 × 0.4 plate
    // facing the limb (normal −z): the limb's bone is behind the plate's normals and behind the
    // cylinder wall, so the only bone the plate sees is chain b, 1.2 further in front (the
    // robot's face plate and its IK pole targets).
    let mut mesh = cylinder(Vec3::ZERO);
    let first = mesh.positions.len();
    for y in [0.8f32, 1.0, 1.2] {
        for x in [-0.2f32, 0.0, 0.2] {
            mesh.positions.push(Vec3::new(x, y, 0.3));
        }
    }
    let p = |row: usize, col: usize| (first + 3 * row + col) as u32;
    for row in 0..2 {
        for col in 0..2 {
            // Clockwise seen from +z: the normal points to −z, towards the limb.
            let (a, b, c, d) = (
                p(row, col),
                p(row, col + 1),
                p(row + 1, col + 1),
                p(row + 1, col),
            );
            mesh.triangles.push([a, c, b]);
            mesh.triangles.push([a, d, c]);
        }
    }
    mesh.compute_normals();
    let skel = skeleton(vec![
        two_bones(Vec3::ZERO, ["a0", "a1"]),
        two_bones(Vec3::new(0.0, 0.0, 1.5), ["b0", "b1"]),
    ]);
    let share = |r: &skinfield_trainer::heat::HeatResult, joints: [u32; 2]| {
        (first..mesh.vertex_count())
            .map(|v| weight(&r.skin, v, joints[0]) + weight(&r.skin, v, joints[1]))
            .fold(f32::INFINITY, f32::min)
    };
    let by_distance = bone_heat(&mesh, &skel, &options()).unwrap();
    assert_valid(&by_distance.skin, mesh.vertex_count());
    assert_eq!(by_distance.stats.fallback_components, 1);
    assert!(
        share(&by_distance, [0, 1]) > 0.99,
        "{:?}",
        by_distance.stats
    );
    // With far visible bones accepted (Pinocchio's rule alone) the plate follows chain b.
    let visible = bone_heat(
        &mesh,
        &skel,
        &HeatOptions {
            far_visible_ratio: 10.0,
            ..options()
        },
    )
    .unwrap();
    assert_eq!(visible.stats.fallback_components, 0);
    assert!(share(&visible, [2, 3]) > 0.99);
    // The limb is solved with visibility either way, and alike.
    for v in 0..first {
        assert_eq!(by_distance.skin.influences(v), visible.skin.influences(v));
    }
}
