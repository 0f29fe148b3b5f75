//! The fast path against the exact path and against independent posing: node interpolation,
//! residual matrices (LBS linearity), top-k selection and quantisation, mesh distances that do
//! not leak across touching surfaces, vertex ranges, and every invalid configuration.

mod common;

use glam::{Vec3, Vec4};
use skinfield_formats::{Pose, StaticSkin};
use skinfield_runtime::fast::{Interpolation, LOG_WEIGHT_FLOOR, MAX_INFLUENCES, NodeMetric};
use skinfield_runtime::{
    BoundMesh, FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, Method, RuntimeError,
    Scratch, SkinJob, SkinNetModel, StaticSkinJob, TopKIndices, TopKJob, TopKWeights,
};

struct Fixture {
    model: SkinNetModel,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    tangents: Vec<Vec4>,
    triangles: Vec<[u32; 3]>,
    frame: FrameState,
    pose: Pose,
}

fn fixture(joints: u32, seed: u64) -> Fixture {
    let model = SkinNetModel::from_skf(&common::vinecs_bytes(joints, seed)).unwrap();
    let (positions, normals, triangles) = common::ellipsoid(12, 16);
    let mut rng = common::rng(seed + 1);
    let (_, tangents) = common::random_frames(positions.len(), &mut rng);
    let pose = common::random_pose(model.skeleton(), &mut rng, 0.6);
    let mut frame = FrameState::new(&model);
    frame.set_pose(&model, &pose).unwrap();
    Fixture {
        model,
        positions,
        normals,
        tangents,
        triangles,
        frame,
        pose,
    }
}

fn bind(f: &Fixture, options: &FastOptions) -> (FastMesh, FastFrame) {
    let mesh = FastMesh::bind(&f.model, &f.positions, &f.triangles, options).unwrap();
    let mut nodes = FastFrame::new(&mesh);
    nodes
        .update(&f.model, &mesh, &f.frame, &mut Scratch::new(&f.model))
        .unwrap();
    (mesh, nodes)
}

struct Out {
    p: Vec<Vec3>,
    n: Vec<Vec3>,
    t: Vec<Vec4>,
    w: Vec<f32>,
}

fn run_fast(
    f: &Fixture,
    mesh: &FastMesh,
    nodes: &FastFrame,
    method: Method,
    influences: usize,
    range: std::ops::Range<usize>,
) -> Out {
    let count = range.len();
    let j = f.model.joint_count();
    let mut o = Out {
        p: vec![Vec3::NAN; count],
        n: vec![Vec3::NAN; count],
        t: vec![Vec4::NAN; count],
        w: vec![f32::NAN; count * j],
    };
    FastSkinJob {
        mesh,
        frame: &f.frame,
        nodes,
        method,
        influences,
        first_vertex: range.start,
        rest_normals: Some(&f.normals),
        rest_tangents: Some(&f.tangents),
        out_positions: &mut o.p,
        out_normals: Some(&mut o.n),
        out_tangents: Some(&mut o.t),
        out_weights: Some(&mut o.w),
    }
    .run()
    .unwrap();
    o
}

fn run_exact(f: &Fixture, method: Method) -> Out {
    let n = f.positions.len();
    let j = f.model.joint_count();
    let mesh = BoundMesh::bind(&f.model, &f.positions).unwrap();
    let mut o = Out {
        p: vec![Vec3::NAN; n],
        n: vec![Vec3::NAN; n],
        t: vec![Vec4::NAN; n],
        w: vec![f32::NAN; n * j],
    };
    SkinJob {
        model: &f.model,
        mesh: &mesh,
        frame: &f.frame,
        method,
        first_vertex: 0,
        rest_normals: Some(&f.normals),
        rest_tangents: Some(&f.tangents),
        out_positions: &mut o.p,
        out_normals: Some(&mut o.n),
        out_tangents: Some(&mut o.t),
        out_weights: Some(&mut o.w),
    }
    .run(&mut Scratch::new(&f.model))
    .unwrap();
    o
}

/// Static skinning (the runtime's independent sparse path) of `f`'s mesh with per-vertex
/// weights `dense` (`J` per vertex) or sparse influences.
fn pose_static(f: &Fixture, skin: &StaticSkin, method: Method) -> Vec<Vec3> {
    let mut p = vec![Vec3::ZERO; f.positions.len()];
    StaticSkinJob {
        skin,
        palette: f.frame.palette(),
        method,
        first_vertex: 0,
        rest_positions: &f.positions,
        rest_normals: None,
        rest_tangents: None,
        out_positions: &mut p,
        out_normals: None,
        out_tangents: None,
    }
    .run()
    .unwrap();
    p
}

