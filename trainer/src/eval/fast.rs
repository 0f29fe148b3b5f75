//! Scoring the runtime's fast path (`trainer eval --fast [N]`): the same benchmark as the exact
//! SkinNet row (poses of the test frames, M2S/S2M/Chamfer against the ground truth, the same
//! surface samples), plus the added error measured directly against the exact path on the same
//! frames: mean and largest vertex distance, and the mean L1 distance of the weights.
//!
//! Rows: `ours-fastN` (the fast path's LBS, `FastSkinJob`) and, per `--top-k K`,
//! `ours-fastN-topK` (the `TopKJob` output in the chosen weight format, dequantised and posed
//! by this crate's own LBS, as an engine's 4- or 8-influence skinning would).

use glam::Vec3;
use skinfield_formats::capture::Capture;
use skinfield_formats::{StaticSkin, Template};
use skinfield_runtime::{
    FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, Method, Scratch, SkinNetModel,
    TopKIndices, TopKJob, TopKWeights,
};

use super::posing::{Blend, pose_dense_lbs, pose_static};
use super::table::EvalRow;
use super::{EvalError, EvalOptions, average, character_size, evaluate_mesh_frames, load_skinnet};

/// Weight format of the scored top-k output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TopKFormat {
    /// unorm8 (255 is one).
    Unorm8,
    /// unorm16 (65535 is one).
    Unorm16,
    /// f32 on the 2⁻²⁴ grid.
    F32,
}

impl TopKFormat {
    /// The name used in row names and on the command line.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Unorm8 => "unorm8",
            Self::Unorm16 => "unorm16",
            Self::F32 => "f32",
        }
    }
}

/// What `--fast` scores.
#[derive(Clone, Debug, PartialEq)]
pub struct FastEval {
    /// Bind-time options of the fast path.
    pub options: FastOptions,
    /// Top-k outputs to score too (each 1..=8).
    pub top_k: Vec<usize>,
    /// Their weight format.
    pub format: TopKFormat,
}

/// The added error of one fast-path row against the exact path, over every vertex of every
/// test frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VsExact {
    /// The row.
    pub method: String,
    /// Mean distance between the fast and the exact posed vertex (cm).
    pub mean_cm: f64,
    /// Largest such distance (cm).
    pub max_cm: f64,
    /// Mean over vertices of Σ_j |w_fast − w_exact| (the weights' L1 distance).
    pub weights_l1: f64,
    /// Nodes SkinNet ran at.
    pub nodes: usize,
    /// Bind time of the fast mesh (ms, this build).
    pub bind_ms: f64,
}

/// One variant's posed meshes and weights for a frame.
struct Posed {
    positions: Vec<Vec3>,
    weights: Vec<f32>,
}

