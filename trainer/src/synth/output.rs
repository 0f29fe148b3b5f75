//! Writing a synthetic capture: pose every frame with the ground-truth deformer, render every
//! camera (Lambert + specular, shadows from a directional light), and write images, masks,
//! motion, template, part-label images, the evaluation-only ground truth and finally the
//! manifest. After the clips comes one more frame, the canonical frame: the bind pose, from
//! which `trainer template` reconstructs a template (neither a training nor a test frame).

use std::path::Path;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use skinfield_formats::capture::{
    CAPTURE_FORMAT, CAPTURE_VERSION, CameraEntry, CaptureManifest, CaptureWriter, ClipEntry,
    EvaluationEntry, LabelsEntry, SourceEntry,
};
use skinfield_formats::{Camera, CameraRig, Pose, Skeleton, Template};

use super::deform::GroundTruthDeformer;
use super::labels::{PART_PALETTE, render_labels, with_boundary_noise};
use super::motion::{CLIPS, Split, library};
use super::rig::camera_rig;
use super::{SynthConfig, SynthError, build_character};
use crate::raster::{Light, ShadowMap, coverage, rasterize, shade};

/// Frames per second recorded in the motion file.
pub const FPS: f32 = 30.0;
/// Background colour of the images (linear RGB).
pub const BACKGROUND: Vec3 = Vec3::new(0.02, 0.025, 0.035);

/// What `synthesize` made.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthSummary {
    /// Template vertex count.
    pub vertices: usize,
    /// Template triangle count.
    pub triangles: usize,
    /// Joint count.
    pub joints: usize,
    /// Training frames.
    pub train_frames: usize,
    /// Test frames.
    pub test_frames: usize,
    /// Cameras.
    pub cameras: usize,
    /// Seconds spent building the character (meshing, simplification, weights).
    pub character_seconds: f64,
    /// Seconds in total.
    pub total_seconds: f64,
}

/// Sub-pixel samples per axis of a capture's masks: 4 × 4 gives coverage in steps of 1/16, which
/// places the outline to about 0.06 px (the silhouette loss works at sub-pixel scale, see
/// `losses::silhouette`).
pub const MASK_SAMPLES: u32 = 4;

/// Renders one view of a posed mesh: shaded linear RGB (one sample per pixel) and the mask's
/// coverage ([`MASK_SAMPLES`]² samples per pixel).
#[allow(clippy::too_many_arguments)]
#[must_use]
pub fn render_view(
    camera: &Camera,
    template: &Template,
    positions: &[Vec3],
    normals: &[Vec3],
    light: &Light,
    shadow: &ShadowMap,
) -> (Vec<Vec3>, Vec<f32>) {
    let frags = rasterize(camera, positions, &template.triangles);
    let rgb = shade(
        camera,
        &frags,
        positions,
        normals,
        template.colors.as_deref(),
        &template.triangles,
        light,
        Some(shadow),
        BACKGROUND,
    );
    (
        rgb,
        coverage(camera, positions, &template.triangles, MASK_SAMPLES),
    )
}

/// What gets filmed: a template, its skeleton, its ground-truth deformer and the motion.
pub struct Subject<'a> {
    /// The template (bind pose).
    pub template: &'a Template,
    /// The skeleton.
    pub skeleton: &'a Skeleton,
    /// The ground-truth deformer.
    pub deformer: &'a GroundTruthDeformer,
    /// Per frame: clip name, split, pose.
    pub frames: Vec<(String, Split, Pose)>,
    /// The cameras.
    pub rig: CameraRig,
    /// Where the character comes from (`procedural` or a file name), for the manifest.
    pub character: String,
    /// What the ground-truth deformer does, for the manifest.
    pub deformer_description: String,
}

/// Makes the built-in synthetic capture in `dir` (see [`skinfield_formats::capture`] for the
/// layout). Same configuration and seed, same bytes.
pub fn synthesize(dir: &Path, config: &SynthConfig) -> Result<SynthSummary, SynthError> {
    config.validate()?;
    let start = Instant::now();
    let character = build_character(config)?;
    let character_seconds = start.elapsed().as_secs_f64();
    let frames = library(
        &character.skeleton,
        config.train_frames_per_clip,
        config.test_frames_per_clip,
        config.test_motions,
        config.seed,
    )?
    .into_iter()
    .map(|f| {
        let name = CLIPS[f.clip].0;
        // A training clip's held-out phases get their own clip entry in the manifest.
        let name = if f.split == CLIPS[f.clip].1 {
            name.to_string()
        } else {
            format!("{name}_heldout")
        };
        (name, f.split, f.pose)
    })
    .collect();
    let subject = Subject {
        template: &character.template,
        skeleton: &character.skeleton,
        deformer: &character.deformer,
        frames,
        rig: camera_rig(config.cameras, config.width, config.height, config.seed),
        character: "procedural".into(),
        deformer_description:
            "dual-quaternion skinning with the true weights + flexion bulge at elbows and knees + \
                               skirt pushed out of the leg capsules (trainer::synth::deform)"
                .into(),
    };
    write_subject(dir, config, &subject, start, character_seconds)
}

