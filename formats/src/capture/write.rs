//! Writing a capture: each file atomically, the manifest last, so a folder with a manifest is
//! always complete.

use std::path::{Path, PathBuf};

use glam::Vec3;

use super::images::{self, write_gt_positions};
use super::schema::{
    CaptureManifest, DofsEntry, JointEntry, MotionFile, SkeletonEntry, SkinFile, TemplateFile,
};
use super::{CaptureError, MANIFEST_FILE, frame_file, transform_to_array};
use crate::mesh::{PartLabel, Template};
use crate::pose::Pose;
use crate::skeleton::{Axis, JointDofs, Skeleton};
use crate::skf::write_atomic;
use crate::skin::StaticSkin;

/// The JSON entry of a skeleton.
#[must_use]
pub fn skeleton_to_entry(s: &Skeleton) -> SkeletonEntry {
    let joints = (0..s.len())
        .map(|j| JointEntry {
            name: s.names()[j].clone(),
            parent: s.parents()[j],
            bind_local: transform_to_array(&s.bind_local()[j]),
            dofs: match &s.dofs()[j] {
                JointDofs::Free => DofsEntry::Free,
                JointDofs::Fixed => DofsEntry::Fixed,
                JointDofs::Euler { axes, limits } => DofsEntry::Euler {
                    axes: axes
                        .iter()
                        .map(|a| match a {
                            Axis::X => 'X',
                            Axis::Y => 'Y',
                            Axis::Z => 'Z',
                        })
                        .collect(),
                    limits: limits.clone(),
                },
            },
        })
        .collect();
    SkeletonEntry {
        joints,
        base: s.base().to_cols_array(),
    }
}

/// The JSON form of a template and its skeleton.
#[must_use]
pub fn template_to_file(t: &Template, s: &Skeleton) -> TemplateFile {
    TemplateFile {
        positions: t.positions.iter().map(|p| p.to_array()).collect(),
        normals: t.normals.iter().map(|p| p.to_array()).collect(),
        triangles: t.triangles.clone(),
        uvs: t
            .uvs
            .as_ref()
            .map(|u| u.iter().map(|p| p.to_array()).collect()),
        colors: t
            .colors
            .as_ref()
            .map(|u| u.iter().map(|p| p.to_array()).collect()),
        part_labels: t
            .part_labels
            .as_ref()
            .map(|u| u.iter().map(|&l| l as u8).collect()),
        skeleton: skeleton_to_entry(s),
    }
}

/// The JSON form of static weights.
#[must_use]
pub fn skin_to_file(s: &StaticSkin) -> SkinFile {
    SkinFile {
        joint_count: s.joint_count(),
        offsets: s.offsets().to_vec(),
        joints: s.joints().to_vec(),
        weights: s.weights().to_vec(),
    }
}

// Keep the part-label codes of the file format tied to the enum.
const _: () = assert!(PartLabel::Skin as u8 == 0 && PartLabel::Clothing as u8 == 1);

/// Writes the files of a capture into a folder; [`CaptureWriter::finish`] writes the manifest.
///
/// The paths come from the manifest given to [`CaptureWriter::new`].
#[derive(Debug)]
pub struct CaptureWriter {
    dir: PathBuf,
    manifest: CaptureManifest,
}

fn to_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), CaptureError> {
    // Compact JSON: templates are megabytes; the manifest is pretty-printed separately.
    let bytes = serde_json::to_vec(value).map_err(|source| CaptureError::Json {
        file: path.to_owned(),
        source,
    })?;
    write_file(path, &bytes)
}

pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), CaptureError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|source| CaptureError::Io {
            file: dir.to_owned(),
            source,
        })?;
    }
    write_atomic(path, bytes).map_err(|source| CaptureError::Io {
        file: path.to_owned(),
        source,
    })
}

impl CaptureWriter {
    /// A writer into `dir` (created if needed) for the files `manifest` names.
    pub fn new(dir: impl AsRef<Path>, manifest: CaptureManifest) -> Result<Self, CaptureError> {
        let dir = dir.as_ref().to_owned();
        std::fs::create_dir_all(&dir).map_err(|source| CaptureError::Io {
            file: dir.clone(),
            source,
        })?;
        Ok(Self { dir, manifest })
    }

    /// The manifest being written.
    #[must_use]
    pub fn manifest(&self) -> &CaptureManifest {
        &self.manifest
    }

    /// The capture folder.
    #[must_use]
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Writes the template and skeleton to the manifest's `template` path.
    pub fn write_template(
        &self,
        template: &Template,
        skeleton: &Skeleton,
    ) -> Result<(), CaptureError> {
        to_json(
            &self.dir.join(&self.manifest.template),
            &template_to_file(template, skeleton),
        )
    }

