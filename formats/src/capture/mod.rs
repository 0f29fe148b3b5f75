//! Multi-view captures on disk: the manifest, its validating loader and the writers.
//!
//! # Layout
//!
//! A capture is a folder:
//!
//! ```text
//! DIR/
//!   manifest.json                 CaptureManifest (below); every path in it is relative to DIR
//!   template.json                 TemplateFile: canonical mesh (positions, normals, triangles,
//!                                 optional colours / uvs / part labels) and the skeleton
//!                                 (names, parents, bind-pose local TRS, joint-angle DOFs, base)
//!   motion.json                   MotionFile: one Pose per frame (10 numbers per joint:
//!                                 translation xyz, rotation quaternion xyzw, scale xyz);
//!                                 optional: a capture with 2D keypoints may leave it to
//!                                 `trainer track`
//!   initial_weights.json          optional SkinFile (CSR static weights) the trainer may start from
//!   images/{camera}/{frame:05}.png  RGB, sRGB-encoded 8-bit (or .exr: linear float RGB)
//!   masks/{camera}/{frame:05}.png   8-bit grey, foreground > 127
//!   keypoints/…                   optional 2D detections in OpenPose JSON ([`keypoints`])
//!   labels/{camera}/{frame:05}.png  optional part labels, 8-bit RGB, one palette colour per part
//!                                 (manifest `labels`: folder, palette, frames)
//!   eval/true_weights.json        EVALUATION ONLY: the ground-truth deformer's static weights
//!   eval/gt/{frame:05}.bin        EVALUATION ONLY: ground-truth posed positions of a test frame
//!                                 (b"SFGTMESH", u32 LE version 1, u32 LE vertex count, then
//!                                 3 × f32 LE per vertex; triangles are the template's)
//! ```
//!
//! The manifest lists the cameras (OpenCV pinhole: resolution, `fx fy cx cy`, Brown–Conrady
//! distortion, world-to-camera rotation rows and translation), the named clips of the motion,
//! and the train and test frame indices (disjoint), and optionally the canonical frame a template
//! is reconstructed from (`canonical_frame`, which may be neither). [`load_capture`] reads the manifest, the
//! template, the skeleton, the motion and the initial weights eagerly and validates all of it
//! (sizes, indices, finiteness, that every image and mask file exists); images, masks and the
//! evaluation files are read lazily. Every error names the file and the field that is wrong.
//!
//! The trainer must never call [`Capture::evaluation_gt_mesh`] or
//! [`Capture::evaluation_true_weights`]: they exist for `trainer eval` alone.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::camera::CameraRig;
use crate::mesh::Template;
use crate::pose::{Pose, UpAxis};
use crate::skeleton::Skeleton;
use crate::skin::StaticSkin;

mod convert;
mod images;
pub mod keypoints;
mod labels;
mod load;
mod schema;
mod write;

pub use convert::{transform_from_array, transform_to_array};
pub use images::{
    CaptureImage, CaptureMask, GT_MESH_MAGIC, linear_to_srgb, mask_from_png, read_gt_positions,
    read_image, read_mask, srgb_to_linear, write_gt_positions, write_image_exr, write_image_png,
    write_mask_png,
};
pub use labels::{
    LabelImage, MAX_PARTS, NO_LABEL, labels_from_png, read_labels, validate_palette,
    write_labels_png,
};
pub use load::load_capture;
pub use schema::{
    CameraEntry, CaptureManifest, ClipEntry, DofsEntry, EvaluationEntry, ImageFormat, JointEntry,
    LabelsEntry, MotionFile, SkeletonEntry, SkinFile, SourceEntry, TemplateFile,
};
pub use write::{CaptureWriter, skeleton_to_entry, skin_to_file, template_to_file};

/// The manifest's file name inside a capture folder.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Value of [`CaptureManifest::format`].
pub const CAPTURE_FORMAT: &str = "skinfield-capture";
/// The manifest version this reader understands.
pub const CAPTURE_VERSION: u32 = 1;
/// Largest JSON file the loader reads (bytes).
pub const MAX_JSON_BYTES: u64 = 512 << 20;
/// Largest frame count a capture may declare.
pub const MAX_FRAMES: usize = 1 << 20;
/// Largest camera count a capture may declare.
pub const MAX_CAMERAS: usize = 1024;

