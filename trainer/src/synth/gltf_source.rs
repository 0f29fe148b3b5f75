//! `trainer synth --character FILE`: a capture of any rigged glTF character.
//!
//! The template, skeleton and artist weights come from the file's largest skin; the artist
//! weights are the ground truth's static part. Motion comes from named clips of the same file
//! or of another glTF whose joints are matched by name (`--motion`). The ground-truth deformer
//! is dual-quaternion skinning with the artist weights plus the flexion bulge at joints whose
//! names mark an elbow or a knee ([`is_bulge_joint`]). glTF files carry no skin / clothing
//! labels, so there is no skirt push-out for them (the built-in character has one).
//! Characters without vertex colours get a procedural pattern (a colour per primitive,
//! modulated by stripes and value noise) so the images carry gradients.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use skinfield_formats::gltf_io::{GltfDocument, load_gltf};
use skinfield_formats::mesh::area_weighted_normals;

use super::body::Part;
use super::deform::GroundTruthDeformer;
use super::motion::Split;
use super::output::{Subject, SynthSummary, write_subject};
use super::rig::camera_rig_around;
use super::texture::value_noise;
use super::{SynthConfig, SynthError};

/// Where a glTF capture's character and motion come from.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfSource {
    /// The rigged character.
    pub character: PathBuf,
    /// Another glTF with the clips (joints matched by name); `None`: the character's own.
    pub motion: Option<PathBuf>,
    /// Clip names for training.
    pub train_clips: Vec<String>,
    /// Clip names for testing (disjoint from the training clips).
    pub test_clips: Vec<String>,
}

/// Whether a joint name marks an elbow or a knee (the joint whose rotation bends the forearm
/// or the shin): it contains, ignoring case, one of `elbow`, `knee`, `lowerarm`, `forearm`,
/// `lowerleg`, `calf`, `shin`.
#[must_use]
pub fn is_bulge_joint(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    [
        "elbow", "knee", "lowerarm", "forearm", "lowerleg", "calf", "shin",
    ]
    .iter()
    .any(|k| n.contains(k))
}

const PALETTE: [Vec3; 8] = [
    Vec3::new(0.62, 0.38, 0.27),
    Vec3::new(0.35, 0.12, 0.45),
    Vec3::new(0.80, 0.62, 0.12),
    Vec3::new(0.20, 0.30, 0.55),
    Vec3::new(0.45, 0.25, 0.10),
    Vec3::new(0.10, 0.45, 0.30),
    Vec3::new(0.70, 0.15, 0.15),
    Vec3::new(0.55, 0.55, 0.50),
];

fn load(path: &Path) -> Result<GltfDocument, SynthError> {
    Ok(load_gltf(path)?)
}