    /// Writes the poses to the manifest's `motion` path (which must be set).
    pub fn write_motion(&self, poses: &[Pose], fps: f32) -> Result<(), CaptureError> {
        let rel = self
            .manifest
            .motion
            .as_ref()
            .ok_or_else(|| self.missing("motion"))?;
        let frames = poses
            .iter()
            .map(|p| p.locals.iter().map(transform_to_array).collect())
            .collect();
        to_json(&self.dir.join(rel), &MotionFile { fps, frames })
    }

    /// Writes initial weights to the manifest's `initial_weights` path (which must be set).
    pub fn write_initial_weights(&self, skin: &StaticSkin) -> Result<(), CaptureError> {
        let rel = self
            .manifest
            .initial_weights
            .as_ref()
            .ok_or_else(|| self.missing("initial_weights"))?;
        to_json(&self.dir.join(rel), &skin_to_file(skin))
    }

    /// Writes the evaluation-only true weights (the manifest's `evaluation.true_weights`).
    pub fn write_true_weights(&self, skin: &StaticSkin) -> Result<(), CaptureError> {
        let rel = self
            .manifest
            .evaluation
            .as_ref()
            .and_then(|e| e.true_weights.as_ref())
            .ok_or_else(|| self.missing("evaluation.true_weights"))?;
        to_json(&self.dir.join(rel), &skin_to_file(skin))
    }

    /// Writes the evaluation-only ground-truth positions of test frame `frame`.
    pub fn write_gt_mesh(&self, frame: usize, positions: &[Vec3]) -> Result<(), CaptureError> {
        let e = self
            .manifest
            .evaluation
            .as_ref()
            .ok_or_else(|| self.missing("evaluation"))?;
        write_gt_positions(
            &self.dir.join(&e.gt_meshes).join(format!("{frame:05}.bin")),
            positions,
        )
    }

    /// Writes the colour image of camera `cam` (index into the manifest's cameras) at `frame`,
    /// linear RGB, in the manifest's image format.
    pub fn write_image(&self, cam: usize, frame: usize, rgb: &[Vec3]) -> Result<(), CaptureError> {
        let c = self.camera(cam)?;
        let fmt = self.manifest.image_format;
        let path = frame_file(&self.dir, &self.manifest.images, &c.name, frame, fmt);
        match fmt {
            super::ImageFormat::Png => images::write_image_png(&path, c.width, c.height, rgb),
            super::ImageFormat::Exr => images::write_image_exr(&path, c.width, c.height, rgb),
        }
    }

    /// Writes the mask of camera `cam` at `frame` from per-pixel coverage in `[0, 1]` (0 and 1
    /// for a binary mask).
    pub fn write_mask(
        &self,
        cam: usize,
        frame: usize,
        coverage: &[f32],
    ) -> Result<(), CaptureError> {
        let c = self.camera(cam)?;
        let path = frame_file(
            &self.dir,
            &self.manifest.masks,
            &c.name,
            frame,
            super::ImageFormat::Png,
        );
        images::write_mask_png(&path, c.width, c.height, coverage)
    }

    /// Writes the part labels of camera `cam` at `frame` (indices into the manifest's
    /// `labels.palette`, [`super::NO_LABEL`] for the background).
    pub fn write_labels(
        &self,
        cam: usize,
        frame: usize,
        labels: &[u8],
    ) -> Result<(), CaptureError> {
        let c = self.camera(cam)?;
        let entry = self
            .manifest
            .labels
            .as_ref()
            .ok_or_else(|| self.missing("labels"))?;
        let path = frame_file(
            &self.dir,
            &entry.folder,
            &c.name,
            frame,
            super::ImageFormat::Png,
        );
        super::labels::write_labels_png(&path, c.width, c.height, labels, &entry.palette)
    }

    /// Writes `manifest.json` (pretty-printed) and returns its path.
    pub fn finish(self) -> Result<PathBuf, CaptureError> {
        let path = self.dir.join(MANIFEST_FILE);
        let mut bytes =
            serde_json::to_vec_pretty(&self.manifest).map_err(|source| CaptureError::Json {
                file: path.clone(),
                source,
            })?;
        bytes.push(b'\n');
        write_file(&path, &bytes)?;
        Ok(path)
    }

    /// The manifest's entry of camera `cam`.
    pub(super) fn camera(&self, cam: usize) -> Result<&super::CameraEntry, CaptureError> {
        self.manifest
            .cameras
            .get(cam)
            .ok_or_else(|| self.missing("cameras"))
    }

    fn missing(&self, field: &str) -> CaptureError {
        CaptureError::invalid(
            &self.dir.join(MANIFEST_FILE),
            field,
            "not set in the manifest given to the writer",
        )
    }
}
