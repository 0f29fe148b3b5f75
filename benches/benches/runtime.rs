//! Runtime throughput: whole frames (pose → weights → LBS with normals) and the MLP alone, for
//! 1k, 10k and 50k vertices, J = 24, the paper's architecture with random weights; one and two
//! threads; side by side with the scalar path, a plain batched-matmul forward in candle on the
//! same weights (unfused Softplus), and a large candle matmul as the machine's practical peak.
//!
//! After criterion's own report, a table with the ratios is printed from the estimates it
//! wrote (the table in `runtime/README.md` comes from this).

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use candle_core::{DType, Device, Tensor};
use criterion::{BenchmarkId, Criterion, SamplingMode, Throughput};
use glam::Vec3;
use rayon::ThreadPool;
use skinfield_benches::{random_points, random_pose, rng, vinecs_bytes};
use skinfield_formats::skf::{Net, SkfView};
use skinfield_formats::{Pose, pose_features};
use skinfield_runtime::parallel::run_parallel;
use skinfield_runtime::{
    BoundMesh, FrameState, Kernel, Method, Scratch, SkinJob, SkinNetModel, WeightsJob,
};

const SIZES: [usize; 3] = [1_000, 10_000, 50_000];
const JOINTS: u32 = 24;
/// Largest mesh the scalar path is timed on.
const SCALAR_MAX: usize = 1_000;
/// Largest mesh the candle forward is timed on (and compared with, for fairness, below).
const CANDLE_MAX: usize = 10_000;
/// The peak reference: `[M, K] × [K, N]`.
const PEAK: (usize, usize, usize) = (4096, 256, 256);

fn pools() -> [(usize, ThreadPool); 2] {
    [1, 2].map(|t| {
        (
            t,
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("thread pool"),
        )
    })
}

struct Setup {
    model: SkinNetModel,
    scalar: SkinNetModel,
    mesh: BoundMesh,
    normals: Vec<Vec3>,
    pose: Pose,
    candle: CandleNet,
}

fn setup(n: usize, bytes: &[u8]) -> Setup {
    let model = SkinNetModel::from_skf(bytes).expect("model");
    let mut scalar = model.clone();
    scalar.set_kernel(Kernel::Scalar).expect("scalar kernel");
    let mut r = rng(7 + n as u64);
    let pts = random_points(n, &mut r);
    let normals = pts
        .iter()
        .map(|p| (*p - Vec3::Y).normalize_or(Vec3::Y))
        .collect();
    let mesh = BoundMesh::bind(&model, &pts).expect("bind");
    let pose = random_pose(model.skeleton(), &mut r, 0.6);
    let candle = CandleNet::new(bytes, &pts, &model, &pose);
    Setup {
        model,
        scalar,
        mesh,
        normals,
        pose,
        candle,
    }
}

/// One whole frame: pose terms, then the skinning job split over `scratches` (one per thread).
fn frame(
    model: &SkinNetModel,
    s: &Setup,
    fs: &mut FrameState,
    out: &mut [Vec3],
    nrm: &mut [Vec3],
    scratches: &mut [Scratch],
) {
    fs.set_pose(model, &s.pose).expect("pose");
    let job = SkinJob {
        model,
        mesh: &s.mesh,
        frame: fs,
        method: Method::Lbs,
        first_vertex: 0,
        rest_normals: Some(&s.normals),
        rest_tangents: None,
        out_positions: out,
        out_normals: Some(nrm),
        out_tangents: None,
        out_weights: None,
    };
    run_parallel(job, scratches).expect("frame");
}

/// The MLP alone over all vertices, split in `scratches.len()` ranges under rayon.
fn mlp(model: &SkinNetModel, s: &Setup, fs: &FrameState, w: &mut [f32], scratches: &mut [Scratch]) {
    let j = model.joint_count();
    let n = w.len() / j;
    if scratches.len() == 1 {
        WeightsJob {
            model,
            mesh: &s.mesh,
            frame: fs,
            first_vertex: 0,
            out_weights: w,
        }
        .run(&mut scratches[0])
        .expect("mlp");
        return;
    }
    let half = n / 2 / 32 * 32;
    let (w0, w1) = w.split_at_mut(half * j);
    let (s0, s1) = scratches.split_at_mut(1);
    rayon::join(
        || {
            WeightsJob {
                model,
                mesh: &s.mesh,
                frame: fs,
                first_vertex: 0,
                out_weights: w0,
            }
            .run(&mut s0[0])
            .expect("mlp")
        },
        || {
            WeightsJob {
                model,
                mesh: &s.mesh,
                frame: fs,
                first_vertex: half,
                out_weights: w1,
            }
            .run(&mut s1[0])
            .expect("mlp")
        },
    );
}

