//! `trainer inspect FILE`: one JSON object on stdout describing a character or model file.
//!
//! Each file kind is one [`Kind`] variant and one match arm in [`run`]; every kind fills the
//! same [`Report`] (counts that do not apply are 0 and `clips` is empty) and may add its own
//! fields in `extra`.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use serde::Serialize;
use skinfield_formats::bvh::load_bvh;
use skinfield_formats::capture::load_capture;
use skinfield_formats::gltf_io::load_gltf;
use skinfield_formats::skf::{SkfView, read_skf_file};

/// Arguments of `trainer inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The file to describe (.gltf, .glb, .skf, .bvh, or a capture folder).
    pub file: PathBuf,
}

/// One clip (animation) of the file.
#[derive(Serialize, Debug)]
pub struct ClipReport {
    /// Clip name.
    pub name: String,
    /// Length in seconds (time of the last key).
    pub duration_s: f32,
    /// Distinct key times (glTF) or frames (BVH).
    pub frames: usize,
}

/// What `inspect` prints.
#[derive(Serialize, Debug)]
pub struct Report {
    /// `gltf`, `glb`, `skf`, `bvh` or `capture`.
    pub kind: &'static str,
    /// Vertices over every primitive as stored (unwelded).
    pub vertices: usize,
    /// Triangles over every primitive as stored.
    pub triangles: usize,
    /// Joints of the largest skin (or the skeleton of a model file).
    pub joints: usize,
    /// Number of skins.
    pub skins: usize,
    /// Most influences on any vertex over all skins.
    pub max_influences: usize,
    /// Vertices whose file weights did not sum to one (normalised on import).
    pub unnormalized_weights: usize,
    /// Clips in file order.
    pub clips: Vec<ClipReport>,
    /// Fields particular to the kind.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

/// The file kinds `inspect` knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// glTF JSON.
    Gltf,
    /// Binary glTF.
    Glb,
    /// Skinfield weight file.
    Skf,
    /// BVH motion capture.
    Bvh,
    /// Capture folder (`manifest.json` inside).
    Capture,
}

impl Kind {
    /// The kind of `path`, from its extension.
    pub fn of(path: &Path) -> anyhow::Result<Self> {
        if path.is_dir() {
            return Ok(Self::Capture);
        }
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("gltf") => Ok(Self::Gltf),
            Some("glb") => Ok(Self::Glb),
            Some("skf") => Ok(Self::Skf),
            Some("bvh") => Ok(Self::Bvh),
            _ => Err(anyhow!(
                "{}: unknown file kind (expected .gltf, .glb, .skf, .bvh or a capture folder)",
                path.display()
            )),
        }
    }
}

fn inspect_gltf(path: &Path, kind: Kind) -> anyhow::Result<Report> {
    // GltfError names the file and field; keep the message on one line.
    let doc = load_gltf(path).map_err(|e| anyhow!(e.to_string().replace('\n', "; ")))?;
    let mut extra = serde_json::Map::new();
    extra.insert("primitives".into(), doc.primitive_count.into());
    extra.insert(
        "skin_joints".into(),
        doc.skins
            .iter()
            .map(|s| s.skin_joint_count())
            .collect::<Vec<_>>()
            .into(),
    );
    extra.insert(
        "skinned_vertices".into(),
        doc.skins
            .iter()
            .map(|s| s.template.vertex_count())
            .sum::<usize>()
            .into(),
    );
    Ok(Report {
        kind: if kind == Kind::Glb { "glb" } else { "gltf" },
        vertices: doc.vertex_count,
        triangles: doc.triangle_count,
        joints: doc.largest_skin().map_or(0, |s| s.skin_joint_count()),
        skins: doc.skins.len(),
        max_influences: doc
            .skins
            .iter()
            .map(|s| s.skin.max_influences())
            .max()
            .unwrap_or(0),
        unnormalized_weights: doc.skins.iter().map(|s| s.skin.unnormalized_count()).sum(),
        clips: doc
            .clips
            .iter()
            .map(|c| ClipReport {
                name: c.name.clone(),
                duration_s: c.duration_s,
                frames: c.frames,
            })
            .collect(),
        extra,
    })
}

fn inspect_skf(path: &Path) -> anyhow::Result<Report> {
    let bytes = read_skf_file(path)?;
    let view = SkfView::parse(&bytes).with_context(|| path.display().to_string())?;
    let config = view.config();
    let mut extra = serde_json::Map::new();
    extra.insert("tensors".into(), view.tensor_count().into());
    extra.insert("pe_frequencies".into(), config.pe_frequencies.into());
    extra.insert("hidden".into(), config.hidden_widths().to_vec().into());
    extra.insert(
        "version".into(),
        format!(
            "{}.{}",
            skinfield_formats::skf::VERSION_MAJOR,
            view.minor_version()
        )
        .into(),
    );
    extra.insert(
        "candidate_anchors".into(),
        view.candidates().map_or(0, |c| c.len()).into(),
    );
    extra.insert("pose_range".into(), view.pose_range().is_some().into());
    Ok(Report {
        kind: "skf",
        vertices: 0,
        triangles: 0,
        joints: config.joint_count as usize,
        skins: 0,
        max_influences: 0,
        unnormalized_weights: 0,
        clips: Vec::new(),
        extra,
    })
}

fn inspect_bvh(path: &Path) -> anyhow::Result<Report> {
    let motion = load_bvh(path).map_err(|e| anyhow!(e.to_string().replace('\n', "; ")))?;
    let mut extra = serde_json::Map::new();
    extra.insert("end_sites".into(), motion.end_sites.len().into());
    extra.insert("channels".into(), motion.channel_count().into());
    extra.insert("frame_time_s".into(), motion.frame_time.into());
    let name = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    Ok(Report {
        kind: "bvh",
        vertices: 0,
        triangles: 0,
        joints: motion.skeleton.len(),
        skins: 0,
        max_influences: 0,
        unnormalized_weights: 0,
        clips: vec![ClipReport {
            name,
            duration_s: motion.duration_s(),
            frames: motion.frame_count(),
        }],
        extra,
    })
}

fn inspect_capture(dir: &Path) -> anyhow::Result<Report> {
    let capture = load_capture(dir).map_err(|e| anyhow!(e.to_string().replace('\n', "; ")))?;
    let mut extra = serde_json::Map::new();
    extra.insert("cameras".into(), capture.rig.cameras.len().into());
    extra.insert("train_frames".into(), capture.train_frames.len().into());
    extra.insert("test_frames".into(), capture.test_frames.len().into());
    let initial = capture.initial_weights.as_ref();
    Ok(Report {
        kind: "capture",
        vertices: capture.template.vertex_count(),
        triangles: capture.template.triangles.len(),
        joints: capture.skeleton.len(),
        skins: usize::from(initial.is_some()),
        max_influences: initial.map_or(0, |s| s.max_influences()),
        unnormalized_weights: initial.map_or(0, |s| s.unnormalized_count()),
        clips: Vec::new(),
        extra,
    })
}

/// Describes `args.file` as one JSON object on stdout.
pub fn run(args: Args) -> anyhow::Result<()> {
    let report = match Kind::of(&args.file)? {
        k @ (Kind::Gltf | Kind::Glb) => inspect_gltf(&args.file, k)?,
        Kind::Skf => inspect_skf(&args.file)?,
        Kind::Bvh => inspect_bvh(&args.file)?,
        Kind::Capture => inspect_capture(&args.file)?,
    };
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}
