//! `trainer synth --character FILE`: a capture of any rigged glTF character.
//!
//! The template, skeleton and artist weights are every mesh that moves with the file's largest
//! skin (other skins over the same joints and rigid mesh nodes below its joints merged, in the
//! rest scene's space: [`super::gltf_character`]); the artist weights are the ground truth's
//! static part. Motion comes from named clips of the same file
//! or of another glTF whose joints are matched by name (`--motion`), or retargeted from another
//! rig through a joint map (`--joint-map`, [`super::joint_map`]). The ground-truth deformer
//! is dual-quaternion skinning with the artist weights plus the flexion bulge at joints whose
//! names mark an elbow or a knee ([`is_bulge_joint`]); rigid parts (mesh nodes that follow a
//! joint, such as a robot's limbs) move rigidly and never bulge. glTF files carry no skin /
//! clothing labels, so there is no skirt push-out for them (the built-in character has one).
//! Characters without vertex colours get a procedural pattern (a colour per primitive,
//! modulated by stripes and value noise) so the images carry gradients. The cameras frame the
//! ground truth's bounding box over every frame ([`Framing::around`]), whatever the
//! character's size, unit or proportions.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use skinfield_formats::gltf_io::{GltfDocument, load_gltf};
use skinfield_formats::makehuman::{MakeHumanOptions, load_makehuman_dir};
use skinfield_formats::mesh::area_weighted_normals;
use skinfield_formats::{Aabb, Pose};

use super::body::Part;
use super::clips::Motion;
use super::deform::GroundTruthDeformer;
use super::gltf_character::{CharacterPart, GltfCharacter, PartSource, assemble};
use super::joint_map::JointMap;
use super::motion::Split;
use super::output::{Subject, SynthSummary, write_subject};
use super::rig::{Framing, camera_rig_framed};
use super::texture::value_noise;
use super::{SynthConfig, SynthError, TestMotions};

