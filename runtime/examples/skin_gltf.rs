//! Embedding the runtime on the CPU, as an engine would: load a `.skf` once, map the engine's
//! skeleton onto it by joint name, bind the character's mesh once, then every frame pose it
//! from the engine's own local transforms and skin it into an interleaved vertex buffer, with
//! no allocation per frame.
//!
//! Here the "engine" is a glTF file: its skin's joints in glTF node order (not the `.skf`'s
//! order) and a clip sampled at 30 frames per second. For each frame the example prints how far
//! SkinNet's surface lies from the file's own (artist) skinning, and the frame time.
//!
//! ```text
//! cargo run -p skinfield-runtime --example skin_gltf -- MODEL.skf CHARACTER.glb [CLIP]
//! ```
//! (A model for a glTF character comes from `trainer synth --character` and `trainer train`.)

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use skinfield_formats::gltf_io::{GltfSkin, load_gltf};
use skinfield_runtime::{
    BoundMesh, FrameState, InterleavedJob, JointMap, Mat4, Method, Palette, Scratch, SkinNetModel,
    StaticSkinJob, Transform, Vec3, VertexLayout, WeightSource, read_skf_file,
};

/// The engine's vertex: position, a UV the skinning leaves alone, normal.
const LAYOUT: VertexLayout = VertexLayout {
    stride: 32,
    position: 0,
    normal: Some(20),
    tangent: None,
};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("skin_gltf: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The engine's skeleton: the skin's joints sorted by glTF node index, with parents.
fn engine_skeleton(skin: &GltfSkin) -> (Vec<usize>, Vec<String>, Vec<Option<usize>>) {
    let mut order: Vec<usize> = (0..skin.skeleton.len()).collect();
    order.sort_by_key(|&j| skin.joint_nodes[j]);
    let mut engine_of = vec![0; order.len()];
    for (e, &j) in order.iter().enumerate() {
        engine_of[j] = e;
    }
    let names = order
        .iter()
        .map(|&j| skin.skeleton.names()[j].clone())
        .collect();
    let parents = order
        .iter()
        .map(|&j| skin.skeleton.parents()[j].map(|p| engine_of[p]))
        .collect();
    (order, names, parents)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [model_path, asset, clip_arg @ ..] = args.as_slice() else {
        return Err("usage: skin_gltf MODEL.skf CHARACTER.glb [CLIP]".into());
    };

    // Load time: the model, the engine's skeleton mapped onto it, the mesh bound.
    let model = SkinNetModel::from_skf(&read_skf_file(Path::new(model_path))?)?;
    let doc = load_gltf(Path::new(asset))?;
    let skin = doc.largest_skin().ok_or("the asset has no skinned mesh")?;
    let (order, names, parents) = engine_skeleton(skin);
    let map = JointMap::new(model.skeleton(), &names)?;
    map.check_parents(model.skeleton(), &names, &parents)?;
    // The engine's mesh lives in the glTF skin's bind space; the model's canonical space may be
    // that space re-expressed (the trainer takes the character's rest scene), so align them.
    let engine_ibms: Vec<Mat4> = order
        .iter()
        .map(|&j| skin.skeleton.inverse_bind()[j])
        .collect();
    let space = map.bind_space(model.skeleton(), &engine_ibms, 1e-3)?;
    let rest = &skin.template;
    let (positions, normals) = (
        space.positions(&rest.positions),
        space.normals(&rest.normals),
    );
    let mesh = BoundMesh::bind(&model, &positions)?;
    let clip = match clip_arg.first() {
        Some(name) => doc.clip(name).ok_or(format!("no clip named `{name}`"))?,
        None => doc.clips.first().ok_or("the asset has no clip")?,
    };
    println!(
        "{}: {} vertices, model {} joints, engine skeleton {} joints (glTF node order), \
         clip `{}` {:.2} s, kernel {:?}",
        Path::new(asset).display(),
        mesh.vertex_count(),
        model.joint_count(),
        names.len(),
        clip.name,
        clip.duration_s,
        model.kernel(),
    );

    // Per-instance state, allocated once.
    let n = mesh.vertex_count();
    let mut frame = FrameState::new(&model);
    let mut scratch = Scratch::new(&model);
    let mut vertex_buffer = vec![0u8; LAYOUT.buffer_len(n).ok_or("mesh too large")?];
    let mut engine_locals = vec![Transform::IDENTITY; names.len()];
    let mut artist_palette = Palette::new(skin.skeleton.len());
    let mut artist = vec![Vec3::ZERO; n];
    let size = rest.positions.iter().fold(0.0f32, |m, p| m.max(p.length()));

    let frames = (clip.duration_s * 30.0).ceil() as usize + 1;
    let (mut worst, mut sum, mut time) = (0.0f32, 0.0f64, 0.0f64);
    for f in 0..frames {
        let t = (f as f32 / 30.0).min(clip.duration_s);
        // What the engine's animation system hands over: local transforms in its own order.
        let pose = clip.sample(skin, t);
        for (e, &j) in order.iter().enumerate() {
            engine_locals[e] = pose.locals[j];
        }

        let start = Instant::now();
        frame.set_engine_pose(&model, &map, &engine_locals)?;
        InterleavedJob {
            source: WeightSource::Exact {
                model: &model,
                mesh: &mesh,
                frame: &frame,
                scratch: &mut scratch,
            },
            method: Method::Lbs,
            first_vertex: 0,
            count: n,
            rest_normals: Some(&normals),
            rest_tangents: None,
            layout: LAYOUT,
            out: &mut vertex_buffer,
        }
        .run()?;
        time += start.elapsed().as_secs_f64();

        // The file's own skinning of the same frame, for comparison.
        artist_palette.set_pose(&skin.skeleton, &pose)?;
        StaticSkinJob {
            skin: &skin.skin,
            palette: &artist_palette,
            method: Method::Lbs,
            first_vertex: 0,
            rest_positions: &rest.positions,
            rest_normals: None,
            rest_tangents: None,
            out_positions: &mut artist,
            out_normals: None,
            out_tangents: None,
        }
        .run()?;
        for (v, a) in artist.iter().enumerate() {
            let at = v * LAYOUT.stride;
            let p = Vec3::from_array(std::array::from_fn(|k| {
                f32::from_ne_bytes(
                    vertex_buffer[at + 4 * k..at + 4 * k + 4]
                        .try_into()
                        .unwrap(),
                )
            }));
            let d = p.distance(*a);
            worst = worst.max(d);
            sum += f64::from(d);
        }
    }
    println!(
        "{frames} frames: SkinNet vs the file's skinning: mean {:.3} %, worst {:.3} % of the \
         mesh's radius; SkinNet frame {:.2} ms (one thread, positions and normals{})",
        100.0 * sum / (frames * n) as f64 / f64::from(size),
        100.0 * worst / size,
        1e3 * time / frames as f64,
        if cfg!(debug_assertions) {
            ", debug build"
        } else {
            ""
        },
    );
    Ok(())
}
