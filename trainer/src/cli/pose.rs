//! `trainer pose --asset FILE.glb --clip NAME_OR_INDEX --times 0,0.5,1 [--model M.skf] [--dqs]
//! --out OUT.json`: world-space skinned positions of every skinned primitive of a glTF asset at
//! the given clip times, computed by the runtime, for checking against other engines.
//!
//! Output: `{"frames":[{"time":t,"positions":[[x,y,z],…]}]}`, primitives in file order (mesh,
//! then primitive), vertices in accessor order. Skinning is glTF's: joint world matrix × inverse
//! bind matrix; the skinned mesh node's own transform does not apply. A time past the clip's end
//! holds its last key. With `--model`, the skin whose joints the `.skf` skeleton names gets
//! SkinNet's pose-dependent weights instead of the file's.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow, bail};
use glam::Vec3;
use serde::Serialize;
use skinfield_formats::Pose;
use skinfield_formats::gltf_io::{Clip, GltfDocument, PrimitiveInfo, load_gltf};
use skinfield_formats::skf::{SkfView, read_skf_file, write_atomic};
use skinfield_runtime::{BindSpace, BoundMesh, FrameState, JointMap, Method, SkinNetModel};
use skinfield_trainer::eval::posing::{pose_static, skin_frame};

/// Largest relative difference between the per-joint bind-space transforms of a skin and a
/// model that still counts as one bind pose (f32 inverse bind matrices agree to ~1e-6).
const BIND_TOLERANCE: f32 = 1e-3;

/// Arguments of `trainer pose`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The glTF/GLB asset.
    #[arg(long)]
    pub asset: PathBuf,
    /// Clip name, or its index in file order.
    #[arg(long)]
    pub clip: String,
    /// Comma-separated times in seconds.
    #[arg(
        long,
        value_delimiter = ',',
        required = true,
        allow_hyphen_values = true
    )]
    pub times: Vec<f32>,
    /// A `.skf` model whose SkinNet weights replace the file's for the skin it matches.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Dual-quaternion skinning instead of linear blend skinning.
    #[arg(long)]
    pub dqs: bool,
    /// Output JSON file (written atomically).
    #[arg(long)]
    pub out: PathBuf,
}

/// Skinned positions at one time.
#[derive(Serialize, Debug, Clone, PartialEq)]
pub struct Frame {
    /// Clip time in seconds.
    pub time: f32,
    /// World-space positions of every skinned primitive, in file order.
    pub positions: Vec<[f32; 3]>,
}

/// What `pose` writes.
#[derive(Serialize, Debug)]
pub struct Output {
    /// One entry per requested time.
    pub frames: Vec<Frame>,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let doc =
        load_gltf(&args.asset).with_context(|| format!("loading {}", args.asset.display()))?;
    let clip =
        find_clip(&doc, &args.clip).with_context(|| format!("{}: --clip", args.asset.display()))?;
    let model = match &args.model {
        Some(p) => Some(load_model(p)?),
        None => None,
    };
    let method = if args.dqs { Method::Dqs } else { Method::Lbs };
    let frames = pose_frames(&doc, clip, &args.times, model.as_ref(), method)?;
    let json = serde_json::to_vec(&Output { frames })?;
    write_atomic(&args.out, &json).with_context(|| format!("writing {}", args.out.display()))?;
    Ok(())
}

fn load_model(path: &Path) -> anyhow::Result<SkinNetModel> {
    let bytes = read_skf_file(path)?;
    let view = SkfView::parse(&bytes).with_context(|| format!("{}", path.display()))?;
    SkinNetModel::from_view(&view).with_context(|| format!("{}", path.display()))
}

/// The clip called `key`, else the clip at index `key`.
pub fn find_clip<'d>(doc: &'d GltfDocument, key: &str) -> anyhow::Result<&'d Clip> {
    if let Some(c) = doc.clip(key) {
        return Ok(c);
    }
    let names: Vec<&str> = doc.clips.iter().map(|c| c.name.as_str()).collect();
    let i: usize = key
        .parse()
        .map_err(|_| anyhow!("no clip named `{key}` (clips: {names:?})"))?;
    doc.clips
        .get(i)
        .ok_or_else(|| anyhow!("clip index {i} out of range ({} clips)", doc.clips.len()))
}

