//! The fast path against the exact path and against static LBS with 4 influences (the floor an
//! engine pays today), side by side in one run, one thread, for 1k, 10k and 50k vertices;
//! J = 24, the paper's SkinNet with random weights, a closed ellipsoid mesh with a UV seam.
//!
//! Every "frame" starts from a pose and ends with skinned positions and normals in caller
//! buffers: exact = `FrameState::set_pose` + `SkinJob` (LBS); fast = `set_pose` +
//! `FastFrame::update` + `FastSkinJob` (LBS, default options; `fast_dqs`: DQS over 4 joints);
//! top-k = `set_pose` + `update` + `TopKJob` (K = 4, u8 indices, unorm8 weights, no skinning);
//! static = `Palette::set_pose` + `StaticSkinJob` (LBS over 4 influences per vertex). A node
//! sweep at 10k vertices times the fast frame for N = 64 … 1024, and an options sweep at 10k and
//! 50k times it for N = 128 / 256 nodes × 4 / 8 base influences. Bind times are printed.
//!
//! After criterion's report a table of the ratios is printed from its estimates
//! (`docs/experiments/fast-path.md` comes from this).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, SamplingMode, Throughput};
use glam::{Vec3, Vec4};
use skinfield_benches::{ellipsoid, random_pose, rng, vinecs_bytes};
use skinfield_formats::{Pose, StaticSkin};
use skinfield_runtime::fast::strongest_influences;
use skinfield_runtime::{
    BoundMesh, FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, Influence, Kernel,
    Method, Palette, Scratch, SkinJob, SkinNetModel, StaticSkinJob, TopKIndices, TopKJob,
    TopKWeights,
};

const SIZES: [usize; 3] = [1_000, 10_000, 50_000];
const SWEEP_SIZE: usize = 10_000;
const SWEEP_NODES: [usize; 5] = [64, 128, 256, 512, 1024];
/// Sizes whose fast frame is also timed for every (nodes, base influences) pair below.
const OPTION_SIZES: [usize; 2] = [10_000, 50_000];
const OPTION_PAIRS: [(usize, usize); 4] = [(128, 4), (128, 8), (256, 4), (256, 8)];
const JOINTS: u32 = 24;

/// An ellipsoid with about `n` vertices.
fn mesh(n: usize) -> (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>) {
    let rings = ((n as f64 / 2.0).sqrt().round() as u32).max(3);
    let segments = ((n as u32 - 2) / (rings - 1)).saturating_sub(1).max(3);
    ellipsoid(rings, segments)
}

struct Setup {
    model: SkinNetModel,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    exact: BoundMesh,
    fast: FastMesh,
    skin4: StaticSkin,
    pose: Pose,
}

fn setup(n: usize, bytes: &[u8]) -> Setup {
    let model = SkinNetModel::from_skf(bytes).expect("model");
    let (positions, normals, triangles) = mesh(n);
    let exact = BoundMesh::bind(&model, &positions).expect("bind");
    let t = Instant::now();
    let fast =
        FastMesh::bind(&model, &positions, &triangles, &FastOptions::DEFAULT).expect("fast bind");
    eprintln!(
        "fast bind, {} vertices, {} nodes: {:.0} ms (kernel {:?})",
        positions.len(),
        fast.node_count(),
        t.elapsed().as_secs_f64() * 1e3,
        model.kernel()
    );
    // The static floor: SkinNet's bind-pose weights cut to 4 per vertex.
    let j = model.joint_count();
    let mut dense = vec![0.0; positions.len() * j];
    model
        .weights_for(&positions, &model.skeleton().bind_pose(), &mut dense)
        .expect("bind-pose weights");
    let (mut offsets, mut joints, mut weights) = (vec![0u32], Vec::new(), Vec::new());
    for w in dense.chunks_exact(j) {
        let mut top = [Influence::default(); 4];
        strongest_influences(w, &mut top);
        for t in top {
            joints.push(t.index);
            weights.push(t.weight);
        }
        offsets.push(joints.len() as u32);
    }
    let skin4 = StaticSkin::new(offsets, joints, weights, j).expect("static skin");
    let pose = random_pose(model.skeleton(), &mut rng(7 + n as u64), 0.6);
    Setup {
        model,
        positions,
        normals,
        triangles,
        exact,
        fast,
        skin4,
        pose,
    }
}