fn max_dist(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f32::max)
}

/// The `keep` strongest joints of `w` (ties: lower joint), renormalised, as a dense row.
fn restricted(w: &[f32], keep: usize) -> Vec<f32> {
    let mut order: Vec<usize> = (0..w.len()).collect();
    order.sort_by(|&a, &b| w[b].total_cmp(&w[a]).then(a.cmp(&b)));
    let mut out = vec![0.0f32; w.len()];
    let s: f32 = order[..keep].iter().map(|&i| w[i]).sum();
    for &i in &order[..keep] {
        out[i] = w[i] / s;
    }
    out
}

#[test]
fn one_node_per_vertex_reproduces_the_exact_path() {
    // Every welded vertex a node and one neighbour: each vertex reads its own node, so the
    // fast path must give the exact path's weights and skinned vertices when the base holds
    // every joint (or there is none), and the exact weights restricted to the vertex's
    // bind-pose base joints otherwise (B_vj · w_vj / b_vj ∝ w_vj on them).
    let f = fixture(6, 1);
    let j = f.model.joint_count();
    let exact = run_exact(&f, Method::Lbs);
    let mut bind_w = vec![0.0; f.positions.len() * j];
    f.model
        .weights_for(&f.positions, &f.model.skeleton().bind_pose(), &mut bind_w)
        .unwrap();
    for base in [0, 3, 8] {
        let options = FastOptions {
            nodes: f.positions.len(),
            neighbours: 1,
            base_influences: base,
            ..FastOptions::DEFAULT
        };
        let (mesh, nodes) = bind(&f, &options);
        assert_eq!(mesh.node_count(), mesh.stats().welded_vertices);
        assert!(mesh.node_count() < f.positions.len(), "the seam is welded");
        let fast = run_fast(&f, &mesh, &nodes, Method::Lbs, 4, 0..f.positions.len());
        let mut dw = 0.0f32;
        for v in 0..f.positions.len() {
            let exact_w = &exact.w[v * j..(v + 1) * j];
            let want = if base == 3 {
                // The base joints are the bind pose's strongest; keep the exact weights there.
                let keep = restricted(&bind_w[v * j..(v + 1) * j], 3);
                let w: Vec<f32> = exact_w
                    .iter()
                    .zip(&keep)
                    .map(|(e, k)| if *k > 0.0 { *e } else { 0.0 })
                    .collect();
                let s: f32 = w.iter().sum();
                w.iter().map(|x| x / s).collect()
            } else {
                exact_w.to_vec()
            };
            for (a, b) in fast.w[v * j..(v + 1) * j].iter().zip(&want) {
                dw = dw.max((a - b).abs());
            }
        }
        assert!(dw < 1e-5, "base {base}: weights differ by {dw}");
        if base != 3 {
            assert!(max_dist(&fast.p, &exact.p) < 1e-5, "base {base}");
            assert!(max_dist(&fast.n, &exact.n) < 1e-4, "base {base}");
        }
    }
}