/// The same network as plain batched matmuls in candle: `[N, in] × Wᵀ + b`, Softplus as
/// separate element-wise ops, skip as a concatenation, softmax.
struct CandleNet {
    input: Tensor,
    layers: Vec<(Tensor, Tensor)>,
    skip: usize,
    beta: f64,
}

impl CandleNet {
    fn new(bytes: &[u8], pts: &[Vec3], model: &SkinNetModel, pose: &Pose) -> Self {
        let view = SkfView::parse(bytes).expect("view");
        let c = *view.config();
        let dev = Device::Cpu;
        let mut theta = vec![0.0; c.pose_width()];
        pose_features(model.skeleton(), pose, c.up_axis, &mut theta).expect("features");
        let mut input = Vec::with_capacity(pts.len() * c.input_width(Net::Skin));
        for p in pts {
            input.extend(c.position_input(*p));
            input.extend_from_slice(&theta);
        }
        let input =
            Tensor::from_vec(input, (pts.len(), c.input_width(Net::Skin)), &dev).expect("input");
        let layers = (0..=c.hidden_count as usize)
            .map(|i| {
                let (w, b) = view.layer(Net::Skin, i).expect("layer");
                let mut wv = vec![0.0; w.len()];
                w.to_f32(&mut wv).expect("w");
                let mut bv = vec![0.0; b.len()];
                b.to_f32(&mut bv).expect("b");
                let (o, k) = (w.dims[0] as usize, w.dims[1] as usize);
                // Stored transposed once, so the timed matmul is a plain row-major product.
                let wt = Tensor::from_vec(wv, (o, k), &dev)
                    .and_then(|t| t.t()?.contiguous())
                    .expect("wt");
                (wt, Tensor::from_vec(bv, o, &dev).expect("bias"))
            })
            .collect();
        Self {
            input,
            layers,
            skip: c.skip_layer as usize,
            beta: f64::from(c.softplus_beta),
        }
    }

    fn forward(&self) -> candle_core::Result<Tensor> {
        let n = self.layers.len() - 1;
        let mut h = self.input.clone();
        for (i, (wt, b)) in self.layers.iter().enumerate() {
            let x = if i == self.skip && i > 0 {
                Tensor::cat(&[&h, &self.input], 1)?
            } else {
                h
            };
            let y = x.matmul(wt)?.broadcast_add(b)?;
            h = if i < n {
                // softplus_β(y) = relu(y) + log(1 + exp(−β|y|)) / β, one op at a time.
                (y.relu()?
                    + y.abs()?
                        .affine(-self.beta, 0.0)?
                        .exp()?
                        .affine(1.0, 1.0)?
                        .log()?
                        .affine(1.0 / self.beta, 0.0)?)?
            } else {
                y
            };
        }
        let m = h.max_keepdim(1)?;
        let e = h.broadcast_sub(&m)?.exp()?;
        e.broadcast_div(&e.sum_keepdim(1)?)
    }
}

fn benches(c: &mut Criterion) {
    let bytes = vinecs_bytes(JOINTS, 1);
    let pools = pools();
    {
        let (m, k, n) = PEAK;
        let a = Tensor::ones((m, k), DType::F32, &Device::Cpu).expect("a");
        let b = Tensor::ones((k, n), DType::F32, &Device::Cpu).expect("b");
        let mut g = c.benchmark_group("peak");
        g.throughput(Throughput::Elements((2 * m * k * n) as u64));
        for (t, pool) in &pools {
            g.bench_function(BenchmarkId::new("candle_matmul", format!("{t}t")), |bn| {
                pool.install(|| bn.iter(|| black_box(a.matmul(&b).expect("matmul"))))
            });
        }
        g.finish();
    }
    for n in SIZES {
        let s = setup(n, &bytes);
        let j = s.model.joint_count();
        let mut fs = FrameState::new(&s.model);
        let mut out = vec![Vec3::ZERO; n];
        let mut nrm = vec![Vec3::ZERO; n];
        let mut w = vec![0.0; n * j];
        let mut g = c.benchmark_group(format!("frame_{n}"));
        g.throughput(Throughput::Elements(n as u64));
        // Frames take 5 ms – 0.5 s (scalar): ten equal samples, not criterion's ramp.
        g.sample_size(10).sampling_mode(SamplingMode::Flat);
        for (name, model) in [("ours", &s.model), ("scalar", &s.scalar)] {
            // The scalar path needs ~0.4 ms per vertex on this machine: 1k vertices only, to keep
            // the run within minutes (its ratio does not depend on the vertex count).
            if name == "scalar" && n > SCALAR_MAX {
                continue;
            }
            for (t, pool) in &pools {
                let mut scratches: Vec<Scratch> = (0..*t).map(|_| Scratch::new(model)).collect();
                g.bench_function(BenchmarkId::new(name, format!("{t}t")), |bn| {
                    pool.install(|| {
                        bn.iter(|| frame(model, &s, &mut fs, &mut out, &mut nrm, &mut scratches))
                    })
                });
            }
        }
        g.finish();
        fs.set_pose(&s.model, &s.pose).expect("pose");
        let mut g = c.benchmark_group(format!("mlp_{n}"));
        g.throughput(Throughput::Elements(n as u64));
        // Frames take 5 ms – 0.5 s (scalar): ten equal samples, not criterion's ramp.
        g.sample_size(10).sampling_mode(SamplingMode::Flat);
        for (t, pool) in &pools {
            let mut scratches: Vec<Scratch> = (0..*t).map(|_| Scratch::new(&s.model)).collect();
            g.bench_function(BenchmarkId::new("ours", format!("{t}t")), |bn| {
                pool.install(|| bn.iter(|| mlp(&s.model, &s, &fs, &mut w, &mut scratches)))
            });
            if n <= CANDLE_MAX {
                g.bench_function(BenchmarkId::new("candle", format!("{t}t")), |bn| {
                    pool.install(|| {
                        bn.iter(|| black_box(s.candle.forward().expect("candle forward")))
                    })
                });
            }
        }
        // Same weights, same answers: a check that the comparison is fair.
        if n > CANDLE_MAX {
            g.finish();
            continue;
        }
        mlp(&s.model, &s, &fs, &mut w, &mut [Scratch::new(&s.model)]);
        let theirs: Vec<f32> = s
            .candle
            .forward()
            .and_then(|t| t.flatten_all()?.to_vec1())
            .expect("candle weights");
        let worst = w
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst < 1e-4, "candle and runtime disagree by {worst}");
        g.finish();
    }
}