/// Scores the fast path of the `.skf` at `path` on `template` (the capture's canonical space):
/// the rows and their added error against the exact path.
pub fn evaluate_fast(
    capture: &Capture,
    template: &Template,
    path: &std::path::Path,
    fast: &FastEval,
    options: &EvalOptions,
) -> Result<(Vec<EvalRow>, Vec<VsExact>), EvalError> {
    let model = load_skinnet(path, capture)?;
    let runtime = |e: skinfield_runtime::RuntimeError| EvalError::Skf {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let t = std::time::Instant::now();
    let mesh = FastMesh::bind(
        &model,
        &template.positions,
        &template.triangles,
        &fast.options,
    )
    .map_err(runtime)?;
    let bind_ms = t.elapsed().as_secs_f64() * 1e3;
    let name = format!("ours-fast{}", mesh.node_count());
    let mut variants: Vec<(String, Option<usize>)> = vec![(name.clone(), None)];
    for &k in &fast.top_k {
        variants.push((format!("{name}-top{k}-{}", fast.format.name()), Some(k)));
    }
    let mut rows = Vec::new();
    let mut errors = Vec::new();
    for (method, top_k) in variants {
        let (mut sum, mut max, mut l1, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        let frames = evaluate_mesh_frames(capture, &template.triangles, options, |frame| {
            let pose = capture.poses.get(frame).ok_or_else(|| EvalError::Skf {
                path: path.to_owned(),
                reason: format!("frame {frame} out of range"),
            })?;
            let exact = exact_pose(capture, &model, template, pose, frame, path)?;
            let fast = fast_pose(capture, &model, &mesh, template, pose, top_k, fast.format)
                .map_err(|e| match e {
                    PoseFailure::Runtime(e) => runtime(e),
                    PoseFailure::Posing(source) => EvalError::Posing { frame, source },
                })?;
            for (a, b) in fast.positions.iter().zip(&exact.positions) {
                let d = f64::from(a.distance(*b)) * 100.0;
                sum += d;
                max = max.max(d);
            }
            let j = model.joint_count();
            for (a, b) in fast
                .weights
                .chunks_exact(j)
                .zip(exact.weights.chunks_exact(j))
            {
                l1 += a
                    .iter()
                    .zip(b)
                    .map(|(x, y)| f64::from((x - y).abs()))
                    .sum::<f64>();
            }
            count += fast.positions.len();
            Ok(fast.positions)
        })?;
        rows.push(average(&method, &frames, character_size(&capture.template)));
        let n = count.max(1) as f64;
        errors.push(VsExact {
            method,
            mean_cm: sum / n,
            max_cm: max,
            weights_l1: l1 / n,
            nodes: mesh.node_count(),
            bind_ms,
        });
    }
    Ok((rows, errors))
}

fn exact_pose(
    capture: &Capture,
    model: &SkinNetModel,
    template: &Template,
    pose: &skinfield_formats::Pose,
    frame: usize,
    path: &std::path::Path,
) -> Result<Posed, EvalError> {
    let mut weights = vec![0.0f32; template.positions.len() * model.joint_count()];
    model
        .weights_for(&template.positions, pose, &mut weights)
        .map_err(|e| EvalError::Skf {
            path: path.to_owned(),
            reason: format!("frame {frame}: {e}"),
        })?;
    let positions = pose_dense_lbs(&capture.skeleton, &weights, &template.positions, pose)
        .map_err(|source| EvalError::Posing { frame, source })?;
    Ok(Posed { positions, weights })
}

enum PoseFailure {
    Runtime(skinfield_runtime::RuntimeError),
    Posing(super::PosingError),
}

fn fast_pose(
    capture: &Capture,
    model: &SkinNetModel,
    mesh: &FastMesh,
    template: &Template,
    pose: &skinfield_formats::Pose,
    top_k: Option<usize>,
    format: TopKFormat,
) -> Result<Posed, PoseFailure> {
    let n = template.positions.len();
    let j = model.joint_count();
    let mut frame = FrameState::new(model);
    frame.set_pose(model, pose).map_err(PoseFailure::Runtime)?;
    let mut nodes = FastFrame::new(mesh);
    nodes
        .update(model, mesh, &frame, &mut Scratch::new(model))
        .map_err(PoseFailure::Runtime)?;
    let mut positions = vec![Vec3::ZERO; n];
    let mut weights = vec![0.0f32; n * j];
    FastSkinJob {
        mesh,
        frame: &frame,
        nodes: &nodes,
        method: Method::Lbs,
        influences: 4,
        first_vertex: 0,
        rest_normals: None,
        rest_tangents: None,
        out_positions: &mut positions,
        out_normals: None,
        out_tangents: None,
        out_weights: Some(&mut weights),
    }
    .run()
    .map_err(PoseFailure::Runtime)?;
    let Some(k) = top_k else {
        return Ok(Posed { positions, weights });
    };
    // What an engine receives: K joints and quantised weights per vertex.
    let mut indices = vec![0u16; n * k];
    let dequantised: Vec<f32> = match format {
        TopKFormat::Unorm8 => {
            let mut q = vec![0u8; n * k];
            run_top_k(
                mesh,
                &frame,
                &nodes,
                k,
                &mut indices,
                TopKWeights::Unorm8(&mut q),
            )?;
            q.iter().map(|&x| f32::from(x) / 255.0).collect()
        }
        TopKFormat::Unorm16 => {
            let mut q = vec![0u16; n * k];
            run_top_k(
                mesh,
                &frame,
                &nodes,
                k,
                &mut indices,
                TopKWeights::Unorm16(&mut q),
            )?;
            q.iter().map(|&x| f32::from(x) / 65535.0).collect()
        }
        TopKFormat::F32 => {
            let mut q = vec![0f32; n * k];
            run_top_k(
                mesh,
                &frame,
                &nodes,
                k,
                &mut indices,
                TopKWeights::F32(&mut q),
            )?;
            q
        }
    };
    let offsets = (0..=n).map(|v| (v * k) as u32).collect();
    let joints = indices.iter().map(|&i| u32::from(i)).collect();
    let skin = StaticSkin::new(offsets, joints, dequantised, j)
        .map_err(|e| PoseFailure::Runtime(skinfield_runtime::RuntimeError::Skin(e)))?;
    let positions = pose_static(
        &capture.skeleton,
        &skin,
        &template.positions,
        pose,
        Blend::Linear,
    )
    .map_err(PoseFailure::Posing)?;
    let mut dense = vec![0.0f32; n * j];
    for v in 0..n {
        let (js, ws) = skin.influences(v);
        for (&jj, &w) in js.iter().zip(ws) {
            dense[v * j + jj as usize] += w;
        }
    }
    Ok(Posed {
        positions,
        weights: dense,
    })
}

fn run_top_k(
    mesh: &FastMesh,
    frame: &FrameState,
    nodes: &FastFrame,
    k: usize,
    indices: &mut [u16],
    weights: TopKWeights<'_>,
) -> Result<(), PoseFailure> {
    TopKJob {
        mesh,
        frame,
        nodes,
        influences: k,
        first_vertex: 0,
        out_indices: TopKIndices::U16(indices),
        out_weights: weights,
    }
    .run()
    .map_err(PoseFailure::Runtime)
}