#[test]
fn interpolated_weights_follow_the_documented_formula_and_lbs_is_their_exact_blend() {
    let f = fixture(8, 2);
    let j = f.model.joint_count();
    for options in [
        FastOptions {
            nodes: 40,
            ..FastOptions::DEFAULT
        },
        FastOptions {
            nodes: 30,
            base_influences: 3,
            ..FastOptions::DEFAULT
        },
        FastOptions {
            nodes: 25,
            neighbours: 3,
            base_influences: 0,
            interpolation: Interpolation::InverseDistance,
            ..FastOptions::DEFAULT
        },
    ] {
        let (mesh, nodes) = bind(&f, &options);
        // Independent of the fast frame: SkinNet at the node positions, straight from the model,
        // in the frame's pose and in the bind pose.
        let node_pos: Vec<Vec3> = mesh
            .node_vertices()
            .iter()
            .map(|&v| f.positions[v as usize])
            .collect();
        let mut wn = vec![0.0; node_pos.len() * j];
        f.model.weights_for(&node_pos, &f.pose, &mut wn).unwrap();
        let bind_pose = f.model.skeleton().bind_pose();
        let mut bn = vec![0.0; node_pos.len() * j];
        f.model.weights_for(&node_pos, &bind_pose, &mut bn).unwrap();
        // And SkinNet at every vertex in the bind pose, cut to the base influences.
        let mut bind_w = vec![0.0; f.positions.len() * j];
        f.model
            .weights_for(&f.positions, &bind_pose, &mut bind_w)
            .unwrap();
        let kb = options.base_influences;
        let fast = run_fast(&f, &mesh, &nodes, Method::Lbs, 4, 0..f.positions.len());
        let k = options.neighbours;
        let ln = |x: f32| f64::from(x.max(LOG_WEIGHT_FLOOR)).ln();
        for v in 0..f.positions.len() {
            let interp = &mesh.interpolation()[v * k..(v + 1) * k];
            let want: Vec<f32> = if kb == 0 {
                let mut w = vec![0.0f32; j];
                for a in interp {
                    let n = a.index as usize;
                    for jj in 0..j {
                        w[jj] += a.weight * wn[n * j + jj];
                    }
                }
                w
            } else {
                let base = restricted(&bind_w[v * j..(v + 1) * j], kb);
                let w: Vec<f64> = (0..j)
                    .map(|jj| {
                        let change: f64 = interp
                            .iter()
                            .map(|a| {
                                let n = a.index as usize;
                                f64::from(a.weight) * (ln(wn[n * j + jj]) - ln(bn[n * j + jj]))
                            })
                            .sum();
                        f64::from(base[jj]) * change.exp()
                    })
                    .collect();
                let s: f64 = w.iter().sum();
                w.iter().map(|x| (x / s) as f32).collect()
            };
            let got = &fast.w[v * j..(v + 1) * j];
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() < 1e-5, "vertex {v}: {got:?} vs {want:?}");
                assert!(*g >= 0.0, "vertex {v}: negative weight");
            }
            assert!((got.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            assert!(got.iter().filter(|&&x| x > 0.0).count() <= kb.max(j));
            let s: f32 = interp.iter().map(|a| a.weight).sum();
            assert!((s - 1.0).abs() < 1e-6);
        }
        // LBS through base joints or node matrices = LBS of the interpolated weights.
        let mats = f.frame.palette().matrices();
        let want: Vec<Vec3> = f
            .positions
            .iter()
            .zip(fast.w.chunks_exact(j))
            .map(|(p, w)| {
                w.iter()
                    .zip(mats)
                    .map(|(w, m)| m.transform_point3(*p) * *w)
                    .sum()
            })
            .collect();
        assert!(max_dist(&fast.p, &want) < 1e-5, "{options:?}");
    }
}

#[test]
fn dqs_and_top_k_use_the_strongest_joints() {
    let f = fixture(10, 3);
    let j = f.model.joint_count();
    let (mesh, nodes) = bind(
        &f,
        &FastOptions {
            nodes: 30,
            ..FastOptions::DEFAULT
        },
    );
    let n = f.positions.len();
    for k in [1, 4, 8] {
        let fast = run_fast(&f, &mesh, &nodes, Method::Dqs, k, 0..n);
        // Independent: the K largest by a full sort of the dense weights, then static DQS.
        let (mut offsets, mut joints, mut weights) = (vec![0u32], Vec::new(), Vec::new());
        for v in 0..n {
            let w = &fast.w[v * j..(v + 1) * j];
            let mut order: Vec<usize> = (0..j).collect();
            order.sort_by(|&a, &b| w[b].total_cmp(&w[a]).then(a.cmp(&b)));
            let s: f32 = order[..k].iter().map(|&i| w[i].max(0.0)).sum();
            for &i in &order[..k] {
                joints.push(i as u32);
                weights.push(w[i].max(0.0) / s);
            }
            offsets.push(joints.len() as u32);
        }
        let skin = StaticSkin::new(offsets, joints.clone(), weights.clone(), j).unwrap();
        let want = pose_static(&f, &skin, Method::Dqs);
        assert!(max_dist(&fast.p, &want) < 1e-5, "K = {k}");

        // Top-k output in every layout: same joints, weights summing exactly to one, each
        // within one quantum of the renormalised weight.
        let mut i8 = vec![0u8; n * k];
        let mut i16 = vec![0u16; n * k];
        let mut u8w = vec![0u8; n * k];
        let mut u16w = vec![0u16; n * k];
        let mut f32w = vec![0.0f32; n * k];
        for (idx, wts) in [
            (TopKIndices::U8(&mut i8), TopKWeights::Unorm8(&mut u8w)),
            (TopKIndices::U16(&mut i16), TopKWeights::Unorm16(&mut u16w)),
            (
                TopKIndices::U16(&mut vec![0; n * k]),
                TopKWeights::F32(&mut f32w),
            ),
        ] {
            TopKJob {
                mesh: &mesh,
                frame: &f.frame,
                nodes: &nodes,
                influences: k,
                first_vertex: 0,
                out_indices: idx,
                out_weights: wts,
            }
            .run()
            .unwrap();
        }
        for v in 0..n {
            let r = v * k..(v + 1) * k;
            let want_j: Vec<u32> = joints[r.clone()].to_vec();
            assert_eq!(
                i8[r.clone()]
                    .iter()
                    .map(|&x| u32::from(x))
                    .collect::<Vec<_>>(),
                want_j
            );
            assert_eq!(
                i16[r.clone()]
                    .iter()
                    .map(|&x| u32::from(x))
                    .collect::<Vec<_>>(),
                want_j
            );
            assert_eq!(
                u8w[r.clone()].iter().map(|&x| u32::from(x)).sum::<u32>(),
                255
            );
            assert_eq!(
                u16w[r.clone()].iter().map(|&x| u32::from(x)).sum::<u32>(),
                65535
            );
            assert_eq!(f32w[r.clone()].iter().sum::<f32>(), 1.0);
            assert_eq!(f32w[r.clone()].iter().rev().sum::<f32>(), 1.0);
            for (i, &w) in weights[r.clone()].iter().enumerate() {
                assert!((f32::from(u8w[v * k + i]) / 255.0 - w).abs() <= 1.0 / 255.0 + 1e-6);
                assert!((f32::from(u16w[v * k + i]) / 65535.0 - w).abs() <= 1.0 / 65535.0 + 1e-6);
                assert!((f32w[v * k + i] - w).abs() <= 1e-6);
            }
        }
    }
}