struct Buffers {
    frame: FrameState,
    scratch: Scratch,
    pos: Vec<Vec3>,
    nrm: Vec<Vec3>,
}

fn exact_frame(s: &Setup, b: &mut Buffers) {
    b.frame.set_pose(&s.model, &s.pose).expect("pose");
    SkinJob {
        model: &s.model,
        mesh: &s.exact,
        frame: &b.frame,
        method: Method::Lbs,
        first_vertex: 0,
        rest_normals: Some(&s.normals),
        rest_tangents: None,
        out_positions: &mut b.pos,
        out_normals: Some(&mut b.nrm),
        out_tangents: None,
        out_weights: None,
    }
    .run(&mut b.scratch)
    .expect("exact frame");
}

fn fast_frame(s: &Setup, mesh: &FastMesh, nodes: &mut FastFrame, b: &mut Buffers, m: Method) {
    b.frame.set_pose(&s.model, &s.pose).expect("pose");
    nodes
        .update(&s.model, mesh, &b.frame, &mut b.scratch)
        .expect("nodes");
    FastSkinJob {
        mesh,
        frame: &b.frame,
        nodes,
        method: m,
        influences: 4,
        first_vertex: 0,
        rest_normals: Some(&s.normals),
        rest_tangents: None,
        out_positions: &mut b.pos,
        out_normals: Some(&mut b.nrm),
        out_tangents: None,
        out_weights: None,
    }
    .run()
    .expect("fast frame");
}

fn benches(c: &mut Criterion) {
    let bytes = vinecs_bytes(JOINTS, 1);
    for n in SIZES {
        let s = setup(n, &bytes);
        let v = s.positions.len();
        let mut b = Buffers {
            frame: FrameState::new(&s.model),
            scratch: Scratch::new(&s.model),
            pos: vec![Vec3::ZERO; v],
            nrm: vec![Vec3::ZERO; v],
        };
        let mut nodes = FastFrame::new(&s.fast);
        let mut palette = Palette::new(s.model.joint_count());
        let (mut idx, mut wts) = (vec![0u8; v * 4], vec![0u8; v * 4]);
        let mut g = c.benchmark_group(format!("fast_{n}"));
        g.throughput(Throughput::Elements(v as u64));
        g.sample_size(10).sampling_mode(SamplingMode::Flat);
        g.bench_function("exact", |bn| bn.iter(|| exact_frame(&s, &mut b)));
        g.bench_function("fast", |bn| {
            bn.iter(|| fast_frame(&s, &s.fast, &mut nodes, &mut b, Method::Lbs))
        });
        g.bench_function("fast_dqs", |bn| {
            bn.iter(|| fast_frame(&s, &s.fast, &mut nodes, &mut b, Method::Dqs))
        });
        g.bench_function("topk4", |bn| {
            bn.iter(|| {
                b.frame.set_pose(&s.model, &s.pose).expect("pose");
                nodes
                    .update(&s.model, &s.fast, &b.frame, &mut b.scratch)
                    .expect("nodes");
                TopKJob {
                    mesh: &s.fast,
                    frame: &b.frame,
                    nodes: &nodes,
                    influences: 4,
                    first_vertex: 0,
                    out_indices: TopKIndices::U8(&mut idx),
                    out_weights: TopKWeights::Unorm8(&mut wts),
                }
                .run()
                .expect("top-k")
            })
        });
        g.bench_function("static_lbs4", |bn| {
            bn.iter(|| {
                palette
                    .set_pose(s.model.skeleton(), &s.pose)
                    .expect("palette");
                StaticSkinJob {
                    skin: &s.skin4,
                    palette: &palette,
                    method: Method::Lbs,
                    first_vertex: 0,
                    rest_positions: &s.positions,
                    rest_normals: Some(&s.normals),
                    rest_tangents: None::<&[Vec4]>,
                    out_positions: &mut b.pos,
                    out_normals: Some(&mut b.nrm),
                    out_tangents: None,
                }
                .run()
                .expect("static")
            })
        });
        g.finish();
        if OPTION_SIZES.contains(&n) {
            let mut g = c.benchmark_group(format!("fast_options_{n}"));
            g.throughput(Throughput::Elements(v as u64));
            g.sample_size(10).sampling_mode(SamplingMode::Flat);
            for (nodes_n, base) in OPTION_PAIRS {
                let options = FastOptions {
                    nodes: nodes_n,
                    base_influences: base,
                    ..FastOptions::DEFAULT
                };
                let mesh =
                    FastMesh::bind(&s.model, &s.positions, &s.triangles, &options).expect("bind");
                let mut fr = FastFrame::new(&mesh);
                let id = format!("n{nodes_n}_b{base}");
                g.bench_function(BenchmarkId::new("fast", id), |bn| {
                    bn.iter(|| fast_frame(&s, &mesh, &mut fr, &mut b, Method::Lbs))
                });
            }
            g.finish();
        }
        if n != SWEEP_SIZE {
            continue;
        }
        let mut g = c.benchmark_group(format!("fast_nodes_{n}"));
        g.throughput(Throughput::Elements(v as u64));
        g.sample_size(10).sampling_mode(SamplingMode::Flat);
        for nodes_n in SWEEP_NODES {
            let options = FastOptions {
                nodes: nodes_n,
                ..FastOptions::DEFAULT
            };
            let t = Instant::now();
            let mesh =
                FastMesh::bind(&s.model, &s.positions, &s.triangles, &options).expect("bind");
            eprintln!(
                "fast bind, {v} vertices, {nodes_n} nodes: {:.0} ms",
                t.elapsed().as_secs_f64() * 1e3
            );
            let mut fr = FastFrame::new(&mesh);
            g.bench_function(BenchmarkId::new("fast", nodes_n), |bn| {
                bn.iter(|| fast_frame(&s, &mesh, &mut fr, &mut b, Method::Lbs))
            });
        }
        g.finish();
    }
}