/// Where a glTF capture's character and motion come from.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfSource {
    /// The rigged character: a glTF/GLB file, or a MakeHuman folder (`base.obj`,
    /// `default.mhskel`, `default_weights.mhw`), which has no clips of its own.
    pub character: PathBuf,
    /// Another glTF with the clips (joints matched by name, or retargeted through
    /// `joint_map`), or BVH motion (a `.bvh` file or a folder of them, one clip per file named
    /// by its stem; always through `joint_map`); `None`: the character's own.
    pub motion: Option<PathBuf>,
    /// Which joint of the motion's skeleton drives which joint of the character's, for a
    /// motion authored on another rig: its poses are retargeted
    /// ([`skinfield_formats::Retarget`]: bone directions, with the two rest poses, facings and
    /// sizes reconciled) instead of copied by name. Only with `motion`.
    pub joint_map: Option<JointMap>,
    /// Play the retargeted motion in place: the hips keep their height changes but not their
    /// travel across the floor, so the cameras frame the character rather than its path
    /// (`Retarget::in_place`). Only with `joint_map`.
    pub in_place: bool,
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
/// middles of equal time slices of each clip. With [`TestMotions::HeldOutPhases`] the test
/// frames are the training clips halfway between their training frames instead (as for the
/// built-in character; no test clips may be named then).
///
/// The template is every mesh that moves with the largest skin's skeleton, in the rest scene's
/// space ([`super::gltf_character`]); the cameras frame the bounding box of the ground truth
/// over every frame ([`Framing::around`]).
pub fn synthesize_gltf(
    dir: &Path,
    config: &SynthConfig,
    source: &GltfSource,
) -> Result<SynthSummary, SynthError> {
    config.validate()?;
    let start = Instant::now();
    let held_out = config.test_motions == TestMotions::HeldOutPhases;
    if held_out && !source.test_clips.is_empty() {
        return Err(SynthError::Config {
            field: "test_clips",
            reason: "held-out phases test on the training clips between their training frames; \
                     name no test clips with them"
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
    let (doc, character) = if source.character.is_dir() {
        (None, makehuman_character(&source.character)?)
    } else {
        let doc = load(&source.character)?;
        let character = assemble(&doc)?;
        (Some(doc), character)
    };
    let own = match &doc {
        Some(d) => Some((
            d,
            d.largest_skin().ok_or_else(|| SynthError::Config {
                field: "character",
                reason: format!("{} has no skin", source.character.display()),
            })?,
        )),
        None => None,
    };
    // Poses are expressed on the file's skin for a glTF character (the same joints as the
    // canonical skeleton), on the character's own skeleton otherwise.
    let pose_skeleton = own.map_or(&character.skeleton, |(_, skin)| &skin.skeleton);
    let wanted: Vec<String> = source
        .train_clips
        .iter()
        .chain(&source.test_clips)
        .cloned()
        .collect();
    let motion = Motion::open(
        source.motion.as_deref(),
        source.joint_map.as_ref(),
        pose_skeleton,
        &wanted,
        source.in_place,
    )?;
    if own.is_none() && matches!(motion, Motion::Own | Motion::GltfByName(_)) {
        return Err(SynthError::Config {
            field: "motion",
            reason: format!(
                "{} has no clips and no joint names in common with a motion file: give a \
                 motion (glTF or BVH) and a joint map",
                source.character.display()
            ),
        });
    }
    let clip_named = |name: &str, field: &'static str| {
        motion.clip(name, own).ok_or_else(|| SynthError::Config {
            field,
            reason: format!(
                "no clip `{name}` in {}; it has: {}",
                motion.describe(doc.as_ref()),
                motion.names(doc.as_ref()).join(", ")
            ),
        })
    };
    // Training phase i of n sits at (i + ½)/n of the clip; a held-out phase at (k + 1)/T, midway
    // between training phases k and k + 1 (distinct while test ≤ train frames, which the
    // config checks), as in the built-in motion library.
    let (n_train, n_test) = (config.train_frames_per_clip, config.test_frames_per_clip);
    let mut frames = Vec::new();
    for name in &source.train_clips {
        let clip = clip_named(name, "train_clips")?;
        for i in 0..n_train {
            let t = clip.duration_s * (i as f32 + 0.5) / n_train as f32;
            frames.push((name.clone(), Split::Train, clip.pose(t)?));
        }
    }
    if held_out {
        for name in &source.train_clips {
            let clip = clip_named(name, "train_clips")?;
            for i in 0..n_test {
                let phase = (i * n_train / n_test + 1) as f32 / n_train as f32;
                let t = clip.duration_s * phase;
                frames.push((format!("{name}_heldout"), Split::Test, clip.pose(t)?));
            }
        }
    } else {
        for name in &source.test_clips {
            let clip = clip_named(name, "test_clips")?;
            for i in 0..n_test {
                let t = clip.duration_s * (i as f32 + 0.5) / n_test as f32;
                frames.push((name.clone(), Split::Test, clip.pose(t)?));
            }
        }
    }

    let mut template = character.template.clone();
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
        for (k, part) in character.parts.iter().enumerate() {
            let base = PALETTE[part.material.unwrap_or(k) % PALETTE.len()];
            let end = (part.first_vertex + part.vertex_count).min(colors.len());
            let start = part.first_vertex.min(end);
            for (colour, &position) in colors[start..end]
                .iter_mut()
                .zip(&template.positions[start..end])
            {
                let p = (position - bounds.min) / height;
                let stripe = 0.85 + 0.15 * (std::f32::consts::TAU * p.y * 14.0).sin();
                let noise = 0.8 + 0.4 * value_noise(p, 0.03, config.seed);
                *colour = (base * stripe * noise).clamp(Vec3::ZERO, Vec3::ONE);
            }
        }
        template.colors = Some(colors);
    }
    let skeleton = character.skeleton.clone();
    let bulge: Vec<usize> = (0..skeleton.len())
        .filter(|&j| is_bulge_joint(&skeleton.names()[j]))
        .collect();
    let deformer = GroundTruthDeformer::new(
        skeleton.clone(),
        character.skin.clone(),
        template.positions.clone(),
        template.normals.clone(),
        template.triangles.clone(),
        vec![Part::Torso; template.vertex_count()],
    )
    .with_rig(bulge, Vec::new())
    .with_bulge_scale(height / 1.75)
    .with_rigid_vertices(rigid_vertices(&character));
    let framed = motion_bounds(&deformer, &frames)?.unwrap_or(bounds);
    let character_seconds = start.elapsed().as_secs_f64();
    let subject = Subject {
        template: &template,
        skeleton: &skeleton,
        deformer: &deformer,
        frames,
        rig: camera_rig_framed(
            config.cameras,
            config.width,
            config.height,
            config.seed,
            &Framing::around(
                &framed,
                config.cameras,
                config.width,
                config.height,
                config.seed,
            ),
        ),
        character: source
            .character
            .file_name()
            .map_or_else(String::new, |f| f.to_string_lossy().into_owned()),
        deformer_description:
            "dual-quaternion skinning with the artist weights (rigid parts: weight 1 on their \
             joint) + flexion bulge at joints named like elbows and knees, except on rigid \
             parts (trainer::synth::gltf_source); no skirt push-out"
                .into(),
    };
    write_subject(dir, config, &subject, start, character_seconds)
}

/// A MakeHuman character (a folder with `base.obj`, `default.mhskel` and
/// `default_weights.mhw`; the body group, in metres) as one skinned part.
fn makehuman_character(dir: &Path) -> Result<GltfCharacter, SynthError> {
    let asset =
        load_makehuman_dir(dir, &MakeHumanOptions::default()).map_err(|e| SynthError::Config {
            field: "character",
            reason: e.to_string(),
        })?;
    let vertex_count = asset.template.vertex_count();
    Ok(GltfCharacter {
        skeleton: asset.skeleton,
        template: asset.template,
        skin: asset.skin,
        parts: vec![CharacterPart {
            source: PartSource::Skinned {
                skin: 0,
                mesh: 0,
                primitive: 0,
            },
            name: "body".into(),
            material: None,
            first_vertex: 0,
            vertex_count,
        }],
        rest_transform: glam::Mat4::IDENTITY,
        left_out: Vec::new(),
    })
}

/// One flag per template vertex: whether it belongs to a rigid part (a mesh node that follows
/// one joint), which the ground truth moves rigidly, without the flexion bulge.
fn rigid_vertices(character: &GltfCharacter) -> Vec<bool> {
    let mut rigid = vec![false; character.template.vertex_count()];
    for part in &character.parts {
        if matches!(part.source, PartSource::Rigid { .. }) {
            let end = (part.first_vertex + part.vertex_count).min(rigid.len());
            let start = part.first_vertex.min(end);
            rigid[start..end].fill(true);
        }
    }
    rigid
}

/// The bounding box of the ground truth over every frame (`None` without frames).
pub fn motion_bounds(
    deformer: &GroundTruthDeformer,
    frames: &[(String, Split, Pose)],
) -> Result<Option<Aabb>, SynthError> {
    let boxes = frames
        .par_iter()
        .map(|(_, _, pose)| -> Result<Option<Aabb>, SynthError> {
            let (positions, _) = deformer.deform(pose)?;
            Ok(Aabb::from_points(&positions))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut out: Option<Aabb> = None;
    for b in boxes.into_iter().flatten() {
        out = Some(match out {
            None => b,
            Some(o) => Aabb {
                min: o.min.min(b.min),
                max: o.max.max(b.max),
            },
        });
    }
    Ok(out)
}