#[test]
fn sub_ranges_give_the_same_result_as_one_run() {
    let f = fixture(6, 4);
    let (mesh, nodes) = bind(
        &f,
        &FastOptions {
            nodes: 20,
            ..FastOptions::DEFAULT
        },
    );
    let n = f.positions.len();
    let j = f.model.joint_count();
    for method in [Method::Lbs, Method::Dqs] {
        let all = run_fast(&f, &mesh, &nodes, method, 4, 0..n);
        for w in [0, 0, 1, 31, 100, n - 1, n].windows(2) {
            let part = run_fast(&f, &mesh, &nodes, method, 4, w[0]..w[1]);
            assert_eq!(part.p, all.p[w[0]..w[1]], "{method:?} {w:?}");
            assert_eq!(part.n, all.n[w[0]..w[1]]);
            assert_eq!(part.t, all.t[w[0]..w[1]]);
            assert_eq!(part.w, all.w[w[0] * j..w[1] * j]);
        }
        assert!(all.n.iter().all(|v| (v.length() - 1.0).abs() < 1e-5));
    }
    let top = |first: usize, count: usize| {
        let (mut i, mut w) = (vec![0u16; count * 4], vec![0u8; count * 4]);
        TopKJob {
            mesh: &mesh,
            frame: &f.frame,
            nodes: &nodes,
            influences: 4,
            first_vertex: first,
            out_indices: TopKIndices::U16(&mut i),
            out_weights: TopKWeights::Unorm8(&mut w),
        }
        .run()
        .unwrap();
        (i, w)
    };
    let (ai, aw) = top(0, n);
    let (pi, pw) = top(33, 50);
    assert_eq!(pi, ai[33 * 4..83 * 4]);
    assert_eq!(pw, aw[33 * 4..83 * 4]);
}