fn criterion_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../target")))
        .join("criterion")
}

/// Mean time in seconds of `group/function[/param]` from criterion's estimates, if measured.
fn mean_s(parts: &[&str]) -> Option<f64> {
    let mut path = criterion_dir();
    for p in parts {
        path = path.join(p);
    }
    let text = std::fs::read_to_string(path.join("new/estimates.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    Some(v["mean"]["point_estimate"].as_f64()? * 1e-9)
}

fn table() {
    println!(
        "\nkernel: {:?}; one thread; J = {JOINTS}; fast = default options {:?}",
        Kernel::detect(),
        FastOptions::DEFAULT
    );
    println!(
        "\n| vertices | exact ms | fast ms | fast DQS ms | top-k 4 ms | static LBS-4 ms | fast / static | exact / fast |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for n in SIZES {
        let g = format!("fast_{n}");
        let get = |f: &str| mean_s(&[&g, f]);
        let (Some(ex), Some(fa), Some(st)) = (get("exact"), get("fast"), get("static_lbs4")) else {
            continue;
        };
        let ms = |x: Option<f64>| x.map_or("–".into(), |x| format!("{:.3}", x * 1e3));
        println!(
            "| {} | {:.2} | {:.3} | {} | {} | {:.3} | {:.2}× | {:.0}× |",
            mesh(n).0.len(),
            ex * 1e3,
            fa * 1e3,
            ms(get("fast_dqs")),
            ms(get("topk4")),
            st * 1e3,
            fa / st,
            ex / fa
        );
    }
    println!(
        "\n| nodes N | fast frame ms ({} vertices) |",
        mesh(SWEEP_SIZE).0.len()
    );
    println!("|---|---|");
    for nodes in SWEEP_NODES {
        if let Some(t) = mean_s(&[
            &format!("fast_nodes_{SWEEP_SIZE}"),
            "fast",
            &nodes.to_string(),
        ]) {
            println!("| {nodes} | {:.3} |", t * 1e3);
        }
    }
    println!(
        "\n| vertices, nodes N | base influences | static LBS-4 ms | fast ms | fast / static |"
    );
    println!("|---|---|---|---|---|");
    for n in OPTION_SIZES {
        let Some(st) = mean_s(&[&format!("fast_{n}"), "static_lbs4"]) else {
            continue;
        };
        for (nodes, base) in OPTION_PAIRS {
            let id = format!("n{nodes}_b{base}");
            if let Some(t) = mean_s(&[&format!("fast_options_{n}"), "fast", &id]) {
                println!(
                    "| {} vertices, {nodes} | {base} | {:.3} | {:.3} | {:.2}× |",
                    mesh(n).0.len(),
                    st * 1e3,
                    t * 1e3,
                    t / st
                );
            }
        }
    }
}

fn main() {
    let mut c = Criterion::default()
        .output_directory(&criterion_dir())
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    benches(&mut c);
    c.final_summary();
    table();
}