/// For `model`, the skin it drives (the first whose joints name every model joint, with the
/// same hierarchy and bind pose), the map from the skin's joint order to the model's, and the
/// transform from the skin's bind space to the model's canonical space, as an engine does.
fn match_model(
    doc: &GltfDocument,
    model: &SkinNetModel,
) -> anyhow::Result<(usize, JointMap, BindSpace)> {
    let mut reasons = Vec::new();
    for (s, skin) in doc.skins.iter().enumerate() {
        let names = skin.skeleton.names();
        let matched = JointMap::new(model.skeleton(), names).and_then(|map| {
            map.check_parents(model.skeleton(), names, skin.skeleton.parents())?;
            let space = map.bind_space(
                model.skeleton(),
                skin.skeleton.inverse_bind(),
                BIND_TOLERANCE,
            )?;
            Ok((map, space))
        });
        match matched {
            Ok((map, space)) => return Ok((s, map, space)),
            Err(e) => reasons.push(format!("skin {s}: {e}")),
        }
    }
    bail!(
        "--model: its skeleton ({} joints) matches no skin of the asset by joint names ({})",
        model.joint_count(),
        reasons.join("; ")
    )
}

/// Skinned positions of every skinned primitive at each of `times`.
pub fn pose_frames(
    doc: &GltfDocument,
    clip: &Clip,
    times: &[f32],
    model: Option<&SkinNetModel>,
    method: Method,
) -> anyhow::Result<Vec<Frame>> {
    if let Some(t) = times.iter().find(|t| !t.is_finite()) {
        bail!("--times: {t} is not a finite time");
    }
    if doc.skins.is_empty() {
        bail!("{}: the asset has no skin", doc.source.display());
    }
    // File order: (mesh, primitive), each with the skin that deforms it.
    let mut order: Vec<(usize, &PrimitiveInfo)> = doc
        .skins
        .iter()
        .enumerate()
        .flat_map(|(s, skin)| skin.primitives.iter().map(move |p| (s, p)))
        .collect();
    order.sort_by_key(|&(s, p)| (p.mesh, p.primitive, s));
    let driven = model.map(|m| match_model(doc, m)).transpose()?;
    let bound = match (model, &driven) {
        (Some(m), Some((s, _, space))) => {
            let positions = space.positions(&doc.skins[*s].template.positions);
            Some(BoundMesh::bind(m, &positions)?)
        }
        _ => None,
    };
    let mut frames = Vec::with_capacity(times.len());
    for &t in times {
        let mut skinned: HashMap<usize, Vec<Vec3>> = HashMap::new();
        for (s, skin) in doc.skins.iter().enumerate() {
            let pose = clip.sample(skin, t);
            let out = match (model, &driven, &bound) {
                (Some(m), Some((ms, map, _)), Some(mesh)) if *ms == s => {
                    skin_with_model(m, map, mesh, &pose, method)?
                }
                _ => pose_static(
                    &skin.skeleton,
                    &skin.skin,
                    &skin.template.positions,
                    &pose,
                    method.into(),
                )?,
            };
            skinned.insert(s, out);
        }
        let mut positions = Vec::new();
        for &(s, p) in &order {
            let range = p.first_vertex..p.first_vertex + p.vertex_count;
            positions.extend(skinned[&s][range].iter().map(|p| p.to_array()));
        }
        frames.push(Frame { time: t, positions });
    }
    Ok(frames)
}

fn skin_with_model(
    model: &SkinNetModel,
    map: &JointMap,
    mesh: &BoundMesh,
    pose: &Pose,
    method: Method,
) -> anyhow::Result<Vec<Vec3>> {
    let mut frame = FrameState::new(model);
    frame.set_engine_pose(model, map, &pose.locals)?;
    Ok(skin_frame(model, mesh, &frame, method)?)
}