/// LBS jobs normalise their normals and tangents a tile at a time after the blends: on every
/// path (fast with and without a base, tangents asked for without normals, static skinning)
/// they come out of unit length, and the static ones match the inverse transpose of the blended
/// matrix.
#[test]
fn lbs_normals_and_tangents_are_normalised_on_every_path() {
    let f = fixture(6, 4);
    let (n, j) = (f.positions.len(), f.model.joint_count());
    let unit = |v: Vec3| (v.length() - 1.0).abs() < 1e-5;
    let mut dense = Vec::new();
    for base in [FastOptions::DEFAULT.base_influences, 0] {
        let options = FastOptions {
            nodes: 20,
            base_influences: base,
            ..FastOptions::DEFAULT
        };
        let (mesh, nodes) = bind(&f, &options);
        let all = run_fast(&f, &mesh, &nodes, Method::Lbs, 4, 0..n);
        assert!(all.n.iter().all(|&v| unit(v)), "base {base}");
        assert!(all.t.iter().all(|v| unit(v.truncate())), "base {base}");
        let (mut p, mut t) = (vec![Vec3::ZERO; n], vec![Vec4::NAN; n]);
        FastSkinJob {
            mesh: &mesh,
            frame: &f.frame,
            nodes: &nodes,
            method: Method::Lbs,
            influences: 4,
            first_vertex: 0,
            rest_normals: None,
            rest_tangents: Some(&f.tangents),
            out_positions: &mut p,
            out_normals: None,
            out_tangents: Some(&mut t),
            out_weights: None,
        }
        .run()
        .unwrap();
        assert_eq!(t, all.t, "tangents without normals, base {base}");
        dense = all.w;
    }
    // Static LBS with the convex run's dense weights, against M⁻ᵀ n and M t.
    let (mut offsets, mut joints, mut weights) = (vec![0u32], Vec::new(), Vec::new());
    for row in dense.chunks_exact(j) {
        for (joint, &w) in row.iter().enumerate() {
            joints.push(joint as u32);
            weights.push(w);
        }
        offsets.push(joints.len() as u32);
    }
    let skin = StaticSkin::new(offsets, joints, weights, j).unwrap();
    let (mut p, mut nn, mut t) = (vec![Vec3::ZERO; n], vec![Vec3::NAN; n], vec![Vec4::NAN; n]);
    StaticSkinJob {
        skin: &skin,
        palette: f.frame.palette(),
        method: Method::Lbs,
        first_vertex: 0,
        rest_positions: &f.positions,
        rest_normals: Some(&f.normals),
        rest_tangents: Some(&f.tangents),
        out_positions: &mut p,
        out_normals: Some(&mut nn),
        out_tangents: Some(&mut t),
    }
    .run()
    .unwrap();
    let mats = f.frame.palette().matrices();
    for v in 0..n {
        let row = &dense[v * j..(v + 1) * j];
        let m = row
            .iter()
            .zip(mats)
            .fold(glam::Mat4::ZERO, |acc, (&w, m)| acc + *m * w);
        let m3 = glam::Mat3::from_mat4(m);
        let want_n = (m3.inverse().transpose() * f.normals[v]).normalize();
        let want_t = (m3 * f.tangents[v].truncate()).normalize();
        assert!(
            (nn[v] - want_n).length() < 1e-4,
            "normal {v}: {} vs {want_n}",
            nn[v]
        );
        assert!((t[v].truncate() - want_t).length() < 1e-4, "tangent {v}");
        assert_eq!(t[v].w, f.tangents[v].w);
    }
}

/// Two parallel sheets 1 mm apart (a skirt over a leg, an arm against the torso): along the
/// mesh every vertex's nodes lie on its own sheet; in straight-line distance they leak.
#[test]
fn mesh_distances_do_not_leak_between_touching_sheets() {
    let f = fixture(6, 5);
    let grid = 12u32;
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for sheet in 0..2u32 {
        let base = positions.len() as u32;
        for y in 0..=grid {
            for x in 0..=grid {
                positions.push(Vec3::new(
                    -0.5 + x as f32 / grid as f32,
                    0.2 + 1.2 * y as f32 / grid as f32,
                    0.001 * sheet as f32,
                ));
            }
        }
        for y in 0..grid {
            for x in 0..grid {
                let a = base + y * (grid + 1) + x;
                let (b, c, d) = (a + 1, a + grid + 1, a + grid + 2);
                triangles.push([a, b, c]);
                triangles.push([b, d, c]);
            }
        }
    }
    let sheet_of = |v: u32| v as usize >= positions.len() / 2;
    let leaks = |metric| {
        let options = FastOptions {
            nodes: 16,
            metric,
            ..FastOptions::DEFAULT
        };
        let mesh = FastMesh::bind(&f.model, &positions, &triangles, &options).unwrap();
        let k = options.neighbours;
        let mut leaked = 0.0f32;
        for v in 0..positions.len() {
            for a in &mesh.interpolation()[v * k..(v + 1) * k] {
                let node_v = mesh.node_vertices()[a.index as usize];
                if sheet_of(node_v) != sheet_of(v as u32) {
                    leaked += a.weight;
                }
            }
        }
        (leaked, mesh.stats().euclidean_fallback_vertices)
    };
    assert_eq!(leaks(NodeMetric::AlongMesh), (0.0, 0));
    let (euclid, _) = leaks(NodeMetric::Euclidean);
    assert!(
        euclid > 0.1 * positions.len() as f32,
        "straight lines leak: {euclid}"
    );
}