/// Why a capture could not be read, naming the file and (where known) the field.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The file could not be read or written.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not valid JSON of the expected shape.
    #[error("{}: {source}", file.display())]
    Json {
        /// The file.
        file: PathBuf,
        /// serde_json's message (with line and column).
        source: serde_json::Error,
    },
    /// A field has a wrong value.
    #[error("{}: field `{field}`: {reason}", file.display())]
    Invalid {
        /// The file.
        file: PathBuf,
        /// The field (a JSON path such as `cameras[3].fx`).
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// An image or binary mesh file is malformed.
    #[error("{}: {reason}", file.display())]
    BadFile {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl CaptureError {
    pub(crate) fn invalid(
        file: &Path,
        field: impl Into<String>,
        reason: impl core::fmt::Display,
    ) -> Self {
        Self::Invalid {
            file: file.to_owned(),
            field: field.into(),
            reason: reason.to_string(),
        }
    }
}

/// A loaded, validated capture. Images and masks are read on demand.
#[derive(Clone, Debug)]
pub struct Capture {
    /// The capture folder.
    pub dir: PathBuf,
    /// The manifest as read.
    pub manifest: CaptureManifest,
    /// The calibrated cameras (manifest order).
    pub rig: CameraRig,
    /// The template mesh (with part labels and colours where the capture has them).
    pub template: Template,
    /// The skeleton with its joint-angle degrees of freedom.
    pub skeleton: Skeleton,
    /// The world's up axis.
    pub up_axis: UpAxis,
    /// Initial static weights shipped with the capture, if any.
    pub initial_weights: Option<StaticSkin>,
    /// One pose per frame; the bind pose throughout when the capture has no motion yet
    /// ([`Capture::require_motion`]).
    pub poses: Vec<Pose>,
    /// The motion file's frame rate (frames per second); `None` when the capture has no motion
    /// file yet. Kept so that tools that rewrite the motion (`trainer track`) keep it.
    pub motion_fps: Option<f32>,
    /// Training frame indices.
    pub train_frames: Vec<usize>,
    /// Test frame indices (disjoint from the training frames).
    pub test_frames: Vec<usize>,
}

impl Capture {
    /// Number of frames.
    #[must_use]
    pub fn frame_count(&self) -> usize {
        self.poses.len()
    }

    /// Path of the image of camera `cam` (index into the rig) at `frame`.
    #[must_use]
    pub fn image_path(&self, cam: usize, frame: usize) -> PathBuf {
        frame_file(
            &self.dir,
            &self.manifest.images,
            &self.rig.cameras[cam].name,
            frame,
            self.manifest.image_format,
        )
    }

    /// Path of the mask of camera `cam` at `frame` (always PNG).
    #[must_use]
    pub fn mask_path(&self, cam: usize, frame: usize) -> PathBuf {
        frame_file(
            &self.dir,
            &self.manifest.masks,
            &self.rig.cameras[cam].name,
            frame,
            ImageFormat::Png,
        )
    }

    fn check_index(&self, cam: usize, frame: usize) -> Result<(), CaptureError> {
        let file = self.dir.join(MANIFEST_FILE);
        if cam >= self.rig.cameras.len() {
            return Err(CaptureError::invalid(
                &file,
                "cameras",
                format!("camera index {cam} out of range"),
            ));
        }
        if frame >= self.poses.len() {
            return Err(CaptureError::invalid(
                &file,
                "frame_count",
                format!("frame {frame} out of range"),
            ));
        }
        Ok(())
    }

    /// Reads the image of camera `cam` at `frame` as linear RGB in [0, 1] (PNG is sRGB-decoded).
    pub fn load_image(&self, cam: usize, frame: usize) -> Result<CaptureImage, CaptureError> {
        self.check_index(cam, frame)?;
        let c = &self.rig.cameras[cam];
        images::read_image(&self.image_path(cam, frame), c.width, c.height)
    }

    /// Reads the foreground mask of camera `cam` at `frame`.
    pub fn load_mask(&self, cam: usize, frame: usize) -> Result<CaptureMask, CaptureError> {
        self.check_index(cam, frame)?;
        let c = &self.rig.cameras[cam];
        images::read_mask(&self.mask_path(cam, frame), c.width, c.height)
    }

    /// Whether the capture has its skeletal motion (the manifest names a motion file).
    #[must_use]
    pub fn has_motion(&self) -> bool {
        self.manifest.motion.is_some()
    }

    /// An error naming the manifest's `motion` field when the capture has no motion yet:
    /// everything that poses the skeleton (training, evaluation, rendering, template
    /// reconstruction) needs it; `trainer track` fits it to the capture's 2D keypoints.
    pub fn require_motion(&self) -> Result<(), CaptureError> {
        if self.has_motion() {
            return Ok(());
        }
        Err(CaptureError::invalid(
            &self.dir.join(MANIFEST_FILE),
            "motion",
            "the capture has no skeletal motion yet: fit it to the 2D keypoints with `trainer track`",
        ))
    }

    /// The frame a template is reconstructed from: the manifest's `canonical_frame`, else the
    /// first training frame.
    #[must_use]
    pub fn canonical_frame(&self) -> usize {
        self.manifest
            .canonical_frame
            .unwrap_or(self.train_frames[0])
    }

    /// Path of the part-label image of camera `cam` at `frame`, if the capture has labels.
    #[must_use]
    pub fn label_path(&self, cam: usize, frame: usize) -> Option<PathBuf> {
        let entry = self.manifest.labels.as_ref()?;
        Some(frame_file(
            &self.dir,
            &entry.folder,
            &self.rig.cameras[cam].name,
            frame,
            ImageFormat::Png,
        ))
    }

    /// Reads the part labels of camera `cam` at `frame`; `Ok(None)` when the capture has no
    /// labels, an error when it has them but not for this frame.
    pub fn load_labels(
        &self,
        cam: usize,
        frame: usize,
    ) -> Result<Option<LabelImage>, CaptureError> {
        self.check_index(cam, frame)?;
        let Some(entry) = &self.manifest.labels else {
            return Ok(None);
        };
        if !entry.frames.contains(&frame) {
            return Err(CaptureError::invalid(
                &self.dir.join(MANIFEST_FILE),
                "labels.frames",
                format!("frame {frame} has no label images"),
            ));
        }
        let c = &self.rig.cameras[cam];
        let path = self.label_path(cam, frame).unwrap_or_default();
        labels::read_labels(&path, c.width, c.height, entry).map(Some)
    }

    /// EVALUATION ONLY — the trainer must never call this. Ground-truth posed vertex positions
    /// of test frame `frame` (same vertex order and triangles as [`Capture::template`]); also of
    /// a training frame when the capture has its file (synthetic captures write every frame's,
    /// for the evaluation's bounds: the best static weights are fitted to the training frames).
    pub fn evaluation_gt_mesh(&self, frame: usize) -> Result<Vec<Vec3>, CaptureError> {
        let manifest_file = self.dir.join(MANIFEST_FILE);
        let eval = self.manifest.evaluation.as_ref().ok_or_else(|| {
            CaptureError::invalid(&manifest_file, "evaluation", "capture has no ground truth")
        })?;
        if !self.test_frames.contains(&frame)
            && !self.train_frames.contains(&frame)
            && self.manifest.canonical_frame != Some(frame)
        {
            return Err(CaptureError::invalid(
                &manifest_file,
                "test_frames",
                format!("frame {frame} is neither a test, a training nor the canonical frame"),
            ));
        }
        let path = self
            .dir
            .join(&eval.gt_meshes)
            .join(format!("{frame:05}.bin"));
        read_gt_positions(&path, self.template.vertex_count())
    }

    /// EVALUATION ONLY — the trainer must never call this. The ground-truth deformer's static
    /// weights (for a glTF character, the artist's), if the capture has them.
    pub fn evaluation_true_weights(&self) -> Result<Option<StaticSkin>, CaptureError> {
        let Some(rel) = self
            .manifest
            .evaluation
            .as_ref()
            .and_then(|e| e.true_weights.as_ref())
        else {
            return Ok(None);
        };
        let path = self.dir.join(rel);
        let file: SkinFile = read_json(&path)?;
        file.to_skin(&path, self.template.vertex_count(), self.skeleton.len())
            .map(Some)
    }
}

pub(crate) fn frame_file(
    dir: &Path,
    folder: &str,
    camera: &str,
    frame: usize,
    format: ImageFormat,
) -> PathBuf {
    dir.join(folder)
        .join(camera)
        .join(format!("{frame:05}.{}", format.extension()))
}

/// Reads a JSON file of at most [`MAX_JSON_BYTES`].
pub(crate) fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, CaptureError> {
    let io = |source| CaptureError::Io {
        file: path.to_owned(),
        source,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_JSON_BYTES {
        return Err(CaptureError::BadFile {
            file: path.to_owned(),
            reason: format!("{len} bytes, more than {MAX_JSON_BYTES}"),
        });
    }
    let bytes = std::fs::read(path).map_err(io)?;
    serde_json::from_slice(&bytes).map_err(|source| CaptureError::Json {
        file: path.to_owned(),
        source,
    })
}

#[cfg(test)]
mod tests;
