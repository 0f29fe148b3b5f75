//! Writes the inputs of the C example (`skin_frames.c`) and the Rust runtime's answer for them,
//! from a `.skf` model and the glTF character it was trained on:
//!
//! - `engine.txt`: the engine's skeleton, one joint per line, `parent<TAB>name` (`-1` for a
//!   root), in glTF node order (not the model's order: the C side maps joints by name);
//! - `mesh.bin`: `u64` vertex count, then positions and normals (3 f32 each per vertex) in the
//!   model's canonical space;
//! - `frames.bin`: `u64` frame count, `u64` joint count, then per frame one `SkfTransform`
//!   (10 f32: translation, rotation x y z w, scale) per engine joint;
//! - `reference.bin`: per frame and vertex, the position and normal from the Rust runtime's
//!   packed `SkinJob` (LBS on even frames, DQS on odd ones), 6 f32;
//! - `triangles.bin`: `u64` triangle count, then 3 `u32` vertex indices per triangle;
//! - `reference_fast.bin`: the same as `reference.bin` from the runtime's fast path
//!   (`FastMesh` with the default options over those triangles, DQS keeping 4 joints).
//!
//! All little-endian. Usage: `fixture MODEL.skf CHARACTER.glb OUT_DIR`.

use std::path::Path;
use std::process::ExitCode;

use glam::{Mat4, Vec3};
use skinfield_formats::gltf_io::load_gltf;
use skinfield_runtime::{
    BoundMesh, FastFrame, FastMesh, FastOptions, FastSkinJob, FrameState, JointMap, Method,
    Scratch, SkinJob, SkinNetModel, Transform, read_skf_file,
};

const FRAMES: usize = 6;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("fixture: {e}");
            ExitCode::FAILURE
        }
    }
}

fn floats(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// Appends each vertex's position then normal (6 f32 per vertex).
fn positions_and_normals(out: &mut Vec<u8>, positions: &[Vec3], normals: &[Vec3]) {
    for (p, n) in positions.iter().zip(normals) {
        floats(out, &p.to_array());
        floats(out, &n.to_array());
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [model_path, asset, out_dir] = args.as_slice() else {
        return Err("usage: fixture MODEL.skf CHARACTER.glb OUT_DIR".into());
    };
    let out_dir = Path::new(out_dir);
    std::fs::create_dir_all(out_dir)?;
    let model = SkinNetModel::from_skf(&read_skf_file(Path::new(model_path))?)?;
    let doc = load_gltf(Path::new(asset))?;
    let skin = doc.largest_skin().ok_or("the asset has no skinned mesh")?;
    let clip = doc.clips.first().ok_or("the asset has no clip")?;

    // The engine's skeleton in glTF node order.
    let mut order: Vec<usize> = (0..skin.skeleton.len()).collect();
    order.sort_by_key(|&j| skin.joint_nodes[j]);
    let mut engine_of = vec![0usize; order.len()];
    for (e, &j) in order.iter().enumerate() {
        engine_of[j] = e;
    }
    let mut engine = String::new();
    for &j in &order {
        let parent = skin.skeleton.parents()[j].map_or(-1, |p| engine_of[p] as i64);
        engine.push_str(&format!("{parent}\t{}\n", skin.skeleton.names()[j]));
    }
    std::fs::write(out_dir.join("engine.txt"), engine)?;

    // The mesh in the model's canonical space.
    let names: Vec<&str> = order
        .iter()
        .map(|&j| skin.skeleton.names()[j].as_str())
        .collect();
    let map = JointMap::new(model.skeleton(), &names)?;
    let ibms: Vec<Mat4> = order
        .iter()
        .map(|&j| skin.skeleton.inverse_bind()[j])
        .collect();
    let space = map.bind_space(model.skeleton(), &ibms, 1e-3)?;
    let positions = space.positions(&skin.template.positions);
    let normals = space.normals(&skin.template.normals);
    let n = positions.len();
    let mut mesh_bytes = (n as u64).to_le_bytes().to_vec();
    for v in positions.iter().chain(&normals) {
        floats(&mut mesh_bytes, &v.to_array());
    }
    std::fs::write(out_dir.join("mesh.bin"), mesh_bytes)?;
    let triangles = &skin.template.triangles;
    let mut triangle_bytes = (triangles.len() as u64).to_le_bytes().to_vec();
    for t in triangles {
        for i in t {
            triangle_bytes.extend_from_slice(&i.to_le_bytes());
        }
    }
    std::fs::write(out_dir.join("triangles.bin"), triangle_bytes)?;

    // Frames in the engine's order, and the Rust runtime's skinning of each.
    let mesh = BoundMesh::bind(&model, &positions)?;
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let (mut p, mut nn) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
    let mut frames = Vec::new();
    frames.extend_from_slice(&(FRAMES as u64).to_le_bytes());
    frames.extend_from_slice(&(order.len() as u64).to_le_bytes());
    let mut reference = Vec::new();
    let fast_mesh = FastMesh::bind(&model, &positions, triangles, &FastOptions::DEFAULT)?;
    let mut nodes = FastFrame::new(&fast_mesh);
    let mut reference_fast = Vec::new();
    for f in 0..FRAMES {
        let t = clip.duration_s * f as f32 / (FRAMES - 1) as f32;
        let pose = clip.sample(skin, t);
        let locals: Vec<Transform> = order.iter().map(|&j| pose.locals[j]).collect();
        for l in &locals {
            floats(&mut frames, &l.translation.to_array());
            floats(&mut frames, &l.rotation.to_array());
            floats(&mut frames, &l.scale.to_array());
        }
        frame.set_engine_pose(&model, &map, &locals)?;
        let method = if f % 2 == 0 { Method::Lbs } else { Method::Dqs };
        SkinJob {
            model: &model,
            mesh: &mesh,
            frame: &frame,
            method,
            first_vertex: 0,
            rest_normals: Some(&normals),
            rest_tangents: None,
            out_positions: &mut p,
            out_normals: Some(&mut nn),
            out_tangents: None,
            out_weights: None,
        }
        .run(&mut scratch)?;
        positions_and_normals(&mut reference, &p, &nn);
        nodes.update(&model, &fast_mesh, &frame, &mut scratch)?;
        FastSkinJob {
            mesh: &fast_mesh,
            frame: &frame,
            nodes: &nodes,
            method,
            influences: 4,
            first_vertex: 0,
            rest_normals: Some(&normals),
            rest_tangents: None,
            out_positions: &mut p,
            out_normals: Some(&mut nn),
            out_tangents: None,
            out_weights: None,
        }
        .run()?;
        positions_and_normals(&mut reference_fast, &p, &nn);
    }
    std::fs::write(out_dir.join("frames.bin"), frames)?;
    std::fs::write(out_dir.join("reference.bin"), reference)?;
    std::fs::write(out_dir.join("reference_fast.bin"), reference_fast)?;
    println!(
        "fixture: {} joints (engine order), {n} vertices, {FRAMES} frames in {}",
        order.len(),
        out_dir.display()
    );
    Ok(())
}