#[test]
fn seam_copies_get_the_same_interpolation_and_components_without_nodes_fall_back() {
    let f = fixture(6, 6);
    let (mesh, _) = bind(
        &f,
        &FastOptions {
            nodes: 30,
            ..FastOptions::DEFAULT
        },
    );
    let k = mesh.options().neighbours;
    // In `ellipsoid`, column `segments` of every ring repeats column 0.
    let (rings, segments) = (12usize, 16usize);
    for i in 1..rings {
        let a = 1 + (i - 1) * (segments + 1);
        let b = a + segments;
        assert_eq!(f.positions[a], f.positions[b]);
        assert_eq!(
            mesh.interpolation()[a * k..(a + 1) * k],
            mesh.interpolation()[b * k..(b + 1) * k]
        );
    }
    // A lone triangle far away with 1 node for 2 components: one component has no node.
    let mut p = f.positions.clone();
    let off = p.len() as u32;
    // Inside the ellipsoid, so the first (farthest-from-centroid) node lands on the ellipsoid.
    p.extend([
        Vec3::new(0.0, 0.9, 0.0),
        Vec3::new(0.02, 0.9, 0.0),
        Vec3::new(0.0, 0.92, 0.0),
    ]);
    let mut t = f.triangles.clone();
    t.push([off, off + 1, off + 2]);
    let mesh = FastMesh::bind(
        &f.model,
        &p,
        &t,
        &FastOptions {
            nodes: 1,
            ..FastOptions::DEFAULT
        },
    )
    .unwrap();
    assert_eq!(mesh.stats().euclidean_fallback_vertices, 3);
    // Still a partition of unity everywhere (the single node takes all the weight).
    for v in 0..p.len() {
        let s: f32 = mesh.interpolation()[v * 4..(v + 1) * 4]
            .iter()
            .map(|a| a.weight)
            .sum();
        assert!((s - 1.0).abs() < 1e-6);
    }
    // A point cloud (no triangles) binds with straight-line distances.
    let cloud = FastMesh::bind(&f.model, &f.positions, &[], &FastOptions::DEFAULT).unwrap();
    assert_eq!(cloud.stats().euclidean_fallback_vertices, 0);
    assert!(cloud.node_count() <= cloud.stats().welded_vertices);
}

#[test]
fn more_nodes_bring_the_fast_path_closer_to_the_exact_one() {
    let f = fixture(6, 7);
    let exact = run_exact(&f, Method::Lbs);
    let err = |nodes: usize| {
        let (mesh, fr) = bind(
            &f,
            &FastOptions {
                nodes,
                ..FastOptions::DEFAULT
            },
        );
        let fast = run_fast(&f, &mesh, &fr, Method::Lbs, 4, 0..f.positions.len());
        fast.p
            .iter()
            .zip(&exact.p)
            .map(|(a, b)| a.distance(*b))
            .sum::<f32>()
            / f.positions.len() as f32
    };
    let (e16, e64, e180) = (err(16), err(64), err(180));
    assert!(e16 > e64 && e64 > e180, "{e16} {e64} {e180}");
}

