//! Embedding the runtime on the GPU: the engine's own wgpu device (here a headless one), the
//! pipelines built once, the model and the mesh uploaded once, and every frame only the pose
//! (through the same `FrameState` and joint map as the CPU path) uploaded and the frame
//! recorded into a command encoder. The output buffer is `STORAGE | VERTEX`, ready to draw.
//!
//! The example reads the skinned vertices back and checks them against the CPU path
//! (`SkinJob`) on every frame; it fails when they differ by more than 1e-4 of the mesh radius.
//!
//! ```text
//! cargo run -p skinfield-runtime --features gpu --example gpu_headless -- MODEL.skf CHARACTER.glb
//! ```

use std::path::Path;
use std::process::ExitCode;

use skinfield_formats::gltf_io::load_gltf;
use skinfield_runtime::gpu::{GpuSkinner, SkinnedVertex, headless_device};
use skinfield_runtime::{
    BoundMesh, FrameState, JointMap, Method, Scratch, SkfView, SkinJob, SkinNetModel, Vec3,
    read_skf_file,
};

const FRAMES: usize = 8;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("gpu_headless: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [model_path, asset] = args.as_slice() else {
        return Err("usage: gpu_headless MODEL.skf CHARACTER.glb".into());
    };
    let bytes = read_skf_file(Path::new(model_path))?;
    let doc = load_gltf(Path::new(asset))?;
    let skin = doc.largest_skin().ok_or("the asset has no skinned mesh")?;
    let clip = doc.clips.first().ok_or("the asset has no clip")?;
    let rest = &skin.template;

    // The engine owns the device; the runtime only borrows it.
    let (adapter, device, queue) = headless_device(wgpu::Limits::default())?;
    let info = adapter.get_info();
    let skinner = GpuSkinner::new(&device)?;
    let gpu_model = skinner.bind_model(&device, &SkfView::parse(&bytes)?)?;

    // The CPU side: the same model for the frame state (pose → matrices and pose features),
    // and the CPU skinning as the reference. The mesh is brought from the skin's bind space
    // into the model's canonical space (see `JointMap::bind_space`).
    let model = SkinNetModel::from_skf(&bytes)?;
    let map = JointMap::new(model.skeleton(), skin.skeleton.names())?;
    let space = map.bind_space(model.skeleton(), skin.skeleton.inverse_bind(), 1e-3)?;
    let (positions, normals) = (
        space.positions(&rest.positions),
        space.normals(&rest.normals),
    );
    let mesh = BoundMesh::bind(&model, &positions)?;
    let gpu_mesh = skinner.bind_mesh(&device, &queue, &gpu_model, &positions, &normals)?;
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let n = mesh.vertex_count();
    let (mut cpu, mut cpu_normals) = (vec![Vec3::ZERO; n], vec![Vec3::ZERO; n]);
    let size = positions.iter().fold(0.0f32, |m, p| m.max(p.length()));
    println!(
        "{} on {} ({:?}): {n} vertices, {} joints",
        Path::new(asset).display(),
        info.name,
        info.backend,
        model.joint_count()
    );

    let mut worst = 0.0f32;
    for f in 0..FRAMES {
        let t = clip.duration_s * f as f32 / (FRAMES - 1) as f32;
        let pose = clip.sample(skin, t);
        frame.set_engine_pose(&model, &map, &pose.locals)?;
        for method in [Method::Lbs, Method::Dqs] {
            skinner.skin(&device, &queue, &gpu_mesh, &frame, method)?;
            let gpu: Vec<SkinnedVertex> = gpu_mesh.read_vertices(&device, &queue)?;
            SkinJob {
                model: &model,
                mesh: &mesh,
                frame: &frame,
                method,
                first_vertex: 0,
                rest_normals: Some(&normals),
                rest_tangents: None,
                out_positions: &mut cpu,
                out_normals: Some(&mut cpu_normals),
                out_tangents: None,
                out_weights: None,
            }
            .run(&mut scratch)?;
            for (g, c) in gpu.iter().zip(&cpu) {
                worst = worst.max(Vec3::from_slice(&g.position[..3]).distance(*c));
            }
        }
    }
    let relative = worst / size;
    println!(
        "{FRAMES} frames × LBS and DQS: GPU vs CPU worst vertex {worst:.3e} ({relative:.2e} of \
         the mesh radius)"
    );
    if relative > 1e-4 {
        return Err(format!("GPU and CPU differ by {relative:.2e} of the mesh radius").into());
    }
    Ok(())
}