/// Renders and writes a subject as a capture in `dir`.
pub fn write_subject(
    dir: &Path,
    config: &SynthConfig,
    subject: &Subject<'_>,
    start: Instant,
    character_seconds: f64,
) -> Result<SynthSummary, SynthError> {
    let light = Light::default();
    let rig = &subject.rig;
    let mut clips = Vec::new();
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (f, (name, split, _)) in subject.frames.iter().enumerate() {
        match clips.last_mut() {
            Some(ClipEntry { name: n, count, .. }) if n == name => *count += 1,
            _ => clips.push(ClipEntry {
                name: name.clone(),
                first: f,
                count: 1,
                split: if *split == Split::Train {
                    "train"
                } else {
                    "test"
                }
                .into(),
            }),
        }
        if *split == Split::Train {
            train.push(f)
        } else {
            test.push(f)
        }
    }
    // The canonical frame: the bind pose, after the clips, as a capture starts with the actor
    // in a calibration pose; `trainer template` reconstructs the template from it.
    let canonical = subject.frames.len();
    clips.push(ClipEntry {
        name: "canonical".into(),
        first: canonical,
        count: 1,
        split: "canonical".into(),
    });
    let bind_pose = subject.skeleton.bind_pose();
    let frame_poses: Vec<&Pose> = subject
        .frames
        .iter()
        .map(|f| &f.2)
        .chain([&bind_pose])
        .collect();
    let parts = subject.template.part_labels.as_deref();
    let manifest = CaptureManifest {
        format: CAPTURE_FORMAT.into(),
        version: CAPTURE_VERSION,
        up_axis: "y".into(),
        cameras: rig.cameras.iter().map(CameraEntry::from_camera).collect(),
        template: "template.json".into(),
        motion: Some("motion.json".into()),
        initial_weights: None,
        frame_count: frame_poses.len(),
        clips,
        train_frames: train.clone(),
        test_frames: test.clone(),
        images: "images".into(),
        masks: "masks".into(),
        image_format: config.image_format,
        keypoints: None,
        labels: parts.map(|_| LabelsEntry {
            folder: "labels".into(),
            palette: PART_PALETTE.to_vec(),
            frames: (0..frame_poses.len()).collect(),
        }),
        canonical_frame: Some(canonical),
        evaluation: Some(EvaluationEntry {
            gt_meshes: "eval/gt".into(),
            true_weights: Some("eval/true_weights.json".into()),
            deformer: subject.deformer_description.clone(),
        }),
        source: Some(SourceEntry {
            generator: format!("trainer synth {}", env!("CARGO_PKG_VERSION")),
            character: subject.character.clone(),
            seed: config.seed,
            light_direction: light.direction.to_array(),
        }),
    };
    let writer = CaptureWriter::new(dir, manifest)?;
    writer.write_template(subject.template, subject.skeleton)?;
    writer.write_motion(
        &frame_poses.iter().map(|&p| p.clone()).collect::<Vec<_>>(),
        FPS,
    )?;
    writer.write_true_weights(subject.deformer.skin())?;

    frame_poses
        .par_iter()
        .enumerate()
        .try_for_each(|(f, &pose)| -> Result<(), SynthError> {
            let (positions, normals) = subject.deformer.deform(pose)?;
            let shadow = ShadowMap::build(
                light.direction,
                &positions,
                &subject.template.triangles,
                config.shadow_map,
            );
            for (c, camera) in rig.cameras.iter().enumerate() {
                let (rgb, mask) = render_view(
                    camera,
                    subject.template,
                    &positions,
                    &normals,
                    &light,
                    &shadow,
                );
                writer.write_image(c, f, &rgb)?;
                let (w, h) = (camera.width as usize, camera.height as usize);
                let mask = super::mask_error::offset_coverage(&mask, w, h, config.mask_offset_px);
                writer.write_mask(c, f, &mask)?;
                if let Some(parts) = parts {
                    let labels =
                        render_labels(camera, &positions, &subject.template.triangles, parts);
                    let seed = config.seed ^ ((f as u64) << 32 | c as u64);
                    let labels = with_boundary_noise(&labels, w, h, config.label_noise, seed);
                    writer.write_labels(c, f, &labels)?;
                }
            }
            // Every frame's ground truth (evaluation only: the bounds fit the training frames').
            writer.write_gt_mesh(f, &positions)?;
            Ok(())
        })?;
    writer.finish()?;
    Ok(SynthSummary {
        vertices: subject.template.vertex_count(),
        triangles: subject.template.triangles.len(),
        joints: subject.skeleton.len(),
        train_frames: train.len(),
        test_frames: test.len(),
        cameras: rig.cameras.len(),
        character_seconds,
        total_seconds: start.elapsed().as_secs_f64(),
    })
}