/// Every way a fast-path bind, update or job can be wrong, and the error that names it.
#[test]
fn every_invalid_configuration_is_refused_by_name() {
    let f = fixture(6, 8);
    let other = fixture(6, 9);
    let n = f.positions.len();
    let d = FastOptions::DEFAULT;
    let bad_options: [(FastOptions, RuntimeError); 4] = [
        (
            FastOptions { nodes: 0, ..d },
            RuntimeError::Setting {
                field: "nodes",
                value: 0,
                min: 1,
                max: 1 << 24,
            },
        ),
        (
            FastOptions { neighbours: 0, ..d },
            RuntimeError::Setting {
                field: "neighbours",
                value: 0,
                min: 1,
                max: MAX_INFLUENCES,
            },
        ),
        (
            FastOptions { neighbours: 9, ..d },
            RuntimeError::Setting {
                field: "neighbours",
                value: 9,
                min: 1,
                max: MAX_INFLUENCES,
            },
        ),
        (
            FastOptions {
                base_influences: 9,
                ..d
            },
            RuntimeError::Setting {
                field: "base_influences",
                value: 9,
                min: 0,
                max: MAX_INFLUENCES,
            },
        ),
    ];
    for (options, want) in bad_options {
        assert_eq!(
            FastMesh::bind(&f.model, &f.positions, &f.triangles, &options).err(),
            Some(want)
        );
    }
    assert_eq!(
        FastMesh::bind(&f.model, &[], &[], &d).err(),
        Some(RuntimeError::VertexCount(0))
    );
    let mut nan = f.positions.clone();
    nan[5].y = f32::NAN;
    assert_eq!(
        FastMesh::bind(&f.model, &nan, &f.triangles, &d).err(),
        Some(RuntimeError::NonFinite {
            field: "positions",
            index: 5
        })
    );
    let mut tris = f.triangles.clone();
    tris[3][1] = n as u32;
    assert_eq!(
        FastMesh::bind(&f.model, &f.positions, &tris, &d).err(),
        Some(RuntimeError::Index {
            field: "triangles",
            index: 3,
            value: n as u32,
            limit: n
        })
    );

    let options = FastOptions { nodes: 20, ..d };
    let (mesh, nodes) = bind(&f, &options);
    let (other_mesh, other_nodes) = bind(&other, &options);
    let mut scratch = Scratch::new(&f.model);
    // Update: a mesh of another model, nodes of another mesh.
    let mut fresh = FastFrame::new(&mesh);
    assert_eq!(
        fresh.update(&f.model, &other_mesh, &f.frame, &mut scratch),
        Err(RuntimeError::Mismatch { field: "mesh" })
    );
    let same_model_mesh = FastMesh::bind(&f.model, &f.positions, &f.triangles, &options).unwrap();
    assert_eq!(
        fresh.update(&f.model, &same_model_mesh, &f.frame, &mut scratch),
        Err(RuntimeError::Mismatch { field: "nodes" })
    );
    assert_eq!(
        fresh.update(&f.model, &mesh, &other.frame, &mut scratch),
        Err(RuntimeError::Mismatch { field: "frame" })
    );
    assert!(f.frame.is_for(&f.model) && other.frame.is_for(&other.model));
    assert!(!other.frame.is_for(&f.model) && !f.frame.is_for(&other.model));
    assert_eq!(
        fresh.update(&f.model, &mesh, &FrameState::new(&f.model), &mut scratch),
        Err(RuntimeError::NoPose)
    );
    assert!(!fresh.is_ready());

    // Skin job.
    let unposed = FrameState::new(&f.model);
    let mut reposed = f.frame.clone();
    reposed.set_pose(&f.model, &f.pose).unwrap();
    let short_normals = vec![Vec3::Y; n - 1];
    let cases: [(&str, RuntimeError); 10] = [
        (
            "nodes of another mesh",
            RuntimeError::Mismatch { field: "nodes" },
        ),
        (
            "frame of another model",
            RuntimeError::Mismatch { field: "frame" },
        ),
        ("frame without pose", RuntimeError::NoPose),
        (
            "nodes of an older pose",
            RuntimeError::Stale { field: "nodes" },
        ),
        (
            "nodes never updated",
            RuntimeError::Stale { field: "nodes" },
        ),
        (
            "range past the end",
            RuntimeError::Range {
                first: 1,
                count: n,
                vertex_count: n,
            },
        ),
        (
            "zero influences",
            RuntimeError::Setting {
                field: "influences",
                value: 0,
                min: 1,
                max: MAX_INFLUENCES,
            },
        ),
        (
            "nine influences",
            RuntimeError::Setting {
                field: "influences",
                value: 9,
                min: 1,
                max: MAX_INFLUENCES,
            },
        ),
        (
            "normals out without rest normals",
            RuntimeError::Missing {
                field: "rest_normals",
                because: "out_normals",
            },
        ),
        (
            "rest normals too short",
            RuntimeError::BufferLength {
                field: "rest_normals",
                len: n - 1,
                expected: n,
            },
        ),
    ];
    let never = FastFrame::new(&mesh);
    for (k, (what, want)) in cases.into_iter().enumerate() {
        let (mut p, mut nn, mut w) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n], vec![0.0; n * 6]);
        let mut job = FastSkinJob {
            mesh: &mesh,
            frame: &f.frame,
            nodes: &nodes,
            method: Method::Dqs,
            influences: 4,
            first_vertex: 0,
            rest_normals: Some(&f.normals),
            rest_tangents: None,
            out_positions: &mut p,
            out_normals: Some(&mut nn),
            out_tangents: None,
            out_weights: Some(&mut w),
        };
        assert_eq!(job.validate(), Ok(()));
        match k {
            0 => job.nodes = &other_nodes,
            1 => job.frame = &other.frame,
            2 => job.frame = &unposed,
            3 => job.frame = &reposed,
            4 => job.nodes = &never,
            5 => job.first_vertex = 1,
            6 => job.influences = 0,
            7 => job.influences = 9,
            8 => job.rest_normals = None,
            _ => job.rest_normals = Some(&short_normals),
        }
        assert_eq!(job.validate(), Err(want.clone()), "{what}");
        assert_eq!(job.run(), Err(want), "{what}: run validates too");
    }
    let mut p = vec![Vec3::ZERO; n];
    let mut short_w = vec![0.0; n * 6 - 1];
    let job = FastSkinJob {
        mesh: &mesh,
        frame: &f.frame,
        nodes: &nodes,
        method: Method::Lbs,
        influences: 4,
        first_vertex: 0,
        rest_normals: None,
        rest_tangents: None,
        out_positions: &mut p,
        out_normals: None,
        out_tangents: None,
        out_weights: Some(&mut short_w),
    };
    assert_eq!(
        job.validate(),
        Err(RuntimeError::BufferLength {
            field: "out_weights",
            len: n * 6 - 1,
            expected: n * 6
        })
    );

    // Top-k job.
    let top = |k: usize, idx: TopKIndices<'_>, w: TopKWeights<'_>, first: usize| {
        TopKJob {
            mesh: &mesh,
            frame: &f.frame,
            nodes: &nodes,
            influences: k,
            first_vertex: first,
            out_indices: idx,
            out_weights: w,
        }
        .validate()
    };
    assert_eq!(
        top(
            4,
            TopKIndices::U8(&mut [0; 8]),
            TopKWeights::F32(&mut [0.0; 8]),
            0
        ),
        Ok(())
    );
    assert_eq!(
        top(
            4,
            TopKIndices::U8(&mut [0; 9]),
            TopKWeights::F32(&mut [0.0; 9]),
            0
        ),
        Err(RuntimeError::BufferLength {
            field: "out_indices",
            len: 9,
            expected: 8
        })
    );
    assert_eq!(
        top(
            4,
            TopKIndices::U16(&mut [0; 8]),
            TopKWeights::Unorm8(&mut [0; 4]),
            0
        ),
        Err(RuntimeError::BufferLength {
            field: "out_weights",
            len: 4,
            expected: 8
        })
    );
    assert_eq!(
        top(
            0,
            TopKIndices::U16(&mut [0; 8]),
            TopKWeights::Unorm16(&mut [0; 8]),
            0
        ),
        Err(RuntimeError::Setting {
            field: "influences",
            value: 0,
            min: 1,
            max: MAX_INFLUENCES
        })
    );
    assert_eq!(
        top(
            4,
            TopKIndices::U16(&mut [0; 8]),
            TopKWeights::Unorm16(&mut [0; 8]),
            n - 1
        ),
        Err(RuntimeError::Range {
            first: n - 1,
            count: 2,
            vertex_count: n
        })
    );
    let stale = TopKJob {
        mesh: &mesh,
        frame: &reposed,
        nodes: &nodes,
        influences: 4,
        first_vertex: 0,
        out_indices: TopKIndices::U8(&mut [0; 4]),
        out_weights: TopKWeights::Unorm8(&mut [0; 4]),
    };
    assert_eq!(
        stale.validate(),
        Err(RuntimeError::Stale { field: "nodes" })
    );
    // u8 indices cannot name joint 256 and beyond.
    let mut wide = common::no_skip_config();
    wide.joint_count = 300;
    let wide_model =
        SkinNetModel::from_skf(&common::random_model(wide, 10).to_bytes().unwrap()).unwrap();
    let wide_mesh = FastMesh::bind(&wide_model, &f.positions, &f.triangles, &options).unwrap();
    let mut wide_frame = FrameState::new(&wide_model);
    let wide_pose = wide_model.skeleton().bind_pose();
    wide_frame.set_pose(&wide_model, &wide_pose).unwrap();
    let mut wide_nodes = FastFrame::new(&wide_mesh);
    wide_nodes
        .update(
            &wide_model,
            &wide_mesh,
            &wide_frame,
            &mut Scratch::new(&wide_model),
        )
        .unwrap();
    let job = TopKJob {
        mesh: &wide_mesh,
        frame: &wide_frame,
        nodes: &wide_nodes,
        influences: 4,
        first_vertex: 0,
        out_indices: TopKIndices::U8(&mut [0; 4]),
        out_weights: TopKWeights::Unorm8(&mut [0; 4]),
    };
    assert_eq!(
        job.validate(),
        Err(RuntimeError::Setting {
            field: "out_indices (u8: joint count)",
            value: 300,
            min: 1,
            max: 256
        })
    );
}