/// Makes a capture of a glTF character in `dir`: `config.train_frames_per_clip` frames of
/// every training clip and `config.test_frames_per_clip` of every test clip, sampled at the
/// middles of equal time slices of each clip.
pub fn synthesize_gltf(
    dir: &Path,
    config: &SynthConfig,
    source: &GltfSource,
) -> Result<SynthSummary, SynthError> {
    config.validate()?;
    let start = Instant::now();
    if config.test_motions != super::TestMotions::Novel {
        return Err(SynthError::Config {
            field: "test_motions",
            reason: "held-out phases are for the built-in character; name test clips instead"
                .into(),
        });
    }
    if source.train_clips.is_empty() {
        return Err(SynthError::Config {
            field: "train_clips",
            reason: "name at least one clip".into(),
        });
    }
    if let Some(c) = source
        .test_clips
        .iter()
        .find(|c| source.train_clips.contains(c))
    {
        return Err(SynthError::Config {
            field: "test_clips",
            reason: format!("`{c}` is also a training clip"),
        });
    }
    let doc = load(&source.character)?;
    let skin = doc.largest_skin().ok_or_else(|| SynthError::Config {
        field: "character",
        reason: format!("{} has no skin", source.character.display()),
    })?;
    let motion_doc = match &source.motion {
        Some(p) => Some(load(p)?),
        None => None,
    };
    let clips_doc = motion_doc.as_ref().unwrap_or(&doc);
    let mut frames = Vec::new();
    for (names, split, n) in [
        (
            &source.train_clips,
            Split::Train,
            config.train_frames_per_clip,
        ),
        (&source.test_clips, Split::Test, config.test_frames_per_clip),
    ] {
        for name in names {
            let clip = clips_doc.clip(name).ok_or_else(|| SynthError::Config {
                field: if split == Split::Train {
                    "train_clips"
                } else {
                    "test_clips"
                },
                reason: format!(
                    "no clip `{name}` in {}; it has: {}",
                    clips_doc.source.display(),
                    clips_doc
                        .clips
                        .iter()
                        .map(|c| c.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })?;
            for i in 0..n {
                let t = clip.duration_s * (i as f32 + 0.5) / n as f32;
                let pose = match motion_doc {
                    None => clip.sample(skin, t),
                    Some(_) => clip.sample_by_name(&skin.skeleton, &skin.default_pose(), t),
                };
                frames.push((name.clone(), split, pose));
            }
        }
    }

    let mut template = skin.template.clone();
    if template.normals.len() != template.positions.len()
        || template
            .normals
            .iter()
            .any(|n| !n.is_finite() || n.length() < 0.5)
    {
        template.normals = area_weighted_normals(&template.positions, &template.triangles);
    }
    for n in &mut template.normals {
        *n = n.try_normalize().unwrap_or(Vec3::Y);
    }
    let bounds = template.bounds().ok_or_else(|| SynthError::Config {
        field: "character",
        reason: "empty or non-finite mesh".into(),
    })?;
    let height = bounds.size().y.max(1e-3);
    if template.colors.is_none() {
        let mut colors = vec![Vec3::splat(0.7); template.vertex_count()];
        for (k, prim) in skin.primitives.iter().enumerate() {
            let base = PALETTE[prim.material.unwrap_or(k) % PALETTE.len()];
            for v in prim.first_vertex..(prim.first_vertex + prim.vertex_count).min(colors.len()) {
                let p = (template.positions[v] - bounds.min) / height;
                let stripe = 0.85 + 0.15 * (std::f32::consts::TAU * p.y * 14.0).sin();
                let noise = 0.8 + 0.4 * value_noise(p, 0.03, config.seed);
                colors[v] = (base * stripe * noise).clamp(Vec3::ZERO, Vec3::ONE);
            }
        }
        template.colors = Some(colors);
    }
    let skeleton = skin.skeleton.clone();
    let bulge: Vec<usize> = (0..skeleton.len())
        .filter(|&j| is_bulge_joint(&skeleton.names()[j]))
        .collect();
    let deformer = GroundTruthDeformer::new(
        skeleton.clone(),
        skin.skin.clone(),
        template.positions.clone(),
        template.normals.clone(),
        template.triangles.clone(),
        vec![Part::Torso; template.vertex_count()],
    )
    .with_rig(bulge, Vec::new())
    .with_bulge_scale(height / 1.75);
    let character_seconds = start.elapsed().as_secs_f64();
    let subject = Subject {
        template: &template,
        skeleton: &skeleton,
        deformer: &deformer,
        frames,
        rig: camera_rig_around(
            config.cameras,
            config.width,
            config.height,
            config.seed,
            bounds.center(),
            height,
        ),
        character: source
            .character
            .file_name()
            .map_or_else(String::new, |f| f.to_string_lossy().into_owned()),
        deformer_description:
            "dual-quaternion skinning with the artist weights + flexion bulge at joints named like \
                               elbows and knees (trainer::synth::gltf_source); no skirt push-out"
                .into(),
    };
    write_subject(dir, config, &subject, start, character_seconds)
}