fn criterion_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../target")))
        .join("criterion")
}

/// Mean time in seconds of `group/function/param` from criterion's estimates, if measured.
fn mean_s(group: &str, func: &str, param: &str) -> Option<f64> {
    let path = criterion_dir()
        .join(group)
        .join(func)
        .join(param)
        .join("new/estimates.json");
    let text = std::fs::read_to_string(path).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    Some(v["mean"]["point_estimate"].as_f64()? * 1e-9)
}

fn table(macs_ours: usize, macs_full: usize) {
    let (m, k, n) = PEAK;
    println!(
        "\n| vertices | threads | frame ours (fps / Mvert/s) | frame scalar (fps) | MLP ours GFLOP/s | MLP candle GFLOP/s (Mvert/s) | peak GFLOP/s | ours/peak | ours/candle (vert/s) | ours/scalar (frame) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for nv in SIZES {
        for t in ["1t", "2t"] {
            let get = |g: &str, f: &str| mean_s(&format!("{g}_{nv}"), f, t);
            let (Some(fo), Some(mo), Some(pk)) = (
                get("frame", "ours"),
                get("mlp", "ours"),
                mean_s("peak", "candle_matmul", t),
            ) else {
                continue;
            };
            let nvf = nv as f64;
            let g_ours = 2.0 * macs_ours as f64 * nvf / mo / 1e9;
            let peak = 2.0 * (m * k * n) as f64 / pk / 1e9;
            let (scalar_fps, scalar_ratio) = match get("frame", "scalar") {
                Some(fs) => (format!("{:.2}", 1.0 / fs), format!("{:.1}×", fs / fo)),
                None => ("–".into(), "–".into()),
            };
            let (candle, candle_ratio) = match get("mlp", "candle") {
                Some(mc) => (
                    format!(
                        "{:.1} ({:.3})",
                        2.0 * macs_full as f64 * nvf / mc / 1e9,
                        nvf / mc / 1e6
                    ),
                    format!("{:.2}×", mc / mo),
                ),
                None => ("–".into(), "–".into()),
            };
            println!(
                "| {nv} | {t} | {:.1} / {:.3} | {scalar_fps} | {g_ours:.1} | {candle} | {peak:.1} | {:.0} % | {candle_ratio} | {scalar_ratio} |",
                1.0 / fo,
                nvf / fo / 1e6,
                100.0 * g_ours / peak,
            );
        }
    }
    println!(
        "\nGFLOP/s count multiply-adds × 2 actually executed: ours {:.3} MFLOP/vertex (position and pose parts precomputed), candle {:.3} MFLOP/vertex (the whole network).",
        2.0 * macs_ours as f64 / 1e6,
        2.0 * macs_full as f64 / 1e6
    );
}

fn main() {
    let mut c = Criterion::default()
        .output_directory(&criterion_dir())
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .configure_from_args();
    benches(&mut c);
    c.final_summary();
    let model = SkinNetModel::from_skf(&vinecs_bytes(JOINTS, 1)).expect("model");
    table(
        model.macs_per_vertex(),
        model.config().macs_per_vertex(Net::Skin),
    );
}
